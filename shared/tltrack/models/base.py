"""The two interfaces every model implements: a motion model and a measurement model.

A filter, the Monte-Carlo engine, the PCRLB, the transfer-decision layer, the wire format and the
services speak to these Protocols only. A new sensor is one class in one file that provides what
:class:`MeasurementModel` lists (as in Stone Soup: ``function``, ``jacobian``, ``covar``); a new
motion model likewise provides :class:`MotionModel`. Subclassing
:class:`tltrack.models.gaussian_sensor.GaussianSensor` gives the generic parts (wrapped residuals,
circular means, noisy draws) from a declaration of which components are angles.

Arrays put the vector components on the first axis: a state is ``(n_x, *batch)`` and a
measurement ``(n_z, *batch)``, so one call serves a single state, a batch of runs, sigma points
or a particle cloud ``(n_x, B, N)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Layout:
    """Where a state vector keeps the object's Cartesian position and velocity.

    The motion model owns it; sensors read the components they measure through it, and scoring
    takes the position error through it. Nothing else knows a state's layout.
    """

    pos: tuple[int, int]
    vel: tuple[int, int]

    def position(self, x: Array) -> Array:
        """The (x, y) components of states ``x`` (n_x, ...) -> (2, ...)."""
        return np.stack([x[self.pos[0]], x[self.pos[1]]])


class MotionModel(Protocol):
    """x_k = f(x_{k-1}) + v_{k-1}, v ~ N(0, Q_v), with Q_v = Q_sqrt Q_sqrt' (possibly singular)."""

    @property
    def n(self) -> int:
        """The state dimension n_x."""

    @property
    def layout(self) -> Layout:
        """Where the position and velocity sit in the state."""

    @property
    def Q(self) -> Array:
        """The process-noise covariance Q_v (n_x, n_x)."""

    @property
    def Q_sqrt(self) -> Array:
        """L with L @ L.T == Q_v; L has as many columns as Q_v has rank."""

    def f(self, x: Array) -> Array:
        """The transition mean of states ``x`` (n_x, ...)."""

    def F(self, x: Array) -> Array:
        """The Jacobian of f at a single state (for the PCRLB)."""

    def with_period(self, dt: float) -> MotionModel:
        """The same model over a step of ``dt`` seconds (reports at irregular times)."""


@runtime_checkable
class MeasurementModel(Protocol):
    """z = h(x) + w, w ~ N(0, R(I_w)), for a sensor at ``position``."""

    @property
    def kind(self) -> str:
        """The sensor's kind, as configs and transfers name it (e.g. ``range-bearing``)."""

    @property
    def position(self) -> tuple[float, float]:
        """Where the sensor sits, in the frame of the state."""

    @property
    def n_z(self) -> int:
        """Components of a measurement."""

    @property
    def components(self) -> tuple[str, ...]:
        """Each component's name with its unit, e.g. ``("range_m", "bearing_rad")``."""

    def R(self, intensity: float) -> Array:
        """The noise covariance Q_w (n_z, n_z) at noise intensity I_w."""

    def h(self, x: Array) -> Array:
        """The noise-free measurement of states ``x`` (n_x, ...) -> (n_z, ...)."""

    def H(self, x: Array) -> Array:
        """The Jacobian of h at a single state (n_z, n_x)."""

    def residual(self, z: Array, zhat: Array) -> Array:
        """z - zhat, with angle components wrapped to (-pi, pi]."""

    def mean(self, Z: Array, axis: int, weights: Array | None = None) -> Array:
        """The sample mean of measurements Z (n_z, ...) over ``axis``, weighted (weights shaped
        as one component, summing to 1 along ``axis``) if given; angles' is circular."""

    def draw(
        self, x: Array, intensity: float, rng: np.random.Generator, offset: Array | None = None
    ) -> Array:
        """Noisy measurements (K, n_z) of the states ``x`` (K, n_x), plus a constant ``offset``."""

    def miscalibration(self, sigmas: float, intensity: float) -> Array:
        """The constant offset (n_z,) of a miscalibrated sensor of this kind: ``sigmas`` noise
        standard deviations in the component such a fault shifts (robustness studies)."""


@runtime_checkable
class PositionFix(Protocol):
    """A sensor whose single measurement fixes a position (not, say, a bearing alone)."""

    def to_position(self, z: Array, P: Array) -> tuple[Array, Array]:
        """The position (2, B) and its linearised covariance (B, 2, 2) of z (n_z, B), cov P."""

    def from_position(self, z: Array, S: Array) -> Array:
        """A Cartesian covariance S (B, 2, 2), seen at z (n_z, B), in this sensor's coordinates."""
