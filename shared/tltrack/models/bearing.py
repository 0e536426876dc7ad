"""A passive bearing-only sensor: z = atan2(y - sy, x - sx) + w, Q_w = I_w sigma_bearing^2.

It measures a direction and no distance, so one measurement fixes no position: it is not a
:class:`~tltrack.models.base.PositionFix`, and from a fixed position its own filter never observes
the range (only the prior and the motion model bound it). That is what a transfer can supply.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from tltrack.declare import Parameter
from tltrack.models.base import Layout
from tltrack.models.gaussian_sensor import GaussianSensor
from tltrack.models.range_bearing import SIGMA_BEARING

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Bearing(GaussianSensor):
    """h(x) = atan2(y - sy, x - sx) for a sensor at (sx, sy): an ESM receiver or a passive sonar."""

    kind: ClassVar[str] = "bearing"
    components: ClassVar[tuple[str, ...]] = ("bearing_rad",)
    angular: ClassVar[tuple[bool, ...]] = (True,)
    parameters: ClassVar[tuple[Parameter, ...]] = (SIGMA_BEARING,)

    sigma_bearing: float
    layout: Layout
    position: tuple[float, float] = (0.0, 0.0)

    def R(self, intensity: float) -> Array:
        """Q_w = I_w sigma_bearing^2 (1 x 1)."""
        return intensity * np.array([[self.sigma_bearing**2]])

    def h(self, x: Array) -> Array:
        ix, iy = self.layout.pos
        return np.arctan2(x[iy] - self.position[1], x[ix] - self.position[0])[None]

    def H(self, x: Array) -> Array:
        """Jacobian of h at a single state (for the PCRLB): (-dy, dx) / r^2 on the position."""
        ix, iy = self.layout.pos
        dx = float(x[ix]) - self.position[0]
        dy = float(x[iy]) - self.position[1]
        r2 = dx * dx + dy * dy
        J = np.zeros((1, len(x)))
        J[0, ix], J[0, iy] = -dy / r2, dx / r2
        return J

    def miscalibration(self, sigmas: float, intensity: float) -> Array:
        """A boresight error, the only thing such a sensor can get wrong: ``sigmas`` bearing
        standard deviations."""
        return np.array([sigmas * self.sigma_bearing * np.sqrt(intensity)])
