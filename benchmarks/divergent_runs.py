"""Are a Monte-Carlo table's divergent runs the filter's design or too few particles? Reruns the
runs of a ``results.json`` whose run RMSE passes ``--over`` metres for any of ``--filters``, each
at every particle count of ``--particles``, and prints each filter's run RMSE per run (the
engine's per-run streams make the first count reproduce the table's own figures).

    .venv/bin/python benchmarks/divergent_runs.py \\
        docs/results/long/losses-rpf-10000/arasaratnam-haykin-random/results.json \\
        [--filters rpf,tl-rpf,robust-tl-rpf] [--over 500] [--particles 6000,24000]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from tltrack.config import Config
from tltrack.engine.montecarlo import run_batch
from tltrack.filters.warm import warm_up


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path)
    ap.add_argument("--filters", default="rpf,tl-rpf,robust-tl-rpf")
    ap.add_argument("--compare", default="ukf,tl-ukf", help="filters rerun beside them")
    ap.add_argument("--over", type=float, default=500.0)
    ap.add_argument("--particles", default="6000,24000")
    args = ap.parse_args()
    warm_up()
    results = json.loads(args.results.read_text())
    cfg = Config.model_validate(results["config"])
    names = args.filters.split(",")
    table = results["filters"]
    runs = sorted({r for n in names for r, v in enumerate(table[n]["run_rmse"]) if v > args.over})
    print(f"runs whose run RMSE passes {args.over:g} m for one of {', '.join(names)}: {runs}")
    everyone = names + [n for n in args.compare.split(",") if n]
    for N in (int(p) for p in args.particles.split(",")):
        stats = run_batch(cfg.with_(particles=N), everyone, runs)
        print(f"N = {N}, run RMSE [m] per run:")
        for n in everyone:
            rmse = np.sqrt(np.ravel(stats[n].run_mse))
            print(f"  {n:14s} " + " ".join(f"{v:6.0f}" for v in rmse))


if __name__ == "__main__":
    main()
