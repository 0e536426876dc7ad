#!/usr/bin/env python3
"""Extract real aircraft tracks from the tracktable-data wheel as tltrack truth files.

SampleFlightsUS.csv holds 25 real US flights of December 2004 (Sandia's tracktable-data,
BSD-2-Clause), a report about every 61 s. The files examples/tracks/flight-*.csv were made by::

    pip download tracktable-data==1.7.3.1 --no-deps -d /tmp/ttd
    python scripts/extract_flights.py /tmp/ttd/tracktable_data-1.7.3.1-py3-none-any.whl \\
        --out examples/tracks

The flights are chosen by a rule fixed before any filter ran on them (the script prints every
flight with the numbers the rule looks at):

1. the flight's last 1200 s of reports, which end in its last report (an approach: the aircraft
   slows, descends and turns onto its runway), must hold no gap over 120 s (the truth reader's
   limit) and strictly increasing times;
2. it must end below 1000 ft (a landing, not a track cut off in cruise);
3. of those, the five whose course changes most over the window (the range of the unwrapped
   course between consecutive reports).

Reports without a position are left out. The file's header names its columns ``latitude
longitude``, but its rows give the longitude
first (-81.97, 26.99 is Florida): this script reads them as longitude, latitude. The output's
header is ``t,lat,lon``, t in seconds from the window's first report.
"""

from __future__ import annotations

import argparse
import csv
import io
import itertools
import sys
from collections import defaultdict
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from course_range import course_range_deg
from tracktable_wheel import read_member

MEMBER = "tracktable_data/python_example_data/SampleFlightsUS.csv"
WINDOW_S = 1200.0
MAX_GAP_S = 120.0
LANDED_FT = 1000.0
COUNT = 5


@dataclass
class Flight:
    """A flight's window of reports, and what the rule looks at."""

    id: str
    times: list[datetime]
    points: list[tuple[float, float]]  #: (lat, lon)
    max_gap_s: float
    end_ft: float
    course_range_deg: float


def window(flight_id: str, rows: list[list[str]]) -> Flight | None:
    """The flight's last WINDOW_S of reports, or None when rule 1 refuses them."""
    rows.sort(key=lambda r: r[1])
    times = [datetime.fromisoformat(r[1]) for r in rows]
    end = times[-1]
    keep = [i for i, t in enumerate(times) if (end - t).total_seconds() <= WINDOW_S]
    times = [times[i] for i in keep]
    rows = [rows[i] for i in keep]
    gaps = [(b - a).total_seconds() for a, b in itertools.pairwise(times)]
    if len(rows) < 4 or max(gaps) > MAX_GAP_S or min(gaps) <= 0:
        return None
    points = [(float(r[3]), float(r[2])) for r in rows]  # the rows give longitude first
    return Flight(
        flight_id,
        times,
        points,
        max(gaps),
        float(rows[-1][4]),
        course_range_deg(points),
    )


def candidates(text: str) -> list[Flight]:
    """Every flight that passes rules 1 and 2, by rule 3's course range, largest first."""
    by_id: dict[str, list[list[str]]] = defaultdict(list)
    for row in csv.reader(io.StringIO(text)):
        if row and not row[0].startswith("#") and row[2] and row[3]:  # reports with a position
            by_id[row[0]].append(row)
    found = [f for i, rows in by_id.items() if (f := window(i, rows)) is not None]
    found = [f for f in found if f.end_ft < LANDED_FT]
    return sorted(found, key=lambda f: -f.course_range_deg)


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("wheel", type=Path, help="tracktable_data-1.7.3.1-py3-none-any.whl")
    ap.add_argument("--out", type=Path, help="the folder to write flight-<id>.csv into")
    args = ap.parse_args()
    text = read_member(args.wheel, MEMBER)
    found = candidates(text)
    print(f"{len(found)} flight(s) pass rules 1 and 2, by course range (rule 3):")
    for f in found:
        print(
            f"  {f.id}  {len(f.times):3d} reports  max gap {f.max_gap_s:4.0f} s  "
            f"ends at {f.end_ft:5.0f} ft  course range {f.course_range_deg:6.1f} deg"
        )
    if not args.out:
        return 0
    args.out.mkdir(parents=True, exist_ok=True)
    for f in found[:COUNT]:
        path = args.out / f"flight-{f.id}.csv"
        lines = ["t,lat,lon"]
        lines += [
            f"{(t - f.times[0]).total_seconds():g},{lat},{lon}"
            for t, (lat, lon) in zip(f.times, f.points, strict=True)
        ]
        path.write_text("\n".join(lines) + "\n")
        print(f"wrote {path}: {len(f.times)} reports over {(f.times[-1] - f.times[0]).seconds} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
