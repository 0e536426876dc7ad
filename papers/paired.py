"""Paired per-run differences of overall RMSE from a results file, with their Monte-Carlo error.

    .venv/bin/python papers/paired.py RESULTS.json A:B [A:B ...] [--rev COMMIT]

Each ``A:B`` names two filters of the file (``tl-rpf:rpf``); the line printed is the mean over
runs of A's run RMSE minus B's, and twice its standard error
(:func:`tltrack.studies.common.mc_error`), as the papers' READMEs quote them. The committed
results files keep no per-run arrays (``strip_runs.py``): ``--rev`` reads the file as it was at
a commit that still held them (``git show COMMIT:PATH``), or give the ``.full.json`` beside it.
"""

from __future__ import annotations

import argparse
import json
import subprocess
from pathlib import Path

import numpy as np
from tltrack.studies.common import mc_error


def read(path: Path, rev: str | None) -> dict:
    """The results document at ``path``, or as it was at commit ``rev``."""
    if rev is None:
        return json.loads(path.read_text())
    root = Path(__file__).resolve().parents[1]
    where = path.resolve().relative_to(root)
    shown = subprocess.run(
        ["git", "-C", str(root), "show", f"{rev}:{where}"], capture_output=True, check=True
    )
    return json.loads(shown.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path)
    ap.add_argument("pairs", nargs="+", help="A:B, two filters of the file")
    ap.add_argument("--rev", help="read the file as it was at this commit")
    a = ap.parse_args()
    filters = read(a.results, a.rev)["filters"]
    for pair in a.pairs:
        first, _, second = pair.partition(":")
        runs = [np.asarray(filters[n].get("run_rmse") or [], dtype=float) for n in (first, second)]
        if not len(runs[0]) or len(runs[0]) != len(runs[1]):
            raise SystemExit(f"{pair}: no per-run RMSE in {a.results} (see --rev)")
        d = runs[0] - runs[1]
        print(f"{first} - {second}: {d.mean():+.3f} ({mc_error(d):.3f}), {len(d)} runs")


if __name__ == "__main__":
    main()
