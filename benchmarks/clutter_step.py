"""A particle filter's step on a scan of 1000 detections against its clean step, side by side.

Both filters (``rpf`` and ``pf``, each clean and in clutter) filter one run (B = 1) of Scenario 2
under the paper preset with N particles, through the step driver. At every step the cluttered one
gets a scan of the target's measurement (pd = 1) plus 999 false alarms uniform in a field of view
centred on the target's noise-free measurement, sized so that the mean number of false alarms in
the 99% gate of the sensor's noise is ``--in-gate`` (issue 32: 2): the field of view follows the
target, so that it stays inside the view of a scan this dense. The steps alternate (clean,
cluttered, clean, ...) at every k, so load hits both alike; the figures are medians over every
step of every repeat and their ratio (issue 32 asks for <= 2 at N = 6000).

    .venv/bin/python benchmarks/clutter_step.py [--particles 6000] [--repeats 3] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
from scipy.stats import chi2
from tltrack.config import make_config
from tltrack.engine.driver import Primaries
from tltrack.engine.registry import parse
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.models.detection import Detection
from tltrack.models.scan import Scan


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, default=6000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--detections", type=int, default=1000, help="per scan, the target's included")
    ap.add_argument("--in-gate", type=float, default=2.0, help="mean false alarms in the 99% gate")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    names = ("rpf", "pf")
    ms: dict[str, list[float]] = {f"{n}{c}": [] for n in names for c in ("", " in clutter")}
    for rep in range(a.repeats + 1):  # the first pass compiles and warms up, untimed
        setup = Setup(make_config(particles=a.particles, K=a.steps, seed=rep))
        sim = simulate(setup, 0)
        own = setup.sensors[PRIMARY]
        sr, sb = np.sqrt(np.diag(own.R))
        # V / V_gate = (clutter per scan) / (clutter in the gate); the box keeps R's aspect
        gate = math.pi * chi2.ppf(0.99, 2) * sr * sb
        half = math.sqrt((a.detections - 1) * gate / a.in_gate / 4.0) / math.sqrt(sr * sb)
        rng = np.random.default_rng(rep)
        x0 = sim.x0_hat[:, None]
        clean = Primaries(setup, [parse(n) for n in names], x0, [0])
        dirty = Primaries(setup, [parse(n) for n in names], x0, [0])
        for k in range(1, a.steps + 1):
            centre = own.model.h(sim.truth[k][:, None])[:, 0]
            lo, hi = centre - half * np.array([sr, sb]), centre + half * np.array([sr, sb])
            fov = {"range_m": (lo[0], hi[0]), "bearing_rad": (lo[1], hi[1])}
            d = Detection(own.model.components, 1.0, a.detections - 1.0, fov)
            Z = np.vstack([sim.z[PRIMARY][k - 1], rng.uniform(lo, hi, (a.detections - 1, 2))])
            scan = Scan.pack(own.model, [rng.permutation(Z)], own.R, d)
            z = own.observe(sim.z[PRIMARY][k - 1])
            for n in names:
                for half_, stmt, label in ((clean, z, n), (dirty, scan, f"{n} in clutter")):
                    t0 = time.perf_counter()
                    half_.step(k, stmt, lambda _s: [], [n])
                    if rep:
                        ms[label].append((time.perf_counter() - t0) * 1e3)
    med = {k: float(np.median(v)) for k, v in ms.items()}
    out = {
        "particles": a.particles,
        "detections_per_scan": a.detections,
        "false_alarms_in_gate": a.in_gate,
        "steps_timed": len(ms["rpf"]),
        "median_ms": med,
        "ratio": {n: med[f"{n} in clutter"] / med[n] for n in names},
    }
    print(json.dumps(out, indent=2))
    if a.json:
        a.json.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
