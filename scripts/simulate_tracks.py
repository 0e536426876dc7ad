"""Write the manoeuvre study's simulated tracks (tltrack.studies.tracks) as truth files.

    .venv/bin/python scripts/simulate_tracks.py --out examples/tracks

sim-turn-sequence.csv: the stated straight-and-turn sequence at 150 m/s, a report a second;
sim-circling-aircraft.csv: a light aircraft circling at 5 deg/s in a 46 m/s wind, a report every
5 s (ground speed 46-139 m/s), for 600 s.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tltrack.studies.tracks import circling_aircraft, turn_sequence, write_csv


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("examples/tracks"))
    out = ap.parse_args().out
    for name, track in (
        ("sim-turn-sequence.csv", turn_sequence()),
        ("sim-circling-aircraft.csv", circling_aircraft()),
    ):
        print(write_csv(out / name, *track))


if __name__ == "__main__":
    main()
