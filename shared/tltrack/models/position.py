"""A Cartesian position sensor (a camera's ground-plane fix, GNSS): z = (x, y) + w.

Q_w = I_w sigma_pos^2 I_2. The measurement is in absolute coordinates, the state's frame, so h does
not depend on where the sensor is: its ``position`` only says where it sits (the dashboard draws
it there). The model is linear, so with a linear motion model the sigma-point filters are exact.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from tltrack.declare import Parameter
from tltrack.models.base import Layout
from tltrack.models.gaussian_sensor import GaussianSensor

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Position(GaussianSensor):
    """h(x) = (x, y) of the target, wherever the sensor is.

    ``sigma_pos`` has a default, so it is keyword-only: ``Position(layout, position,
    sigma_pos=...)`` keeps the positional order of the other sensors (..., layout, position).
    """

    kind: ClassVar[str] = "position"
    components: ClassVar[tuple[str, ...]] = ("x_m", "y_m")
    angular: ClassVar[tuple[bool, ...]] = (False, False)
    parameters: ClassVar[tuple[Parameter, ...]] = (
        Parameter("sigma_pos", "m", "noise std per axis at I_w = 1", default=10.0, gt=0),
    )

    layout: Layout
    position: tuple[float, float] = (0.0, 0.0)
    sigma_pos: float = field(default=10.0, kw_only=True)

    def R(self, intensity: float) -> Array:
        """Q_w = I_w sigma_pos^2 I_2: the same noise in x and in y."""
        return intensity * self.sigma_pos**2 * np.eye(2)

    def h(self, x: Array) -> Array:
        return self.layout.position(x)

    def H(self, x: Array) -> Array:
        """Jacobian of h (constant): a one in each position component of the layout."""
        J = np.zeros((2, len(x)))
        J[0, self.layout.pos[0]] = J[1, self.layout.pos[1]] = 1.0
        return J

    def miscalibration(self, sigmas: float, intensity: float) -> Array:
        """A registration error: the fix shifted by ``sigmas`` standard deviations in x."""
        return np.array([sigmas * self.sigma_pos * np.sqrt(intensity), 0.0])

    def to_position(self, z: Array, P: Array) -> tuple[Array, Array]:
        """z (2, B) with covariance P (B, 2, 2) already is a position: both returned as they are."""
        return np.asarray(z, dtype=float), np.asarray(P, dtype=float)

    def from_position(self, z: Array, S: Array) -> Array:
        """A Cartesian covariance S (B, 2, 2) is already in this sensor's coordinates."""
        return np.asarray(S, dtype=float)
