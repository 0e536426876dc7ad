"""Scenario 2's coordinated turn: x = [x, vx, y, vy, Omega] (Bar-Shalom, Li & Kirubarajan).

The turn-rate noise enters as q2 * T (the seed's Q_v); Omega -> 0 uses the straight-line limit.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from tltrack.declare import Parameter
from tltrack.models.base import Layout
from tltrack.models.process_noise import Q1, Q2, wna_sqrt

Array = NDArray[np.float64]

_DEG = np.pi / 180.0


@dataclass(frozen=True)
class CoordinatedTurn:
    """The coordinated-turn model with unknown turn rate Omega, as the seed writes it."""

    kind: ClassVar[str] = "ct"
    components: ClassVar[tuple[str, ...]] = ("x_m", "vx_mps", "y_m", "vy_mps", "omega_radps")
    parameters: ClassVar[tuple[Parameter, ...]] = (Q1, Q2)
    #: Scenario 2 as the seed prints it (Table 1): start, P0's diagonal and noise
    defaults: ClassVar[dict[str, object]] = {
        "x0": [1000.0, 300.0, 1000.0, 0.0, -3.0 * _DEG],
        "P0_diag": [100.0, 10.0, 100.0, 10.0, 100e-3],
        "q1": 0.1,
        "q2": 1.75e-2,
    }

    T: float
    q1: float
    q2: float
    n: int = 5
    layout: ClassVar[Layout] = Layout(pos=(0, 2), vel=(1, 3))
    Q: Array = field(init=False, repr=False)
    Q_sqrt: Array = field(init=False, repr=False)

    #: below this |Omega T| the sin/cos ratios use their Taylor series (relative error < 1e-16)
    SMALL = 1e-5

    def __post_init__(self) -> None:
        L = np.zeros((5, 3))
        L[0:2, 0:1] = wna_sqrt(self.T, self.q1)
        L[2:4, 1:2] = wna_sqrt(self.T, self.q1)
        L[4, 2] = np.sqrt(self.q2 * self.T)
        object.__setattr__(self, "Q_sqrt", L)
        object.__setattr__(self, "Q", L @ L.T)

    @classmethod
    def build(cls, T: float, params: dict[str, float]) -> CoordinatedTurn:
        return cls(T=T, q1=params["q1"], q2=params["q2"])

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

    def with_period(self, dt: float) -> CoordinatedTurn:
        """The same model over a step of ``dt`` seconds: F(dt) and Q(dt)."""
        return dataclasses.replace(self, T=dt)

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
