"""When each operator samples, and what its clock reads then: the episode's timeline.

The paper's operators share one clock and one period T_s. On vehicles they share neither: each
sensor samples every ``period_s`` from ``phase_s`` (true time), and each operator's clock reads
the true time plus its own ``clock_offset_s``. The truth is simulated on a grid that holds every
sample time: the greatest common divisor of the periods and phases, refused when finer than
:data:`FINEST_GRID_US` (a period of 1/3 s beside 1 s has no such grid).

Times are whole microseconds here, so that "is this sample on that grid" and "is this horizon
the source's own period" are exact questions, not float comparisons.

A source steps at its own times and, after each step at clock time s, sends a transfer for
every primary measurement stamped in (s, s + its period] on the primary's clock
(:meth:`Timeline.targets`): the times until its next step. Its horizon to each is read on two
clocks, so an offset between them predicts to the wrong true time by their difference. With one
period, no phase and no offset, that is the paper's transfer for k + 1.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

US = 1_000_000
#: the finest truth grid a set of periods and phases may need, in microseconds
FINEST_GRID_US = 1000


def us(seconds: float) -> int:
    """Seconds as whole microseconds."""
    return round(seconds * US)


@dataclass(frozen=True)
class Clock:
    """One operator's sampling: every ``period_us`` from ``phase_us`` (true time), stamped by a
    clock ``offset_us`` ahead of the truth."""

    period_us: int
    phase_us: int = 0
    offset_us: int = 0

    def sample(self, j: int) -> int:
        """The true time of sample j (j = 1, 2, ...)."""
        return self.phase_us + j * self.period_us

    def stamp(self, j: int) -> int:
        """What the operator's clock reads at sample j."""
        return self.sample(j) + self.offset_us

    def count(self, duration_us: int) -> int:
        """Samples in (0, duration]."""
        return max(0, (duration_us - self.phase_us) // self.period_us)


def grid_us(clocks: Mapping[str, Clock]) -> int:
    """The coarsest grid that holds every clock's sample times; ValueError if finer than
    :data:`FINEST_GRID_US`."""
    g = 0
    for c in clocks.values():
        g = math.gcd(g, c.period_us, c.phase_us)
    if g < FINEST_GRID_US:
        said = ", ".join(
            f"{sid}: period {c.period_us / US:g} s, phase {c.phase_us / US:g} s"
            for sid, c in clocks.items()
        )
        raise ValueError(
            f"the sample times ({said}) share no grid of {FINEST_GRID_US / 1000:g} ms or coarser "
            f"(theirs is {g} us): give periods and phases in whole milliseconds that fit one grid"
        )
    return g


@dataclass(frozen=True)
class Timeline:
    """Every operator's :class:`Clock` over an episode of ``duration_us``, on one truth grid."""

    clocks: Mapping[str, Clock]
    duration_us: int
    primary: str = "primary"

    @cached_property
    def grid_us(self) -> int:
        return grid_us(self.clocks)

    @property
    def grid_s(self) -> float:
        return self.grid_us / US

    @property
    def ticks(self) -> int:
        """Grid steps after t = 0: the truth holds ticks + 1 states."""
        return self.duration_us // self.grid_us

    @property
    def synchronous(self) -> bool:
        """The paper's case: one period, no phase, no offset."""
        first = next(iter(self.clocks.values()))
        return all(c == Clock(first.period_us) for c in self.clocks.values())

    def steps(self, sid: str) -> int:
        """How many samples operator ``sid`` takes."""
        return self.clocks[sid].count(self.duration_us)

    def indices(self, sid: str) -> NDArray[np.intp]:
        """The grid index of each of its samples j = 1..steps (the truth's row)."""
        c = self.clocks[sid]
        j = np.arange(1, self.steps(sid) + 1)
        return np.asarray((c.phase_us + j * c.period_us) // self.grid_us, dtype=np.intp)

    @cached_property
    def _at(self) -> dict[int, dict[str, int]]:
        out: dict[int, dict[str, int]] = {}
        for sid in self.clocks:
            for j, n in enumerate(self.indices(sid), start=1):
                out.setdefault(int(n), {})[sid] = j
        return out

    def at(self, n: int) -> dict[str, int]:
        """Who samples at grid tick n, and which of its samples that is."""
        return self._at.get(n, {})

    def tick(self, sid: str, k: int) -> int:
        """The grid tick of operator ``sid``'s sample k; past its last, the ticks after the end
        (an episode's end names its last tick)."""
        c, steps = self.clocks[sid], self.steps(sid)
        if k <= steps:
            return c.sample(k) // self.grid_us
        return self.ticks + k - steps

    def stamp(self, sid: str, j: int) -> int:
        """What operator ``sid``'s clock reads at its sample j (us): its schedule, public."""
        return self.clocks[sid].stamp(j)

    def expects(self, sid: str, j: int) -> bool:
        """Does some step of source ``sid`` send a transfer for the primary's sample j? Not
        before its first step's first target (the paper's primary steps alone at k = 1)."""
        first = self._first_targets.get(sid)
        return first is not None and first <= j

    @cached_property
    def _first_targets(self) -> dict[str, int]:
        """Each source's first primary sample it sends for (none: it never sends)."""
        first: dict[str, int] = {}
        for sid in self.clocks:
            if sid == self.primary:
                continue
            for k in range(1, self.steps(sid) + 1):
                if targets := self.targets(sid, k):
                    first[sid] = targets[0][0]
                    break
        return first

    def targets(self, sid: str, k: int) -> list[tuple[int, int]]:
        """The primary's samples j that source ``sid``'s step k sends transfers for, each with
        the horizon (us) the source predicts over: the primary's stamp minus its own."""
        src, prim = self.clocks[sid], self.clocks[self.primary]
        s = src.stamp(k)
        base = prim.phase_us + prim.offset_us  # the primary's stamp of sample j: base + j T
        first = (s - base) // prim.period_us + 1
        last = (s + src.period_us - base) // prim.period_us
        last = min(last, self.steps(self.primary) + 1)  # the one past the end: the paper's k + 1
        return [(j, base + j * prim.period_us - s) for j in range(max(first, 1), last + 1)]

    @property
    def sends_ahead(self) -> int:
        """The most primary samples one source step sends transfers for (how long a channel
        keeps them): a source k times slower than the primary sends for k."""
        prim = self.clocks[self.primary].period_us
        return max(-(-c.period_us // prim) for c in self.clocks.values())
