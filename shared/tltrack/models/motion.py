"""Motion models x_k = f(x_{k-1}) + v_{k-1}, v ~ N(0, Q_v).

Arrays put the state on the first axis, ``x.shape == (n_x, *batch)``, so one call propagates a
particle cloud ``(n_x, B, N)``, a set of sigma points or a single state alike, and each component
``x[i]`` is a contiguous block.

Q_v (the seed's white-noise-acceleration form, with T^4/4, T^3/2, T^2 blocks) has rank 2 per
position/velocity pair, so it has no Cholesky factor. :attr:`MotionModel.Q_sqrt` is an exact
rank-deficient square root ``L`` with ``L @ L.T == Q_v``: per axis ``sqrt(q1) * [T^2/2, T]``.
Sampling draws only ``rank`` standard normals per particle.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from tltrack.config import Config

Array = NDArray[np.float64]

#: Indices of the Cartesian position (x, y) in both state vectors.
POS = (0, 2)


class MotionModel(Protocol):
    """What a filter needs to know about the dynamics."""

    @property
    def n(self) -> int: ...

    @property
    def Q(self) -> Array: ...

    @property
    def Q_sqrt(self) -> Array:
        """L with L @ L.T == Q_v; L has as many columns as Q_v has rank."""

    def f(self, x: Array) -> Array: ...

    def F(self, x: Array) -> Array: ...


def _wna_sqrt(T: float, q: float) -> Array:
    """Square root of one axis' white-noise-acceleration block q [[T^4/4, T^3/2], [T^3/2, T^2]]."""
    return np.sqrt(q) * np.array([[T * T / 2.0], [T]])


@dataclass(frozen=True)
class ConstantVelocity:
    """Scenario 1: x = [x, vx, y, vy], the seed's eq. for the linear motion model."""

    T: float
    q: float
    n: int = 4
    Q: Array = field(init=False, repr=False)
    Q_sqrt: Array = field(init=False, repr=False)
    A: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        T = self.T
        A = np.eye(4)
        A[0, 1] = A[2, 3] = T
        L = np.zeros((4, 2))
        L[0:2, 0:1] = _wna_sqrt(T, self.q)
        L[2:4, 1:2] = _wna_sqrt(T, self.q)
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "Q_sqrt", L)
        object.__setattr__(self, "Q", L @ L.T)

    def f(self, x: Array) -> Array:
        return np.tensordot(self.A, x, axes=1)

    def F(self, x: Array) -> Array:
        return self.A


@dataclass(frozen=True)
class CoordinatedTurn:
    """Scenario 2: x = [x, vx, y, vy, Omega], the coordinated-turn model of Bar-Shalom et al.

    The turn-rate noise enters as q2 * T (the seed's Q_v); Omega -> 0 uses the straight-line limit.
    """

    T: float
    q1: float
    q2: float
    n: int = 5
    Q: Array = field(init=False, repr=False)
    Q_sqrt: Array = field(init=False, repr=False)

    #: below this |Omega T| the sin/cos ratios use their Taylor series (relative error < 1e-16)
    SMALL = 1e-5

    def __post_init__(self) -> None:
        L = np.zeros((5, 3))
        L[0:2, 0:1] = _wna_sqrt(self.T, self.q1)
        L[2:4, 1:2] = _wna_sqrt(self.T, self.q1)
        L[4, 2] = np.sqrt(self.q2 * self.T)
        object.__setattr__(self, "Q_sqrt", L)
        object.__setattr__(self, "Q", L @ L.T)

    def _ratios(self, w: Array) -> tuple[Array, Array, Array, Array]:
        """sin(wT)/w, (1 - cos(wT))/w, cos(wT), sin(wT), stable as w -> 0."""
        T = self.T
        wT = w * T
        s, c = np.sin(wT), np.cos(wT)
        small = np.abs(wT) < self.SMALL
        safe_w = np.where(small, 1.0, w)
        a = np.where(small, T * (1.0 - wT * wT / 6.0), s / safe_w)
        b = np.where(small, T * (wT / 2.0), (1.0 - c) / safe_w)
        return a, b, c, s

    def f(self, x: Array) -> Array:
        px, vx, py, vy, w = x
        a, b, c, s = self._ratios(w)
        return np.stack(
            [px + a * vx - b * vy, c * vx - s * vy, py + b * vx + a * vy, s * vx + c * vy, w]
        )

    def F(self, x: Array) -> Array:
        """Jacobian of f at a single state (for the PCRLB)."""
        _, vx, _, vy, w = (float(v) for v in x)
        T = self.T
        a, b, c, s = (float(v) for v in self._ratios(np.asarray(w)))
        if abs(w * T) < self.SMALL:
            da, db = -w * T**3 / 3.0, T * T / 2.0
        else:
            da = (T * c - a) / w  # d/dw [sin(wT)/w]
            db = (T * s - b) / w  # d/dw [(1-cos(wT))/w]
        dc, ds = -T * s, T * c
        return np.array(
            [
                [1.0, a, 0.0, -b, da * vx - db * vy],
                [0.0, c, 0.0, -s, dc * vx - ds * vy],
                [0.0, b, 1.0, a, db * vx + da * vy],
                [0.0, s, 0.0, c, ds * vx + dc * vy],
                [0.0, 0.0, 0.0, 0.0, 1.0],
            ]
        )


def motion_model(cfg: Config) -> ConstantVelocity | CoordinatedTurn:
    """The motion model a configuration describes."""
    if cfg.scenario == "cv":
        return ConstantVelocity(T=cfg.Ts, q=cfg.q1)
    return CoordinatedTurn(T=cfg.Ts, q1=cfg.q1, q2=cfg.q2)
