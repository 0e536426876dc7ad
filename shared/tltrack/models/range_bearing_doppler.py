"""A Doppler radar: range, bearing and range rate, z = h(x) + w (n_z = 3).

Q_w = I_w diag(sigma_r^2, sigma_bearing^2, sigma_rr^2). The range rate is the velocity's component
along the line of sight, ((x - sx) vx + (y - sy) vy) / r, read through the motion model's layout.
Range and bearing fix a position as the paper's radar does, so this is a
:class:`~tltrack.models.base.PositionFix` through those two components; the range rate adds
information about the velocity only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from tltrack.declare import Parameter
from tltrack.models.base import Layout
from tltrack.models.gaussian_sensor import GaussianSensor
from tltrack.models.range_bearing import SIGMA_BEARING, SIGMA_R, RangeBearing

Array = NDArray[np.float64]


@dataclass(frozen=True)
class RangeBearingDoppler(GaussianSensor):
    """h(x) = [r, atan2(y - sy, x - sx), ((x - sx) vx + (y - sy) vy) / r] for a sensor at (sx, sy).

    ``sigma_rr`` has a default, so it is keyword-only: the positional arguments are those of
    :class:`~tltrack.models.range_bearing.RangeBearing` (sigma_r, sigma_bearing, layout, position).
    """

    kind: ClassVar[str] = "range-bearing-doppler"
    components: ClassVar[tuple[str, ...]] = ("range_m", "bearing_rad", "range_rate_mps")
    angular: ClassVar[tuple[bool, ...]] = (False, True, False)
    parameters: ClassVar[tuple[Parameter, ...]] = (
        SIGMA_R,
        SIGMA_BEARING,
        Parameter("sigma_rr", "m/s", "range-rate noise std at I_w = 1", default=1.0, gt=0),
    )

    sigma_r: float
    sigma_bearing: float
    layout: Layout
    position: tuple[float, float] = (0.0, 0.0)
    sigma_rr: float = field(default=1.0, kw_only=True)

    @property
    def _polar(self) -> RangeBearing:
        """The same radar without the Doppler channel: its (range, bearing) geometry is ours."""
        return RangeBearing(self.sigma_r, self.sigma_bearing, self.layout, self.position)

    def R(self, intensity: float) -> Array:
        """Q_w = I_w diag(sigma_r^2, sigma_bearing^2, sigma_rr^2): independent channels."""
        return intensity * np.diag([self.sigma_r**2, self.sigma_bearing**2, self.sigma_rr**2])

    def h(self, x: Array) -> Array:
        ix, iy = self.layout.pos
        ivx, ivy = self.layout.vel
        dx = x[ix] - self.position[0]
        dy = x[iy] - self.position[1]
        r = np.hypot(dx, dy)
        # at the sensor itself the numerator is 0 too: a range rate of 0 there, as atan2 gives a
        # bearing of 0, keeps h finite (one NaN particle would poison a whole run's weights)
        rr = (dx * x[ivx] + dy * x[ivy]) / np.where(r > 0.0, r, 1.0)
        return np.stack([r, np.arctan2(dy, dx), rr])

    def H(self, x: Array) -> Array:
        """Jacobian of h at a single state (for the PCRLB).

        With u = (dx, dy) / r the line of sight and rr the range rate: d rr / d(x, y) =
        (v - rr u) / r (the velocity across the line of sight, over r), d rr / d(vx, vy) = u.
        """
        ix, iy = self.layout.pos
        ivx, ivy = self.layout.vel
        dx = float(x[ix]) - self.position[0]
        dy = float(x[iy]) - self.position[1]
        vx, vy = float(x[ivx]), float(x[ivy])
        r2 = dx * dx + dy * dy
        r = np.sqrt(r2)
        ux, uy = dx / r, dy / r
        rr = ux * vx + uy * vy
        J = np.zeros((3, len(x)))
        J[0, ix], J[0, iy] = ux, uy
        J[1, ix], J[1, iy] = -dy / r2, dx / r2
        J[2, ix], J[2, iy] = (vx - rr * ux) / r, (vy - rr * uy) / r
        J[2, ivx], J[2, ivy] = ux, uy
        return J

    def miscalibration(self, sigmas: float, intensity: float) -> Array:
        """A boresight error, as the paper's radar's: ``sigmas`` bearing standard deviations; range
        and range rate (both timing, not pointing) untouched."""
        return np.array([0.0, sigmas * self.sigma_bearing * np.sqrt(intensity), 0.0])

    def to_position(self, z: Array, P: Array) -> tuple[Array, Array]:
        """Cartesian position (2, B) and its linearised covariance (B, 2, 2) of z (3, B), cov P.

        Range and bearing fix the position; the range rate says nothing about it, so only z's first
        two components and P's (range, bearing) block enter.
        """
        return self._polar.to_position(z[:2], P[:, :2, :2])

    def from_position(self, z: Array, S: Array) -> Array:
        """A Cartesian covariance S (B, 2, 2), seen at z (3, B), in (range, bearing, range rate).

        The (range, bearing) block is S mapped as the paper's radar maps it. The range-rate row
        and column are zero, on purpose. The consumer is the robust transfer's bias discount
        (:mod:`tltrack.filters.decision`), which adds this to a transfer's P_eta_eta: S is there an
        estimate of b b' for a position bias b between source and primary. A position offset has
        no determined range-rate counterpart (that would take the velocity across the line of
        sight, which z does not carry), the disagreement it comes from compares positions only,
        so there is no evidence about the range rate, and a boresight error (the ``bias`` fault)
        leaves the range rate exact. Zeros keep the range rate's stated precision and keep
        P_eta_eta + discount positive definite. The cost: a fault in the range rate alone is
        neither gated nor discounted by that policy.
        """
        out = np.zeros((S.shape[0], 3, 3))
        out[:, :2, :2] = self._polar.from_position(z[:2], S)
        return out
