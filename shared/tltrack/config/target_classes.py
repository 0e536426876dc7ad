"""Target classes (``target_class``): how a kind of target moves, as the filters' motion modes.

A class sets the filters' ``motion_modes`` (their noise) and their Markov chain. The chain is given
as switching rates (a generator G, 1/s, rows summing to 0), so that one class serves every
sampling period: over a step of Ts the transition matrix is Pi = exp(G Ts). The truth keeps the
scenario's model and the preset still sets the sensors; a ``motion_modes`` or ``mode_transition``
given explicitly wins over the class's.

Each class is ``tltrack fit --model manoeuvres`` (or ``modes``) on the tracks named with it, all
in examples/tracks; the fits, their intervals and the commands are on the docs site's page
docs/howto/manoeuvring-targets.md.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

TargetClassName = Literal["ship", "aircraft"]


@dataclass(frozen=True)
class TargetClass:
    """A class's modes, each ``{"kind", "q1"[, "q2"]}`` as in ``motion_modes``, and the rate
    (1/s) at which the target leaves mode i for mode j (``rates[i][j]``, i != j); ``single``, the
    q1 and q2 of one coordinated turn fitted to the same tracks (what the modes are measured
    against)."""

    name: str
    modes: tuple[dict[str, Any], ...]
    rates: tuple[tuple[float, ...], ...]
    single: dict[str, float]

    def fields(self, Ts: float) -> dict[str, Any]:
        """The config fields the class fills: ``motion_modes`` and ``mode_transition``."""
        return {
            "motion_modes": [dict(m) for m in self.modes],
            "mode_transition": transition(self.rates, Ts),
        }


def transition(rates: Sequence[Sequence[float]], dt: float) -> list[list[float]]:
    """Pi = exp(G dt), G the generator of the switching ``rates`` (1/s; rates[i][j], the rate
    from mode i to mode j; the diagonal is ignored): the chain over dt seconds."""
    return [list(r) for r in _transition(tuple(tuple(float(x) for x in r) for r in rates), dt)]


@functools.lru_cache(maxsize=4096)
def _transition(rates: tuple[tuple[float, ...], ...], dt: float) -> tuple[tuple[float, ...], ...]:
    # cached: a fit asks for the same few periods at every report of every likelihood evaluation
    from scipy.linalg import expm  # on first use: every service loads this module

    G = np.array(rates)
    np.fill_diagonal(G, 0.0)
    G -= np.diag(G.sum(axis=1))
    Pi = np.clip(expm(G * dt), 0.0, None)
    return tuple(map(tuple, (Pi / Pi.sum(axis=1, keepdims=True)).tolist()))


def uniform_rates(M: int, rate: float) -> tuple[tuple[float, ...], ...]:
    """A chain that leaves each of M modes at ``rate`` (1/s), for any other mode alike."""
    return tuple(tuple(0.0 if i == j else rate / (M - 1) for j in range(M)) for i in range(M))


#: the five real flights and the two simulated aircraft of examples/tracks (566 reports): a
#: straight mode, a turn and a manoeuvre, left at 0.0488 /s
AIRCRAFT = TargetClass(
    "aircraft",
    (
        {"kind": "cv", "q1": 21.694},
        {"kind": "ct", "q1": 2.0753, "q2": 5.43697e-05},
        {"kind": "ct", "q1": 4.78573, "q2": 0.00162539},
    ),
    uniform_rates(3, 0.0488321),
    {"q1": 2.0753, "q2": 5.43697e-05},
)

#: the four AIS vessels of examples/tracks (171 reports, 61-120 s apart): a straight and a turning
#: mode, left at 0.000174 /s (a third, manoeuvring, mode took no weight: its rate fitted to 1e-20)
SHIP = TargetClass(
    "ship",
    ({"kind": "cv", "q1": 1.91776e-05}, {"kind": "ct", "q1": 0.00200374, "q2": 3.86855e-10}),
    uniform_rates(2, 0.000174088),
    {"q1": 0.00200374, "q2": 3.86855e-10},
)

#: every class, by name
TARGET_CLASSES: dict[str, TargetClass] = {c.name: c for c in (SHIP, AIRCRAFT)}
