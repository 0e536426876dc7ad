"""Range-bearing measurement z = h(x) + w, w ~ N(0, Q_w), Q_w = I_w * diag(sigma_r^2, sigma_b^2).

The sensor may sit anywhere; the paper's sits at the origin. The bearing is ``atan2`` (the seed's
arctan(y/x) loses the quadrant), and every bearing *difference* goes through :func:`wrap_angle`:
a trajectory that crosses the +-pi cut would otherwise produce a 2*pi innovation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tltrack.models.motion import POS

Array = NDArray[np.float64]

BEARING = 1  #: index of the bearing in z = [r, bearing]


def wrap_angle(a: Array | float) -> Array:
    """Wrap to (-pi, pi]."""
    w = np.pi - np.mod(np.pi - np.asarray(a, dtype=float), 2.0 * np.pi)
    return w


@dataclass(frozen=True)
class RangeBearing:
    """h(x) = [hypot(x - sx, y - sy), atan2(y - sy, x - sx)] for a sensor at (sx, sy)."""

    sigma_r: float
    sigma_bearing: float
    position: tuple[float, float] = (0.0, 0.0)
    n_z: int = 2

    def R(self, intensity: float) -> Array:
        """Q_w = I_w B_w with B_w = diag(sigma_r^2, sigma_bearing^2) (seed, Sec. II-B)."""
        return intensity * np.diag([self.sigma_r**2, self.sigma_bearing**2])

    def h(self, x: Array) -> Array:
        dx = x[POS[0]] - self.position[0]
        dy = x[POS[1]] - self.position[1]
        return np.stack([np.hypot(dx, dy), np.arctan2(dy, dx)])

    def H(self, x: Array) -> Array:
        """Jacobian of h at a single state (for the PCRLB)."""
        n = len(x)
        dx = float(x[POS[0]]) - self.position[0]
        dy = float(x[POS[1]]) - self.position[1]
        r2 = dx * dx + dy * dy
        r = np.sqrt(r2)
        J = np.zeros((2, n))
        J[0, POS[0]], J[0, POS[1]] = dx / r, dy / r
        J[1, POS[0]], J[1, POS[1]] = -dy / r2, dx / r2
        return J

    def mean(self, Z: Array, axis: int) -> Array:
        """Sample mean of measurements along ``axis``; the bearing's is circular."""
        r = Z[0].mean(axis=axis - 1)
        b = np.arctan2(
            np.sin(Z[BEARING]).mean(axis=axis - 1), np.cos(Z[BEARING]).mean(axis=axis - 1)
        )
        return np.stack([r, b])

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

    def residual(self, z: Array, zhat: Array) -> Array:
        """z - zhat with the bearing wrapped; measurement components on the first axis."""
        d = np.asarray(z, dtype=float) - zhat
        d[BEARING] = wrap_angle(d[BEARING])
        return d
