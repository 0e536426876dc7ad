"""Nearly-constant-acceleration motion: x = [x, vx, ax, y, vy, ay], x_k = A x_{k-1} + v.

The discrete Wiener process acceleration model (Bar-Shalom, Li & Kirubarajan 2001, sec. 6.3.3):
per axis the acceleration is a random walk whose increment over one period, of variance q, acts on
position, velocity and acceleration through Gamma = [T^2/2, T, 1]'. So Q_v = q Gamma Gamma' per
axis: rank 1 per axis, rank 2 in all, singular like the CV model's, and sampled through its exact
square root ``Q_sqrt`` (6 x 2).

Each axis keeps its position, velocity and acceleration together, unlike CV's and CT's layouts;
that sensors and scoring find the position at (0, 3) proves they read it through the layout.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from tltrack.declare import Parameter
from tltrack.models.base import Layout
from tltrack.models.process_noise import Q1

Array = NDArray[np.float64]


def dwpa_sqrt(T: float, q: float) -> Array:
    """Square root sqrt(q) [T^2/2, T, 1]' of one axis' Wiener-process-acceleration block."""
    return np.sqrt(q) * np.array([[T * T / 2.0], [T], [1.0]])


@dataclass(frozen=True)
class ConstantAcceleration:
    """Constant acceleration per axis, whose increment per period has variance q (m^2/s^4)."""

    kind: ClassVar[str] = "ca"
    components: ClassVar[tuple[str, ...]] = (
        "x_m",
        "vx_mps",
        "ax_mps2",
        "y_m",
        "vy_mps",
        "ay_mps2",
    )
    parameters: ClassVar[tuple[Parameter, ...]] = (Q1,)
    #: a slow target (a boat, a drone) starting where Scenario 2 does at 30 m/s with a 0.5 m/s^2
    #: lateral acceleration, so that it stays within about 5 km of the sensors over 100 steps;
    #: q1, the variance of the acceleration's increment per step: it wanders by about 0.1 m/s^2
    defaults: ClassVar[dict[str, object]] = {
        "x0": [1000.0, 30.0, 0.0, 1000.0, 0.0, 0.5],
        "P0_diag": [100.0, 10.0, 0.1, 100.0, 10.0, 0.1],
        "q1": 0.01,
        "q2": 0.0,
    }

    T: float
    q: float
    n: int = 6
    layout: ClassVar[Layout] = Layout(pos=(0, 3), vel=(1, 4))
    Q: Array = field(init=False, repr=False)
    Q_sqrt: Array = field(init=False, repr=False)
    A: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        T = self.T
        block = np.array([[1.0, T, T * T / 2.0], [0.0, 1.0, T], [0.0, 0.0, 1.0]])
        A = np.zeros((6, 6))
        A[0:3, 0:3] = A[3:6, 3:6] = block
        L = np.zeros((6, 2))
        L[0:3, 0:1] = dwpa_sqrt(T, self.q)
        L[3:6, 1:2] = dwpa_sqrt(T, self.q)
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "Q_sqrt", L)
        object.__setattr__(self, "Q", L @ L.T)

    @classmethod
    def build(cls, T: float, params: dict[str, float]) -> ConstantAcceleration:
        return cls(T=T, q=params["q1"])

    def with_period(self, dt: float) -> ConstantAcceleration:
        """The same model over a step of ``dt`` seconds: F(dt) and Q(dt)."""
        return dataclasses.replace(self, T=dt)

    def f(self, x: Array) -> Array:
        return np.tensordot(self.A, x, axes=1)

    def F(self, x: Array) -> Array:
        return self.A
