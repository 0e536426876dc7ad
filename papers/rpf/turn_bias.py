"""Why does ``tl-rpf`` fed by ``source-rpf`` trail ``tl-ukf`` on one fixed truth? Two checks of
papers/rpf/README.md ("The one 1000-run cell where `tl-rpf` trails `tl-ukf`"):

- **Are the sources' transfers consistent?** The mean NIS of the source's next measurement
  z_{k+1} under its transfer (eta_hat_{k+1}, P_eta_eta): 2 (n_z) if P_eta_eta is honest.
- **Do the filters share a bias?** On a fixed truth every run follows the same trajectory, so
  the mean over runs of the position error at step k is the filter's systematic error (a lag in
  the turns, say); the cosine between two filters' bias sequences says whether they err the
  same way, and the correlation of what is left over, whether their random errors do.

Every filter (and the sources the TL ones listen to) steps once, in one batch of the runs, through
the step driver; a collector keeps the estimates and the sources' transfers.

    .venv/bin/python papers/rpf/turn_bias.py [--runs 100] [--truth-seed 4]
"""

from __future__ import annotations

import argparse
from collections import defaultdict

import numpy as np
from tltrack.config import make_config
from tltrack.engine.driver import Driver, StepRecord
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import Setup
from tltrack.filters.warm import warm_up
from tltrack.models.observation import Observation

Array = np.ndarray


class Record:
    """A collector: each filter's estimated mean (B, n_x) and each source's transfer, per step."""

    def __init__(self) -> None:
        self.means: dict[str, list[Array]] = defaultdict(list)
        self.transfers: dict[str, list[Observation]] = defaultdict(list)

    def __call__(self, r: StepRecord) -> None:
        self.means[r.name].append(r.estimate.mean)
        if r.transfer is not None:
            self.transfers[r.name].append(r.transfer)


def transfer_nis(transfers: list[Observation], z: Array) -> float:
    """Mean over runs and steps of (z_{k+1} - eta)' P_eta^-1 (z_{k+1} - eta); the transfer of
    step k is for k + 1, z (K, n_z, B) the source's measurements."""
    nis = []
    for eta, z_next in zip(transfers[:-1], z[1:], strict=True):
        d = eta.sensor.residual(z_next[:, :, None], eta.mean[:, :, None])[:, :, 0].T  # (B, n_z)
        nis.append(np.einsum("bi,bi->b", d, np.linalg.solve(eta.cov, d[:, :, None])[:, :, 0]))
    return float(np.mean(nis))


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
    setup, runs = Setup(cfg), list(range(args.runs))
    sims = [simulate(setup, r) for r in runs]
    z = {i: np.stack([s.z[i] for s in sims], axis=2) for i in setup.sensor_ids}  # (K, n_z, B)
    record = Record()
    x0_hat = np.stack([s.x0_hat for s in sims], axis=1)
    driver = Driver(
        [setup], ["rpf", "ukf", "tl-rpf", "tl-ukf"], x0_hat, runs, collectors=[[record]]
    )
    for k in range(1, cfg.K + 1):
        driver.step(k, [{i: setup.sensors[i].observe(z[i][k - 1]) for i in setup.sensor_ids}])
    for kind in ("rpf", "ukf"):
        nis = transfer_nis(record.transfers[f"source-{kind}"], z["s1"])
        print(f"source-{kind}: mean NIS of z_(k+1) under its transfer (2 if honest): {nis:.2f}")
    x = np.stack([s.truth for s in sims], axis=1)[1:]  # (K, B, n_x)
    pos = list(setup.layout.pos)
    err = {n: (np.stack(m) - x)[:, :, pos] for n, m in record.means.items()}  # (K, B, 2)
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
