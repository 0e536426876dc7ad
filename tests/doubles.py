"""Linear-Gaussian stand-ins for the models, where a Kalman filter is exact."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from tltrack.models.motion import ConstantVelocity


@dataclass(frozen=True)
class PositionSensor:
    """h(x) = [x, y]: linear, no angle, so the Kalman filter is the exact posterior."""

    position: tuple[float, float] = (0.0, 0.0)
    n_z: int = 2

    def h(self, x):
        return np.stack([x[0], x[2]])

    def H(self, x):
        H = np.zeros((2, len(x)))
        H[0, 0] = H[1, 2] = 1.0
        return H

    def residual(self, z, zhat):
        return np.asarray(z, dtype=float) - zhat

    def mean(self, Z, axis):
        return Z.mean(axis=axis)


def cv_model(q: float = 0.1) -> ConstantVelocity:
    return ConstantVelocity(T=1.0, q=q)


def kalman(model, sensor, x0, P0, zs, Rs):
    """Textbook KF; ``zs[k]`` is a list of measurements at step k with covariances ``Rs[k]``."""
    m, P = np.array(x0, float), np.array(P0, float)
    out = []
    for z_list, R_list in zip(zs, Rs, strict=True):
        m = model.A @ m
        P = model.A @ P @ model.A.T + model.Q
        for z, R in zip(z_list, R_list, strict=True):
            H = sensor.H(m)
            S = H @ P @ H.T + R
            K = P @ H.T @ np.linalg.inv(S)
            m = m + K @ (z - H @ m)
            P = P - K @ S @ K.T
        out.append((m.copy(), P.copy()))
    return out
