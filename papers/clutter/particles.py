"""rpf in the clutter study's setting (paper preset, fixed truth, 50-sigma field of view) at pd 0.9,
with 0.05 false alarms per gate and with none, at N = 1000, 6000 and 24000: does the lost share
fall with the particle count? Usage: python papers/clutter/particles.py RUNS"""

import sys
import time

from tltrack.engine.montecarlo import run_experiment
from tltrack.studies import Setting
from tltrack.studies.clutter import configs

runs = int(sys.argv[1])
for n in (1000, 6000, 24000):
    for pd, dens in ((0.9, 0.05), (0.9, 0.0)):
        cfg = configs(Setting(runs=runs, particles=n), pd, (dens,))[0]
        t = time.time()
        r = run_experiment(cfg, ["rpf", "tl-rpf", "robust-tl-rpf"], workers=2)
        print(
            f"N={n} pd={pd} per_gate={dens}: "
            + ", ".join(
                f"{k} lost {v.lost_fraction:.0%} rmse {v.rmse_overall:.1f}" for k, v in r.items()
            )
            + f" ({time.time() - t:.0f} s)",
            flush=True,
        )
