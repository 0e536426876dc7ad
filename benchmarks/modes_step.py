"""The three-mode rpf step against the single-model coordinated-turn rpf step, side by side.

Both filter one run (B = 1) of Scenario 2 under the arasaratnam-haykin preset with N particles;
the three-mode filter takes the aircraft class's modes (config ``target_class``). The runs
alternate (single, three modes, single, ...), each recording every step's wall time, so load hits
both alike; the figures are medians over all steps and their ratio (issue 31 asks for <= 1.5 at
N = 6000).

    .venv/bin/python benchmarks/modes_step.py [--particles 6000] [--runs 6] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from tltrack.config import make_config
from tltrack.engine.montecarlo import run_batch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, default=6000)
    ap.add_argument("--runs", type=int, default=6, help="runs of each, alternated")
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--filter", default="rpf", help="rpf, tl-rpf, pf or tl-pf")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    base = {"preset": "arasaratnam-haykin", "K": a.steps, "particles": a.particles}
    cfgs = {
        "single": make_config(**base),
        "three-mode": make_config(**base, target_class="aircraft"),
    }
    assert len(cfgs["three-mode"].motion_modes or []) == 3
    run_batch(cfgs["single"], [a.filter], [0], timing=True)  # compile the kernels first
    run_batch(cfgs["three-mode"], [a.filter], [0], timing=True)
    ms: dict[str, list[float]] = {k: [] for k in cfgs}
    for r in range(a.runs):
        for name, cfg in cfgs.items():
            ms[name] += run_batch(cfg, [a.filter], [r], timing=True)[a.filter].step_ms
    med = {k: float(np.median(v)) for k, v in ms.items()}
    out = {
        "filter": a.filter,
        "particles": a.particles,
        "steps": len(ms["single"]),
        "median_ms": med,
        "ratio": med["three-mode"] / med["single"],
    }
    print(json.dumps(out, indent=2))
    if a.json:
        a.json.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
