"""The paper's radar: range and bearing, z = h(x) + w, Q_w = I_w diag(sigma_r^2, sigma_bearing^2).

The sensor may sit anywhere; the paper's sits at the origin. The bearing is ``atan2`` (the seed's
arctan(y/x) loses the quadrant).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from tltrack.declare import Parameter
from tltrack.models.base import Layout
from tltrack.models.gaussian_sensor import GaussianSensor

Array = NDArray[np.float64]

BEARING = 1  #: index of the bearing in z = [r, bearing]

#: the seed's radar noise (Table 1); by default the config's top-level fields of these names
SIGMA_R = Parameter("sigma_r", "m", "range noise std at I_w = 1", gt=0, inherit=True)
SIGMA_BEARING = Parameter(
    "sigma_bearing", "rad", "bearing noise std at I_w = 1", gt=0, inherit=True
)


@dataclass(frozen=True)
class RangeBearing(GaussianSensor):
    """h(x) = [hypot(x - sx, y - sy), atan2(y - sy, x - sx)] for a sensor at (sx, sy)."""

    kind: ClassVar[str] = "range-bearing"
    components: ClassVar[tuple[str, ...]] = ("range_m", "bearing_rad")
    angular: ClassVar[tuple[bool, ...]] = (False, True)
    parameters: ClassVar[tuple[Parameter, ...]] = (SIGMA_R, SIGMA_BEARING)

    sigma_r: float
    sigma_bearing: float
    layout: Layout
    position: tuple[float, float] = (0.0, 0.0)

    def R(self, intensity: float) -> Array:
        """Q_w = I_w B_w with B_w = diag(sigma_r^2, sigma_bearing^2) (seed, Sec. II-B)."""
        return intensity * np.diag([self.sigma_r**2, self.sigma_bearing**2])

    def h(self, x: Array) -> Array:
        ix, iy = self.layout.pos
        dx = x[ix] - self.position[0]
        dy = x[iy] - self.position[1]
        return np.stack([np.hypot(dx, dy), np.arctan2(dy, dx)])

    def H(self, x: Array) -> Array:
        """Jacobian of h at a single state (for the PCRLB)."""
        ix, iy = self.layout.pos
        dx = float(x[ix]) - self.position[0]
        dy = float(x[iy]) - self.position[1]
        r2 = dx * dx + dy * dy
        r = np.sqrt(r2)
        J = np.zeros((2, len(x)))
        J[0, ix], J[0, iy] = dx / r, dy / r
        J[1, ix], J[1, iy] = -dy / r2, dx / r2
        return J

    def miscalibration(self, sigmas: float, intensity: float) -> Array:
        """A boresight error: ``sigmas`` bearing standard deviations, the range untouched."""
        return np.array([0.0, sigmas * self.sigma_bearing * np.sqrt(intensity)])

    def to_position(self, z: Array, P: Array) -> tuple[Array, Array]:
        """Cartesian position (2, B) and its linearised covariance (B, 2, 2) of z (2, B), cov P.

        It lets two sensors at different places be compared without any filter's prior.
        """
        r, b = z[0], z[BEARING]
        c, s = np.cos(b), np.sin(b)
        pos = np.stack([self.position[0] + r * c, self.position[1] + r * s])
        J = np.empty((r.shape[0], 2, 2))
        J[:, 0, 0], J[:, 0, 1], J[:, 1, 0], J[:, 1, 1] = c, -r * s, s, r * c
        return pos, J @ P @ J.transpose(0, 2, 1)

    def from_position(self, z: Array, S: Array) -> Array:
        """A Cartesian covariance S (B, 2, 2) seen at z (2, B) in this sensor's (range, bearing)."""
        r, b = z[0], z[BEARING]
        c, s = np.cos(b), np.sin(b)
        Jinv = np.empty((r.shape[0], 2, 2))
        Jinv[:, 0, 0], Jinv[:, 0, 1], Jinv[:, 1, 0], Jinv[:, 1, 1] = c, s, -s / r, c / r
        return Jinv @ S @ Jinv.transpose(0, 2, 1)
