"""Monte-Carlo throughput of the particle filters: ns per particle-step, engine with W workers.

    .venv/bin/python benchmarks/mc_throughput.py [--runs 200] [--workers 2] [--particles 6000]
        [--batch-size B] [--json FILE]

A particle-step is one particle through one time step of one particle filter; ``pf`` and
``tl-pf`` also run ``source-pf``, so a run counts 3 * K * N of them. "per core" multiplies the wall
time by the worker count (all cores busy); the CPU figure counts only the CPU time this process and
its workers used, so it is less sensitive to other load on a shared machine. The numba kernels are
loaded (or compiled) before the clock starts.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time

from tltrack.config import make_config
from tltrack.engine.montecarlo import default_batch_size, run_batch, run_experiment


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--particles", type=int, default=6000)
    ap.add_argument("--batch-size", type=int, default=None)
    ap.add_argument("--filters", default="pf,tl-pf")
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    names = a.filters.split(",")
    cfg = make_config(particles=a.particles, runs=a.runs)
    run_batch(cfg.with_(K=2), names, [0])  # load the cached kernels outside the clock
    t0 = time.perf_counter()
    c0 = _cpu()
    run_experiment(cfg, names, workers=a.workers, batch_size=a.batch_size, time_steps=False)
    wall = time.perf_counter() - t0
    cpu = _cpu() - c0
    n_pf = 3 if "tl-pf" in names else len(names)
    steps = a.runs * cfg.K * cfg.particles * n_pf
    out = {
        "runs": a.runs,
        "workers": a.workers,
        "particles": a.particles,
        "filters": names,
        "batch_size": a.batch_size or default_batch_size(cfg, names),
        "wall_s": round(wall, 2),
        "particle_steps": steps,
        "ns_per_particle_step_per_core": round(wall * a.workers / steps * 1e9, 1),
        "cpu_ns_per_particle_step": round(cpu / steps * 1e9, 1),
        "loadavg_1min": round(os.getloadavg()[0], 2),
    }
    print(json.dumps(out, indent=2))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=2)


def _cpu() -> float:
    """CPU seconds of this process and of its finished children (the workers)."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


if __name__ == "__main__":
    main()
