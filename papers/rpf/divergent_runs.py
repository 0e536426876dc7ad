"""Are a Monte-Carlo table's divergent runs the filter's design or too few particles? Reruns the
runs of a ``results.json`` whose run RMSE passes ``--over`` metres for any of ``--filters`` (or
the runs named by ``--runs``, in the setting the flags name), each at every particle count of
``--particles``, and prints each filter's run RMSE and the least error of its last 10 steps per
run (the engine's per-run streams make the first count reproduce the table's own figures).
``--rerun`` reruns other filters than ``--filters`` on those runs (another proposal,
``proposals.py``).

A committed ``results.json`` has no ``run_rmse`` (papers/strip_runs.py): the per-run arrays are
read from ``results.full.json`` beside it, which ``scripts/long_runs.sh`` leaves there, or
``git show`` restores (papers/README.md, "Per-run arrays").

    .venv/bin/python papers/rpf/divergent_runs.py \\
        papers/rpf/results/losses-rpf-10000/arasaratnam-haykin-random/results.json \\
        [--filters rpf,tl-rpf,robust-tl-rpf] [--over 500] [--particles 6000,24000]
    .venv/bin/python papers/rpf/divergent_runs.py --runs 497,760 --preset paper --truth fixed \\
        --truth-seed 1
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from tltrack.config import Config, make_config
from tltrack.engine.montecarlo import run_batch
from tltrack.filters.warm import warm_up


def per_run(path: Path) -> Path:
    """``path``, or the original of it that ``papers/strip_runs.py`` set aside with its arrays."""
    if '"run_rmse"' in path.read_text():
        return path
    full = path.with_name(path.stem + ".full.json")
    if full.exists():
        return full
    raise SystemExit(
        f"{path} has no run_rmse, and {full.name} is not beside it: rerun its job with "
        "scripts/long_runs.sh, or restore it from the history (papers/README.md, "
        '"Per-run arrays"), or name the runs with --runs'
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path, nargs="?", help="a results.json (or --runs)")
    ap.add_argument("--runs", help="these runs (comma-separated) of the setting below")
    ap.add_argument("--preset", default="arasaratnam-haykin")
    ap.add_argument("--truth", default="random")
    ap.add_argument("--truth-seed", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--filters", default="rpf,tl-rpf,robust-tl-rpf")
    ap.add_argument("--rerun", help="the filters rerun on those runs (default: --filters)")
    ap.add_argument("--compare", default="ukf,tl-ukf", help="filters rerun beside them")
    ap.add_argument("--over", type=float, default=500.0)
    ap.add_argument("--particles", default="6000,24000")
    args = ap.parse_args()
    warm_up()
    names = args.filters.split(",")
    if args.runs:
        runs = [int(r) for r in args.runs.split(",")]
        cfg = make_config(
            preset=args.preset,
            truth=args.truth,
            truth_seed=args.truth_seed,
            seed=args.seed,
            primary_intensity=4.0,
            runs=max(runs) + 1,
        )
    elif args.results is not None:
        results = json.loads(per_run(args.results).read_text())
        cfg = Config.model_validate(results["config"])
        table = results["filters"]
        runs = sorted(
            {r for n in names for r, v in enumerate(table[n]["run_rmse"]) if v > args.over}
        )
        print(f"runs whose run RMSE passes {args.over:g} m for one of {', '.join(names)}: {runs}")
    else:
        ap.error("name a results.json or --runs")
    rerun = args.rerun.split(",") if args.rerun else names
    everyone = rerun + [n for n in args.compare.split(",") if n]
    for N in (int(p) for p in args.particles.split(",")):
        stats = run_batch(cfg.with_(particles=N), everyone, runs)
        print(f"N = {N}, run RMSE / least error of the last 10 steps [m] of runs {runs}:")
        width = max(14, *map(len, stats))
        for n, s in stats.items():
            rmse, final = np.sqrt(np.ravel(s.run_mse)), np.ravel(s.tail_err)
            print(
                f"  {n:{width}s} "
                + " ".join(f"{r:5.0f}/{f:<5.0f}" for r, f in zip(rmse, final, strict=True))
            )


if __name__ == "__main__":
    main()
