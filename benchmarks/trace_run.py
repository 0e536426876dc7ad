"""One run of TL-RPF, step by step: how a divergence unfolds. Replays run ``--run`` of a setting
in lock step as the live services do (:class:`~tltrack.tracking.SourceEpisode` and
:class:`~tltrack.tracking.PrimaryEpisode`, which compute what the engine computes for that run),
and prints at each step the position error of the TL, isolated and source estimates, the TL
cloud's effective sample size and weighted spread (position, velocity, turn rate), and the true
and estimated turn rate.

    .venv/bin/python benchmarks/trace_run.py --run 6275 [--preset arasaratnam-haykin]
        [--truth random] [--particles 6000] [--every 1]
"""

from __future__ import annotations

import argparse

import numpy as np
from tltrack.config import make_config
from tltrack.engine.scenario import simulate
from tltrack.filters.base import Estimate
from tltrack.filters.warm import warm_up
from tltrack.messages import Measurement, Transfer
from tltrack.tracking import PrimaryEpisode, SourceEpisode


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
    sim = simulate(cfg, args.run)
    primary, source = (
        PrimaryEpisode(cfg, args.run, "rpf"),
        SourceEpisode(cfg, args.run, "rpf", "s1"),
    )
    tl = primary.tl.filter
    x = sim.truth
    ix, iv, iy, iw, io = 0, 1, 2, 3, 4  # the CT state (x, vx, y, vy, omega)

    def err(e: Estimate, k: int) -> float:
        return float(np.hypot(e.mean[0, ix] - x[k, ix], e.mean[0, iy] - x[k, iy]))

    print(
        "   k  err TL   isol.  source |  ESS  sd x/y [m]   vx/vy [m/s]  omega [deg/s]"
        " | omega true/TL"
    )
    transfers: dict[str, Transfer] = {}
    for k in range(1, cfg.K + 1):
        z = {
            sid: Measurement(episode="e", sender=sid, k=k, t_sensor=0.0, sensor=sid, z=zk[k - 1])
            for sid, zk in sim.z.items()
        }
        est_s, eta = source.step(z["s1"])
        est = primary.step(z["primary"], transfers)
        iso = primary.step_twin(z["primary"])
        w = np.exp(tl._logw[0] - tl._logw[0].max())
        w /= w.sum()
        cloud = tl.x[:, 0, :]
        mean = cloud @ w
        sd = np.sqrt(((cloud - mean[:, None]) ** 2) @ w)
        if k % args.every == 0:
            print(
                f"{k:4d} {err(est, k):7.1f} {err(iso, k):7.1f} {err(est_s, k):7.1f} |"
                f" {1.0 / (w @ w):5.0f} {sd[ix]:5.1f}/{sd[iy]:<5.1f} {sd[iv]:5.2f}/{sd[iw]:<5.2f}"
                f" {np.degrees(sd[io]):6.3f} | {np.degrees(x[k, io]):6.2f}/"
                f"{np.degrees(est.mean[0, io]):6.2f}"
            )
        transfers = {"s1": source.transfer_message(eta, "e", k, 0.0)}


if __name__ == "__main__":
    main()
