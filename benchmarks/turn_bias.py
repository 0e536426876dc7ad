"""Why does ``tl-rpf`` fed by ``source-rpf`` trail ``tl-ukf`` on one fixed truth? Two checks of
docs/rpf.md ("The one 1000-run cell where `tl-rpf` trails `tl-ukf`"):

- **Are the sources' transfers consistent?** The mean NIS of the source's next measurement
  z_{k+1} under its transfer (eta_hat_{k+1}, P_eta_eta): 2 (n_z) if P_eta_eta is honest.
- **Do the filters share a bias?** On a fixed truth every run follows the same trajectory, so
  the mean over runs of the position error at step k is the filter's systematic error (a lag in
  the turns, say); the cosine between two filters' bias sequences says whether they err the
  same way, and the correlation of what is left over, whether their random errors do.

    .venv/bin/python benchmarks/turn_bias.py [--runs 100] [--truth-seed 4]
"""

from __future__ import annotations

import argparse

import numpy as np
from tltrack.config import Config, make_config
from tltrack.engine.montecarlo import run_batch
from tltrack.engine.scenario import simulate, truth
from tltrack.filters.warm import warm_up
from tltrack.messages import Measurement
from tltrack.models.base import MeasurementModel
from tltrack.tracking import SourceEpisode

Array = np.ndarray


def transfer_nis(cfg: Config, kind: str, runs: int) -> float:
    """Mean over runs and steps of (z_{k+1} - eta)' P_eta^-1 (z_{k+1} - eta) for source s1."""
    nis = []
    for run in range(runs):
        z = simulate(cfg, run).z["s1"]
        src = SourceEpisode(cfg, run, kind, "s1")
        sensor: MeasurementModel = src.sensor.model
        eta = None
        for k, z_k in enumerate(z, start=1):
            if eta is not None:
                d = sensor.residual(z_k[:, None, None], eta.mean[:, :, None])[:, 0, 0]
                nis.append(float(d @ np.linalg.solve(eta.cov[0], d)))
            m = Measurement(episode="e", sender="s1", k=k, t_sensor=0.0, sensor="s1", z=z_k)
            _, eta = src.step(m)
    return float(np.mean(nis))


def position_errors(cfg: Config, names: list[str], runs: int) -> dict[str, Array]:
    """Position error (K, runs, 2) of each filter (and of the sources the TL ones need)."""
    stats = run_batch(cfg, names, list(range(runs)), keep_tracks=True)
    x = truth(cfg, 0)
    out = {}
    for name, s in stats.items():
        t = np.concatenate(s.tracks, axis=1)  # (K, B, n)
        out[name] = np.stack([t[:, :, 0] - x[1:, None, 0], t[:, :, 2] - x[1:, None, 2]], axis=-1)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--truth-seed", type=int, default=4)
    ap.add_argument("--particles", type=int, default=6000)
    args = ap.parse_args()
    warm_up()
    cfg = make_config(
        preset="arasaratnam-haykin",
        truth="fixed",
        truth_seed=args.truth_seed,
        seed=0,
        particles=args.particles,
        primary_intensity=4.0,
    )
    for kind in ("rpf", "ukf"):
        print(
            f"source-{kind}: mean NIS of z_(k+1) under its transfer (2 if honest):"
            f" {transfer_nis(cfg, kind, args.runs):.2f}"
        )
    err = position_errors(cfg, ["rpf", "ukf", "tl-rpf", "tl-ukf"], args.runs)
    bias = {n: e.mean(axis=1) for n, e in err.items()}  # (K, 2)
    print("filter       |bias| mean over k, in the two turns (k = 25-35, 80-90) [m]")
    for n, b in bias.items():
        size = np.linalg.norm(b, axis=1)
        print(f"{n:12s} {size.mean():6.2f}  {size[24:35].mean():6.2f}  {size[79:90].mean():6.2f}")
    for a, b in [("source-rpf", "rpf"), ("source-ukf", "ukf"), ("source-ukf", "rpf")]:
        cos = (bias[a] * bias[b]).sum() / np.linalg.norm(bias[a]) / np.linalg.norm(bias[b])
        ra, rb = err[a] - bias[a][:, None], err[b] - bias[b][:, None]
        corr = (ra * rb).sum() / np.sqrt((ra * ra).sum() * (rb * rb).sum())
        print(f"{a} and {b}: bias cosine {cos:.3f}, random-error correlation {corr:.3f}")


if __name__ == "__main__":
    main()
