"""Does a Stone Soup particle filter with the plugin get tltrack's TL gain?

Scenario 2 (coordinated turn, range-bearing, the ``arasaratnam-haykin`` preset), N = 1000, the
same truths, measurements and initial estimates as the engine's runs. Per run, both pipelines run
a source, an isolated SIR PF and a TL-PF (the source's transfer stacked with the primary's z_k,
from the second step): tltrack's engine (``pf``, ``tl-pf``, ``source-pf``) and Stone Soup's
``ParticlePredictor`` and ``ParticleUpdater`` (systematic resampling at every step) with the
plugin's models and transfer. Their random numbers differ, so they agree within Monte-Carlo
error or not at all: the share of runs each filter loses, and the TL gain (isolated minus TL
RMSE, paired per run, over every run and over the runs neither primary filter lost) with its
standard error come from each, then the gains' difference in SEs.

Usage: python papers/stonesoup/particles.py RUNS [OUT.json]
"""

from __future__ import annotations

import datetime
import json
import sys
import time
from pathlib import Path

import numpy as np
from rich.progress import Progress
from stonesoup.predictor.particle import ParticlePredictor
from stonesoup.resampler.particle import SystematicResampler
from stonesoup.types.array import StateVector, StateVectors
from stonesoup.types.detection import Detection
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.state import ParticleState
from stonesoup.updater.particle import ParticleUpdater
from tltrack.config import make_config
from tltrack.engine.montecarlo import LOST_STEPS, trace_run
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import PRIMARY, Setup, sensor_spec
from tltrack.interop.stonesoup import Motion, Sensor, detection, stacked, timestamp
from tltrack.interop.stonesoup import transfer_message as transfer

N = 1000
NAMES = ("source-pf", "pf", "tl-pf")


def stone_soup_run(setup: Setup, run: int) -> dict[str, np.ndarray]:
    """Every filter's estimates (K, n_x) of run ``run``, in Stone Soup with the plugin."""
    cfg, layout = setup.cfg, setup.motion.layout
    sim = simulate(setup, run)
    np.random.seed(run)  # Stone Soup's predictor draws from NumPy's global generator

    def sensor(i: str) -> Sensor:
        return Sensor(
            spec=sensor_spec(cfg, i),
            ndim_state=cfg.n_x,
            mapping=layout.pos,
            velocity_mapping=layout.vel,
            noise_covar=setup.sensors[i].R,
        )

    own, src = sensor(PRIMARY), sensor("s1")
    predictor = ParticlePredictor(Motion(model=setup.motion))
    updater = ParticleUpdater(None, resampler=SystematicResampler())
    T, t0 = datetime.timedelta(seconds=setup.motion.T), timestamp(0.0)
    spread = np.sqrt(np.asarray(cfg.P0_diag))[:, None]
    log_w = np.full(N, -np.log(N))

    def prior() -> ParticleState:
        cloud = sim.x0_hat[:, None] + spread * np.random.standard_normal((cfg.n_x, N))
        return ParticleState(StateVectors(cloud), log_weight=log_w.copy(), timestamp=t0)

    state = {name: prior() for name in NAMES}
    out: dict[str, list[np.ndarray]] = {name: [] for name in NAMES}
    ahead = None  # the source's prediction for the next step: its transfer's density
    sent = None
    for k in range(1, cfg.K + 1):
        t = t0 + k * T
        z = Detection(StateVector(sim.z[PRIMARY][k - 1]), timestamp=t, measurement_model=own)
        zs = Detection(StateVector(sim.z["s1"][k - 1]), timestamp=t, measurement_model=src)
        tl = (
            z
            if sent is None
            else stacked([z, detection(sent, ndim_state=cfg.n_x, mapping=layout.pos)], when=t)
        )
        for name, d in (("source-pf", zs), ("pf", z), ("tl-pf", tl)):
            prediction = (
                ahead
                if name == "source-pf" and ahead is not None
                else predictor.predict(state[name], timestamp=t)
            )
            state[name] = updater.update(SingleHypothesis(prediction, d))
            out[name].append(np.asarray(state[name].mean, dtype=float)[:, 0])
        ahead = predictor.predict(state["source-pf"], timestamp=t + T)
        sent = transfer(ahead, src, episode="e", source="s1", k=k, t_sensor=float(k))
    return {name: np.array(v) for name, v in out.items()}


def position_errors(setup: Setup, truth: np.ndarray, est: np.ndarray) -> np.ndarray:
    """|p_hat_k - p_k| for k = 1..K."""
    pos = setup.motion.layout.pos
    return np.hypot(est[:, pos[0]] - truth[1:, pos[0]], est[:, pos[1]] - truth[1:, pos[1]])


def summary(rmse: dict[str, np.ndarray], lost: dict[str, np.ndarray]) -> dict[str, float]:
    """Lost shares, and the TL gain (isolated minus TL RMSE, paired per run) over every run and
    over the runs that neither primary filter lost (a lost run's RMSE is its divergence's, not
    the filter's accuracy), each with its standard error."""
    out: dict[str, float] = {}
    for n in NAMES:
        p = float(lost[n].mean())
        out[f"lost_{n}"] = p
        out[f"lost_{n}_se"] = float(np.sqrt(p * (1 - p) / len(lost[n])))
    kept = ~(lost["pf"] | lost["tl-pf"])
    for label, runs in (("all", np.ones_like(kept)), ("kept", kept)):
        gain = (rmse["pf"] - rmse["tl-pf"])[runs]
        out[f"runs_{label}"] = int(runs.sum())
        for n in NAMES:
            out[f"rmse_{n}_{label}"] = float(rmse[n][runs].mean())
        out[f"gain_{label}_m"] = float(gain.mean())
        out[f"gain_{label}_se_m"] = float(gain.std(ddof=1) / np.sqrt(len(gain)))
    return out


def main(runs: int, out: Path | None) -> None:
    cfg = make_config(scenario="ct", preset="arasaratnam-haykin", runs=runs, particles=N)
    setup = Setup(cfg)
    rmse = {p: {n: np.empty(runs) for n in NAMES} for p in ("tltrack", "stonesoup")}
    lost = {p: {n: np.empty(runs, bool) for n in NAMES} for p in ("tltrack", "stonesoup")}
    seconds = {"tltrack": 0.0, "stonesoup": 0.0}
    with Progress() as bar:
        task = bar.add_task("runs", total=runs)
        for r in range(runs):
            truth = simulate(setup, r).truth
            for pipeline, go in (
                ("tltrack", lambda r=r: trace_run(cfg, list(NAMES), r)),
                ("stonesoup", lambda r=r: stone_soup_run(setup, r)),
            ):
                t = time.perf_counter()
                est = go()
                seconds[pipeline] += time.perf_counter() - t
                for n in NAMES:
                    e = position_errors(setup, truth, est[n])
                    rmse[pipeline][n][r] = np.sqrt(np.mean(e**2))
                    lost[pipeline][n][r] = e[-LOST_STEPS:].min() > cfg.lost_threshold_m
            bar.advance(task)
    result = {p: summary(rmse[p], lost[p]) for p in rmse}
    a, b = result["tltrack"], result["stonesoup"]
    for label in ("all", "kept"):
        se = float(np.hypot(a[f"gain_{label}_se_m"], b[f"gain_{label}_se_m"]))
        result[f"gain_{label}_difference_in_se"] = (
            a[f"gain_{label}_m"] - b[f"gain_{label}_m"]
        ) / se
    result["runs"] = runs
    result["particles"] = N
    result["seconds"] = seconds
    print(json.dumps(result, indent=2))
    if out is not None:
        out.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main(int(sys.argv[1]), Path(sys.argv[2]) if len(sys.argv) > 2 else None)
