"""How much a recorded track turns, the number both extraction scripts rank tracks by
(``extract_ais_track.py``, ``extract_flights.py``): the range of its course between consecutive
reports, each the initial great-circle bearing, unwrapped so that a turn through north counts as
the turn it is.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence


def course(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Initial great-circle bearing from point 1 to point 2, radians clockwise from north."""
    p1, p2, dl = math.radians(lat1), math.radians(lat2), math.radians(lon2 - lon1)
    y = math.sin(dl) * math.cos(p2)
    x = math.cos(p1) * math.sin(p2) - math.sin(p1) * math.cos(p2) * math.cos(dl)
    return math.atan2(y, x)


def course_range_deg(points: Sequence[tuple[float, float]]) -> float:
    """Range (max - min) of the unwrapped course between consecutive (lat, lon) points, degrees."""
    c = [course(*a, *b) for a, b in itertools.pairwise(points)]
    unwrapped = [c[0]]
    for prev, cur in itertools.pairwise(c):
        unwrapped.append(unwrapped[-1] + (cur - prev + math.pi) % (2 * math.pi) - math.pi)
    return math.degrees(max(unwrapped) - min(unwrapped))
