"""What a measured component can be: the bounds a value must meet before any filter sees it.

Finite is not enough. A range of 1e300 m is a finite number, and it overflows the filters' squares:
a UKF's eigen-decomposition fails and stops the service that ran it, a particle cloud's weights
turn NaN, and so does every estimate after. No sensor of this domain measures anything near
:data:`MAX_MAGNITUDE`, so a value beyond it, or a range that is not positive, or a bearing outside
[-pi, pi], is refused where it enters: a recorded scan's row (:mod:`tltrack.engine.scan_file`), a
live measurement (:mod:`tltrack.live.episodes`), a source's transfer
(:mod:`tltrack.wire.messages`) and a recorded truth's row (:mod:`tltrack.config.truth_file`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable

#: the largest magnitude of any measured value or recorded coordinate [m, m/s]: 2.6 times the
#: Moon's distance, far beyond any sensor or track here, and its square (1e18) far from overflow
MAX_MAGNITUDE = 1e9

#: component -> (can a measurement take this value?, what it must be); others: GENERIC
RULES: dict[str, tuple[Callable[[float], bool], str]] = {
    "range_m": (lambda v: 0 < v <= MAX_MAGNITUDE, "finite and in (0, 1e9]"),
    "bearing_rad": (lambda v: -math.pi <= v <= math.pi, "finite and in [-pi, pi]"),
}
GENERIC: tuple[Callable[[float], bool], str] = (
    lambda v: abs(v) <= MAX_MAGNITUDE,
    "finite and at most 1e9 in magnitude",
)


def problem(component: str, value: float) -> str | None:
    """None if ``value`` can be a measurement of ``component``, else what it must be."""
    ok, want = RULES.get(component, GENERIC)
    return None if math.isfinite(value) and ok(value) else want


def first_problem(components: Iterable[str], values: Iterable[float]) -> str | None:
    """``"range_m = -5.0 must be finite and in (0, 1e9]"`` for the first value refused, or None."""
    for c, v in zip(components, values, strict=True):
        want = problem(c, v)
        if want is not None:
            return f"{c} = {v!r} must be {want}"
    return None
