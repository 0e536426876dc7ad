"""Is the live TL step slower than the engine's because of the service's code, or because of when
it runs? Times, side by side in one process, the engine's tl-rpf step (``run_bench``), the
service's ``PrimaryEpisode.step`` back to back without and with the lost-track recovery (on in
the services, off in the engine), and with it 20 ms apart (50 steps/s). ``--spin`` spends those
20 ms spinning instead of sleeping: is a slow paced step the wake-up, or a cold cache?

    .venv/bin/python benchmarks/live_step.py --particles 6000 --rounds 2 [--spin]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from tltrack.config import Config, make_config
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import Setup
from tltrack.filters.warm import warm_up
from tltrack.live.tracking import PrimaryEpisode, SourceEpisode
from tltrack.perf.bench import run_bench
from tltrack.wire.messages import Measurement, Transfer


def pause(seconds: float, spin: bool) -> None:
    if not spin:
        time.sleep(seconds)
        return
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        pass


def tl_steps_ms(cfg: Config, kind: str, pause_s: float, spin: bool = False) -> list[float]:
    """The TL steps of one episode as the primary_tracker takes them (messages in, estimate out)."""
    sim = simulate(Setup(cfg), 0)
    primary, source = PrimaryEpisode(cfg, 0, kind), SourceEpisode(cfg, 0, kind, "s1")
    out: list[float] = []
    transfers: dict[str, Transfer] = {}
    for k in range(1, cfg.K + 1):
        z = {
            sid: Measurement(episode="e", sender="x", k=k, t_sensor=0.0, sensor=sid, z=zk[k - 1])
            for sid, zk in sim.z.items()
        }
        _est, eta = source.step(z["s1"])
        t0 = time.perf_counter()
        primary.step(z["primary"], transfers)
        if k > 1:  # step 1 has no transfer: not a TL step
            out.append((time.perf_counter() - t0) * 1e3)
        primary.step_twin(z["primary"])
        transfers = {"s1": source.transfer_message(eta, "e", k, 0.0)}
        pause(pause_s, spin)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, default=6000)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--spin", action="store_true", help="spin between paced steps, not sleep")
    args = ap.parse_args()
    warm_up()
    cfg = make_config(preset="arasaratnam-haykin", truth="fixed", seed=0, particles=args.particles)
    how = "spinning" if args.spin else "sleeping"
    for _ in range(args.rounds):
        engine = run_bench(args.particles, cfg=cfg, stonesoup=False)["ms_per_step"]["tl-rpf"]
        live = cfg.with_(recovery=True)
        plain = float(np.median(tl_steps_ms(cfg, "rpf", 0.0)))
        back = float(np.median(tl_steps_ms(live, "rpf", 0.0)))
        paced = float(np.median(tl_steps_ms(live, "rpf", 0.02, args.spin)))
        print(
            f"tl-rpf step p50 (ms): engine {engine:.3f}; PrimaryEpisode back to back, without"
            f" recovery {plain:.3f} ({plain / engine:.2f}x), with it {back:.3f}"
            f" ({back / engine:.2f}x); with it 20 ms apart ({how})"
            f" {paced:.3f} ({paced / engine:.2f}x)"
        )


if __name__ == "__main__":
    main()
