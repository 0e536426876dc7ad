"""Step times of the particle filters against the NumPy baseline (and Stone Soup if installed).

    .venv/bin/python benchmarks/bench_pf.py [--particles 6000] [--repeats 3] [--json FILE]

The same as ``tltrack bench``: see :mod:`tltrack.perf.bench`. No timing is asserted anywhere in the
tests; track regressions by comparing these figures (ratios are steadier than absolute times on a
shared machine).
"""

from __future__ import annotations

import argparse
import json

from tltrack.perf.bench import format_table, run_bench


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, default=6000)
    ap.add_argument("--steps", type=int, default=None)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    result = run_bench(particles=a.particles, steps=a.steps, repeats=a.repeats)
    print(format_table(result))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(result, f, indent=2)


if __name__ == "__main__":
    main()
