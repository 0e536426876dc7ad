"""Motion modes: a target that flies straight, then turns hard, then flies straight again.

A jump-Markov motion model: at each step the target's mode m_k follows a Markov chain with
transition matrix Pi (row i: the probabilities of going from mode i to each mode), and given the
mode the state moves as that mode's model says. Every mode lives in one common state, the
coordinated turn's (x, vx, y, vy, Omega): a straight (constant-velocity) mode holds Omega at 0
(:class:`Straight`), a turning mode is a
:class:`~tltrack.models.coordinated_turn.CoordinatedTurn` with its own noise. The interacting
multiple-model filter (Blom & Bar-Shalom 1988) and the particle filters with a mode per particle
follow the chain (tltrack.filters).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from tltrack.models.base import Layout, MotionModel
from tltrack.models.coordinated_turn import CoordinatedTurn
from tltrack.models.process_noise import wna_sqrt

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Straight:
    """Constant velocity in the coordinated turn's state: Omega is held at 0.

    f(x) = (x + T vx, vx, y + T vy, vy, 0); Q_v has the CV blocks and no turn-rate noise. Its
    square root keeps CT's three columns (the third is zero), so a particle draws the same
    Gaussians whatever its mode.
    """

    T: float
    q1: float
    n: int = 5
    layout: ClassVar[Layout] = CoordinatedTurn.layout
    components: ClassVar[tuple[str, ...]] = CoordinatedTurn.components
    Q: Array = field(init=False, repr=False)
    Q_sqrt: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        L = np.zeros((5, 3))
        L[0:2, 0:1] = wna_sqrt(self.T, self.q1)
        L[2:4, 1:2] = wna_sqrt(self.T, self.q1)
        object.__setattr__(self, "Q_sqrt", L)
        object.__setattr__(self, "Q", L @ L.T)

    def f(self, x: Array) -> Array:
        px, vx, py, vy, w = x
        T = self.T
        return np.stack([px + T * vx, vx, py + T * vy, vy, np.zeros_like(w)])

    def F(self, x: Array) -> Array:
        T = self.T
        F = np.eye(5)
        F[0, 1] = F[2, 3] = T
        F[4, 4] = 0.0
        return F

    def with_period(self, dt: float) -> Straight:
        return dataclasses.replace(self, T=dt)


@dataclass(frozen=True)
class MotionModes:
    """Motion models in one state (``models``), named, and the Markov chain between them.

    ``transition[i, j]`` is the probability of mode j at k given mode i at k - 1 (rows sum to 1);
    ``initial`` the mode probabilities at k = 0.
    """

    names: tuple[str, ...]
    models: tuple[MotionModel, ...]
    transition: Array
    initial: Array

    def __post_init__(self) -> None:
        M = len(self.models)
        if M == 0 or len(self.names) != M:
            raise ValueError("one name per motion mode, and at least one mode")
        if {m.n for m in self.models} != {self.models[0].n}:
            raise ValueError("every motion mode must share one state")
        Pi = np.asarray(self.transition, dtype=float)
        if Pi.shape != (M, M) or np.any(Pi < 0) or not np.allclose(Pi.sum(axis=1), 1.0):
            raise ValueError(f"the mode transition must be a {M}x{M} row-stochastic matrix")
        p0 = np.asarray(self.initial, dtype=float)
        if p0.shape != (M,) or np.any(p0 < 0) or not np.isclose(p0.sum(), 1.0):
            raise ValueError(f"the initial mode probabilities must be {M} numbers summing to 1")

    @property
    def M(self) -> int:
        return len(self.models)

    @property
    def n(self) -> int:
        return self.models[0].n

    @property
    def layout(self) -> Layout:
        return self.models[0].layout
