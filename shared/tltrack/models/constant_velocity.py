"""Scenario 1's nearly-constant-velocity motion: x = [x, vx, y, vy], x_k = A x_{k-1} + v."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from tltrack.declare import Parameter
from tltrack.models.base import Layout
from tltrack.models.process_noise import Q1, wna_sqrt

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ConstantVelocity:
    """The seed's linear motion model, with white-noise acceleration of intensity q per axis."""

    kind: ClassVar[str] = "cv"
    components: ClassVar[tuple[str, ...]] = ("x_m", "vx_mps", "y_m", "vy_mps")
    parameters: ClassVar[tuple[Parameter, ...]] = (Q1,)
    #: Scenario 1 as the seed prints it (Table 1)
    defaults: ClassVar[dict[str, object]] = {
        "x0": [100.0, 10.0, 100.0, 10.0],
        "P0_diag": [50.0, 1.0, 50.0, 1.0],
        "q1": 0.1,
        "q2": 0.0,
    }

    T: float
    q: float
    n: int = 4
    layout: ClassVar[Layout] = Layout(pos=(0, 2), vel=(1, 3))
    Q: Array = field(init=False, repr=False)
    Q_sqrt: Array = field(init=False, repr=False)
    A: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        T = self.T
        A = np.eye(4)
        A[0, 1] = A[2, 3] = T
        L = np.zeros((4, 2))
        L[0:2, 0:1] = wna_sqrt(T, self.q)
        L[2:4, 1:2] = wna_sqrt(T, self.q)
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "Q_sqrt", L)
        object.__setattr__(self, "Q", L @ L.T)

    @classmethod
    def build(cls, T: float, params: dict[str, float]) -> ConstantVelocity:
        return cls(T=T, q=params["q1"])

    def with_period(self, dt: float) -> ConstantVelocity:
        """The same model over a step of ``dt`` seconds: F(dt) and Q(dt)."""
        return dataclasses.replace(self, T=dt)

    def f(self, x: Array) -> Array:
        return np.tensordot(self.A, x, axes=1)

    def F(self, x: Array) -> Array:
        return self.A
