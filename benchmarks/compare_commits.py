"""Is this tree as fast as another commit? ``tltrack bench`` of both, alternated on one machine.

Each round runs the bench once with the other commit's package (checked out in a git worktree) and
once with this tree's, in alternating order, and records each one's tl-pf step time relative to
its own plain-NumPy yardstick (``speedup["numpy-baseline"]``): a ratio measured inside one
process, so machine noise mostly cancels. The medians over the rounds are then compared.

    .venv/bin/python benchmarks/compare_commits.py --rev d109480 --rounds 5
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def bench(shared: Path, out: Path) -> float:
    """The tl-pf speedup over numpy-baseline of one ``tltrack bench`` with the package in
    ``shared``."""
    env = {**os.environ, "PYTHONPATH": str(shared)}
    argv = [sys.executable, "-m", "tltrack", "bench", "--json", str(out)]
    subprocess.run(argv, env=env, check=True, capture_output=True)
    return float(json.loads(out.read_text())["speedup"]["numpy-baseline"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", default="d109480", help="the commit to compare with")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tree = Path(d) / "other"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), args.rev],
            check=True,
            capture_output=True,
        )
        try:
            ratios: dict[str, list[float]] = {args.rev: [], "this tree": []}
            for r in range(args.rounds):
                order = [(args.rev, tree / "shared"), ("this tree", ROOT / "shared")]
                for name, shared in order if r % 2 == 0 else order[::-1]:
                    ratios[name].append(bench(shared, Path(d) / "bench.json"))
                    print(f"round {r + 1}: {name}: {ratios[name][-1]:.2f}x", flush=True)
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                check=False,
                capture_output=True,
            )
    med = {k: statistics.median(v) for k, v in ratios.items()}
    load = os.getloadavg()
    print(
        json.dumps(
            {
                "speedup_over_numpy_baseline": ratios,
                "median": med,
                "this_tree_over_other": med["this tree"] / med[args.rev],
                "loadavg": load,
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
