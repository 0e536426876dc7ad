#!/usr/bin/env python3
"""Extract one vessel's AIS track from the tracktable-data wheel as a tltrack truth file.

The shipped example examples/tracks/ais-nyharbor-2020-06-30-mmsi-367370920.csv was made by::

    pip download tracktable-data==1.7.3.1 --no-deps -d /tmp/ttd
    python scripts/extract_ais_track.py /tmp/ttd/tracktable_data-1.7.3.1-py3-none-any.whl \\
        --out examples/tracks/ais-nyharbor-2020-06-30-mmsi-367370920.csv

The vessel is chosen by a rule fixed before any filter ran on it (the script prints every vessel
that passes rules 1-4, with the number rule 5 ranks by):

1. the track spans at least 30 minutes;
2. no gap between consecutive reports is longer than 120 s (the truth reader's limit);
3. it is under way at every report: speed over ground >= 2 knots, so its heading is defined;
4. its report times strictly increase (no duplicated reports);
5. of those, the one whose course changes most: the largest range of its course over ground,
   taken from consecutive positions (initial great-circle bearing) and unwrapped.

Only the standard library is used; the output's header is ``t,lat,lon``, t in seconds from the
first report, lat and lon copied from the source file as written.
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

MEMBER = "tracktable_data/python_example_data/NYHarbor_2020_06_30_first_hour.csv"
MIN_SPAN_S = 30 * 60.0
MAX_GAP_S = 120.0
MIN_SOG_KN = 2.0


@dataclass
class Vessel:
    """One vessel's reports in time order, and what the rule looks at."""

    mmsi: str
    name: str
    rows: list[dict[str, str]]
    times: list[datetime]
    span_s: float
    max_gap_s: float
    sog_kn: tuple[float, float]
    course_range_deg: float


def candidates(text: str) -> list[Vessel]:
    """Every vessel that passes rules 1-4, best by rule 5 first."""
    by_mmsi: dict[str, list[dict[str, str]]] = defaultdict(list)
    for row in csv.DictReader(io.StringIO(text)):
        by_mmsi[row["MMSI"]].append(row)
    out: list[Vessel] = []
    for mmsi, rows in by_mmsi.items():
        if len(rows) < 3:
            continue
        rows.sort(key=lambda r: r["BaseDateTime"])
        times = [datetime.fromisoformat(r["BaseDateTime"]) for r in rows]
        gaps = [(b - a).total_seconds() for a, b in itertools.pairwise(times)]
        span = (times[-1] - times[0]).total_seconds()
        sog = [float(r["SOG"]) for r in rows]
        if span < MIN_SPAN_S or max(gaps) > MAX_GAP_S or min(sog) < MIN_SOG_KN or min(gaps) <= 0:
            continue
        out.append(
            Vessel(
                mmsi,
                rows[0]["VesselName"],
                rows,
                times,
                span,
                max(gaps),
                (min(sog), max(sog)),
                course_range_deg([(float(r["LAT"]), float(r["LON"])) for r in rows]),
            )
        )
    out.sort(key=lambda v: -v.course_range_deg)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("wheel", type=Path, help="tracktable_data-1.7.3.1-py3-none-any.whl")
    ap.add_argument("--out", type=Path, help="the t,lat,lon file to write")
    ap.add_argument("--mmsi", help="take this vessel instead of the rule's choice")
    args = ap.parse_args()
    text = read_member(args.wheel, MEMBER)
    found = candidates(text)
    print(f"{len(found)} vessel(s) pass rules 1-4, by course range (rule 5):")
    for v in found:
        print(
            f"  {v.mmsi}  {v.name or '-':<20} {len(v.rows):3d} points  {v.span_s / 60:5.1f} min  "
            f"max gap {v.max_gap_s:4.0f} s  SOG {v.sog_kn[0]:.1f}-{v.sog_kn[1]:.1f} kn  "
            f"course range {v.course_range_deg:5.1f} deg"
        )
    if not args.out:
        return 0
    chosen = [v for v in found if v.mmsi == args.mmsi] if args.mmsi else found[:1]
    if not chosen:
        print(f"no vessel passes the rule{' with MMSI ' + args.mmsi if args.mmsi else ''}")
        return 1
    v = chosen[0]
    lines = ["t,lat,lon"]
    for r, t in zip(v.rows, v.times, strict=True):
        lines.append(f"{(t - v.times[0]).total_seconds():g},{r['LAT']},{r['LON']}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}: MMSI {v.mmsi}, {len(v.rows)} points over {v.span_s:g} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
