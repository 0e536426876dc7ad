"""An extended Kalman filter as a plugin filter kind, outside the package: ``ekf``.

It is installed the way a third party's would be, through an entry point in the group
``tltrack.filters`` (tests/test_plugins.py writes the distribution's metadata), and then runs in
every role by name: ``ekf``, ``tl-ekf``, ``robust-tl-ekf``, ``source-ekf``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import ClassVar

import numpy as np
from tltrack.declare import Parameter
from tltrack.filters.base import Estimate
from tltrack.models.base import MeasurementModel, MotionModel
from tltrack.models.observation import Observation

Array = np.ndarray


class ExtendedKalmanFilter:
    """The EKF over B runs: m (n, B), P (B, n, n); Jacobians at the current mean, run by run."""

    kind: ClassVar[str] = "ekf"
    particle: ClassVar[bool] = False
    parameters: ClassVar[tuple[Parameter, ...]] = ()

    @classmethod
    def build(
        cls,
        model: MotionModel,
        x0_hat: Array,
        P0: Array,
        *,
        particles: int,
        rngs: Sequence[np.random.Generator] | None,
        params: Mapping[str, float],
    ) -> ExtendedKalmanFilter:
        return cls(model, x0_hat, P0)

    def __init__(self, model: MotionModel, x0_hat: Array, P0: Array) -> None:
        n, B = x0_hat.shape
        self.model = model
        self.m = np.array(x0_hat, dtype=float)
        self.P = np.broadcast_to(np.asarray(P0, dtype=float), (B, n, n)).copy()

    def predict(self) -> None:
        F = np.stack([self.model.F(self.m[:, b]) for b in range(self.m.shape[1])])
        self.m = np.asarray(self.model.f(self.m))
        self.P = F @ self.P @ F.transpose(0, 2, 1) + self.model.Q

    def update(self, observations: Sequence[Observation]) -> None:
        for obs in observations:  # independent statements: one update after the other
            s = obs.sensor
            for b in range(self.m.shape[1]):
                if obs.mask is not None and not obs.mask[b]:
                    continue
                H = s.H(self.m[:, b])
                S = H @ self.P[b] @ H.T + obs.cov[b]
                K = np.linalg.solve(S, H @ self.P[b]).T
                nu = s.residual(obs.mean[:, b], s.h(self.m[:, b]))
                self.m[:, b] = self.m[:, b] + K @ nu
                P = self.P[b] - K @ S @ K.T
                self.P[b] = 0.5 * (P + P.T)

    def estimate(self) -> Estimate:
        return Estimate(self.m.T.copy(), self.P.copy())

    def predicted_observation(self, sensor: MeasurementModel, R: Array) -> Observation:
        B = self.m.shape[1]
        H = np.stack([sensor.H(self.m[:, b]) for b in range(B)])
        return Observation(sensor, sensor.h(self.m), H @ self.P @ H.transpose(0, 2, 1) + R)

    def adopt(self, other: ExtendedKalmanFilter, runs: np.ndarray) -> None:
        self.m[:, runs] = other.m[:, runs]
        self.P[runs] = other.P[runs]
