"""How much clutter a "light" 0.05 false alarms per gate is to a filter: the gate of R, in which the
study counts clutter, against the gate of the filter's own predicted measurement N(z_hat, S),
in which false alarms compete with the target. Both are ellipses of the same probability, so
their areas are in the ratio sqrt(det S / det R).

The source's transfer (eta_hat, P_eta_eta) is that predicted measurement, R included. So a
source with each intensity, clean (pd = 1, no clutter) under the study's setting (paper preset,
fixed truth, N = 6000), gives the ratio at every step of every run: intensity 1 is the study's
source, intensity 4 the primary's sensor. Usage: python papers/clutter/gates.py RUNS"""

import sys

import numpy as np
from tltrack.config import make_config
from tltrack.engine.driver import Driver, StepRecord
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import Setup


def ratios(intensity: float, runs: int) -> dict[str, np.ndarray]:
    """sqrt(det S / det R) at every run-step of each source filter with that intensity."""
    cfg = make_config(
        preset="paper",
        truth="fixed",
        primary_intensity=4,
        particles=6000,
        runs=runs,
        sources=[{"id": "s1", "intensity": intensity}],
    )
    setup = Setup(cfg)
    det_R = np.linalg.det(setup.sensors["s1"].R)
    found: dict[str, list[np.ndarray]] = {}

    def keep(record: StepRecord) -> None:
        if record.transfer is not None:
            det_S = np.linalg.det(record.transfer.cov)
            found.setdefault(record.name, []).append(np.sqrt(det_S / det_R))

    sims = [simulate(setup, r) for r in range(runs)]
    x0_hat = np.stack([s.x0_hat for s in sims], axis=1)
    driver = Driver([setup], ["tl-rpf", "tl-ukf"], x0_hat, list(range(runs)), collectors=[[keep]])
    for k in range(1, cfg.K + 1):
        z = {i: setup.sensors[i].statement(np.stack([s.z[i][k - 1] for s in sims], axis=1), None)
             for i in setup.sensor_ids}  # fmt: skip
        driver.step(k, [z])
    return {name: np.concatenate(v) for name, v in found.items()}


runs = int(sys.argv[1])
for intensity in (1.0, 4.0):
    for name, a in ratios(intensity, runs).items():
        print(
            f"intensity {intensity:g}, {name}: sqrt(det S / det R) median {np.median(a):.2f}, "
            f"10-90% [{np.percentile(a, 10):.2f}, {np.percentile(a, 90):.2f}] over {a.size} "
            f"run-steps; 0.05 per gate of R is {0.05 * np.median(a):.2f} per gate of S"
        )
