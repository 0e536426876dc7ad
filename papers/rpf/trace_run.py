"""One run of TL-RPF, step by step: how a divergence unfolds. Replays run ``--run`` of a setting
through the step driver (:class:`~tltrack.engine.driver.Driver`, a batch of that one run: what
the engine computes for it), and prints at each step the position error of the TL, isolated and
source estimates, the TL cloud's effective sample size and weighted spread (position, velocity,
turn rate), and the true and estimated turn rate.

    .venv/bin/python papers/rpf/trace_run.py --run 6275 [--preset arasaratnam-haykin]
        [--truth random] [--particles 6000] [--every 1]
"""

from __future__ import annotations

import argparse

import numpy as np
from tltrack.config import make_config
from tltrack.engine.driver import Driver, StepRecord, effective_sample_size
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import Setup
from tltrack.filters.warm import warm_up

IX, IV, IY, IW, IO = 0, 1, 2, 3, 4  # the CT state (x, vx, y, vy, omega)


class Trace:
    """A collector: each filter's estimate at the step, and the TL cloud's ESS and spread."""

    def __init__(self, tl: str) -> None:
        self.tl = tl
        self.estimates: dict[str, np.ndarray] = {}
        self.ess, self.sd = 0.0, np.zeros(0)

    def __call__(self, r: StepRecord) -> None:
        self.estimates[r.name] = r.estimate.mean[0]
        if r.name != self.tl:
            return
        ess = effective_sample_size(r.filter)
        assert ess is not None, "the trace reads a weighted cloud: a particle filter only"
        logw = r.filter.log_weights[0]
        w = np.exp(logw - logw.max())
        w /= w.sum()
        cloud = r.filter.x[:, 0, :]
        mean = cloud @ w
        self.ess, self.sd = float(ess[0]), np.sqrt(((cloud - mean[:, None]) ** 2) @ w)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", type=int, required=True)
    ap.add_argument("--preset", default="arasaratnam-haykin")
    ap.add_argument("--truth", default="random")
    ap.add_argument("--truth-seed", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--particles", type=int, default=6000)
    ap.add_argument("--every", type=int, default=1, help="print every this many steps")
    args = ap.parse_args()
    warm_up()
    cfg = make_config(
        preset=args.preset,
        truth=args.truth,
        truth_seed=args.truth_seed,
        seed=args.seed,
        particles=args.particles,
        primary_intensity=4.0,
        runs=args.run + 1,
    )
    if cfg.scenario != "ct":
        ap.error("the trace reads the turn rate: a CT scenario only")
    setup = Setup(cfg)
    sim = simulate(setup, args.run)
    trace = Trace("tl-rpf")
    driver = Driver(
        [setup], ["tl-rpf", "rpf"], sim.x0_hat[:, None], [args.run], collectors=[[trace]]
    )
    x = sim.truth

    def err(name: str, k: int) -> float:
        m = trace.estimates[name]
        return float(np.hypot(m[IX] - x[k, IX], m[IY] - x[k, IY]))

    print(
        "   k  err TL   isol.  source |  ESS  sd x/y [m]   vx/vy [m/s]  omega [deg/s]"
        " | omega true/TL"
    )
    for k in range(1, cfg.K + 1):
        driver.step(k, [{i: setup.sensors[i].observe(sim.z[i][k - 1]) for i in setup.sensor_ids}])
        sd = trace.sd
        if k % args.every == 0:
            print(
                f"{k:4d} {err('tl-rpf', k):7.1f} {err('rpf', k):7.1f} {err('source-rpf', k):7.1f} |"
                f" {trace.ess:5.0f} {sd[IX]:5.1f}/{sd[IY]:<5.1f} {sd[IV]:5.2f}/{sd[IW]:<5.2f}"
                f" {np.degrees(sd[IO]):6.3f} | {np.degrees(x[k, IO]):6.2f}/"
                f"{np.degrees(trace.estimates['tl-rpf'][IO]):6.2f}"
            )


if __name__ == "__main__":
    main()
