"""A particle filter's step on a scan of 1000 detections against its clean step, side by side.

    .venv/bin/python benchmarks/clutter_step.py [--particles 6000] [--repeats 3] [--json FILE]

The same as ``tltrack bench --clutter``: see :mod:`tltrack.perf.clutter`.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from tltrack.perf.clutter import format_clutter_table, run_clutter_bench


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, default=6000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--detections", type=int, default=1000, help="per scan, the target's included")
    ap.add_argument("--in-gate", type=float, default=2.0, help="mean false alarms in the 99% gate")
    ap.add_argument("--stonesoup-steps", type=int, default=10)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    out = run_clutter_bench(
        a.particles, a.repeats, a.steps, a.detections, a.in_gate, a.stonesoup_steps
    )
    print(format_clutter_table(out))
    if a.json:
        a.json.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
