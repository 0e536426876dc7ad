"""``tltrack bench --clutter``: a particle filter's step on a scan of 1000 detections against its
clean step, side by side.

Both filters (``rpf`` and ``pf``, each clean and in clutter) filter one run (B = 1) of Scenario 2
under the paper preset with N particles, through the step driver. At every step the cluttered one
gets a scan of the target's measurement (pd = 1) plus 999 false alarms uniform in a box centred
on the target's noise-free measurement, sized so that the mean number of false alarms in the 99%
gate of the sensor's noise is ``in_gate`` (2 by default). The filters are told that density
over the sensor's whole default field of view (false alarms far from the target change no
likelihood, only the scan's size), so the box follows the target at no cost to it.
The steps alternate (clean, cluttered, clean, ...) at every k, so load hits both alike; the
figures are medians over every step of every repeat and their ratio (the aim is <= 2 at
N = 6000), with each filter's RMSE over the timed steps.

With Stone Soup installed (``pip install -e .[stonesoup]``), its expected-likelihood particle filter
(``SingleTargetExpectedLikelihoodParticleFilter`` with a ``PDAHypothesiser``, its
``ConstantTurn`` model and the same N) runs the first ``stonesoup_steps`` scans (10) of the last
repeat (it is slow), beside ours on the same scans. ``benchmarks/clutter_step.py`` sets both
(``--in-gate``, ``--stonesoup-steps``).

    tltrack bench --clutter [--particles 6000] [--repeats 3] [--json FILE]
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from tltrack.config import make_config
from tltrack.engine.driver import Primaries
from tltrack.engine.registry import parse
from tltrack.engine.scenario import simulate
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.filters.association import gate_volume
from tltrack.models.detection import Detection
from tltrack.models.scan import Scan


def stonesoup_elpf(
    setup: Setup, x0_hat: np.ndarray, N: int, density: float, seed: int
) -> Callable[[int, np.ndarray], np.ndarray] | None:
    """Stone Soup's ELPF on the primary's radar, as a function of (k, scan (M, 2)) -> estimate
    (n_x,); None without Stone Soup."""
    try:
        from stonesoup.dataassociator.probability import PDA
        from stonesoup.deleter import Deleter
        from stonesoup.hypothesiser.probability import PDAHypothesiser
        from stonesoup.initiator import Initiator
        from stonesoup.tracker.particle import SingleTargetExpectedLikelihoodParticleFilter
        from stonesoup.types.track import Track
        from stonesoup.updater.particle import ParticleUpdater
        from tltrack.perf.stonesoup_anchor import T0, anchor
    except ImportError:
        return None
    ss = anchor(setup, x0_hat, N, seed)
    updater = ParticleUpdater(ss.radar, resampler=None)

    class Given(Initiator):
        def initiate(self, detections: Any, timestamp: Any, **kwargs: Any) -> set[Any]:
            return {Track([ss.prior])}

    class Never(Deleter):
        def check_for_deletion(self, track: Any, **kwargs: Any) -> bool:
            return False

    scans: list[tuple[Any, set[Any]]] = []
    hyp = PDAHypothesiser(ss.predictor, updater, density, prob_detect=1.0, prob_gate=0.99)
    tracker = SingleTargetExpectedLikelihoodParticleFilter(
        initiator=Given(),
        deleter=Never(),
        detector=scans,
        data_associator=PDA(hyp),
        updater=updater,
    )
    scans.append((T0, set()))  # the first call initiates the track at T0
    steps = iter(tracker)
    next(steps)

    def step(k: int, Z: np.ndarray) -> np.ndarray:
        scans.append((ss.at(k), {ss.detection(r, b, k) for r, b in Z}))
        _, tracks = next(steps)
        return np.asarray(next(iter(tracks)).state.mean, dtype=float).ravel()

    return step


def run_clutter_bench(
    particles: int = 6000,
    repeats: int = 3,
    steps: int = 100,
    detections: int = 1000,
    in_gate: float = 2.0,
    stonesoup_steps: int = 10,
) -> dict[str, Any]:
    """Median ms per step of ``rpf`` and ``pf``, clean and on dense scans, their ratios and RMSE,
    and Stone Soup's ELPF beside them when it is installed (the module's docstring)."""
    names = ("rpf", "pf")
    ms: dict[str, list[float]] = {f"{n}{c}": [] for n in names for c in ("", " in clutter")}
    sq: dict[str, list[float]] = {k: [] for k in ms}  # squared position errors, timed steps
    early: dict[str, list[float]] = {}  # the same over the steps Stone Soup runs
    for rep in range(repeats + 1):  # the first pass compiles and warms up, untimed
        setup = Setup(make_config(particles=particles, K=steps, seed=rep))
        sim = simulate(setup, 0)
        own = setup.sensors[PRIMARY]
        sr, sb = np.sqrt(np.diag(own.R))
        # V / V_gate = (clutter per scan) / (clutter in the gate); the box keeps R's aspect
        gate = gate_volume(own.R)
        half = math.sqrt((detections - 1) * gate / in_gate / 4.0) / math.sqrt(sr * sb)
        rng = np.random.default_rng(rep)
        # what the filters are told: that density over the sensor's whole (default) field of
        # view, pd = 1 everywhere in it; the scan draws it only in the box around the target
        density = (detections - 1) / ((2 * half * sr) * (2 * half * sb))
        wide = Detection(own.model.components, 1.0)
        d = Detection(own.model.components, 1.0, density * wide.volume)
        x0 = sim.x0_hat[:, None]
        clean = Primaries(setup, [parse(n) for n in names], x0, [0])
        dirty = Primaries(setup, [parse(n) for n in names], x0, [0])
        last = rep == repeats
        ss = None
        if last and stonesoup_steps > 0:
            ss = stonesoup_elpf(setup, sim.x0_hat, particles, density, rep)
            if ss is not None:
                ms["stonesoup elpf"], sq["stonesoup elpf"] = [], []
        for k in range(1, steps + 1):
            centre = own.model.h(sim.truth[k][:, None])[:, 0]
            lo, hi = centre - half * np.array([sr, sb]), centre + half * np.array([sr, sb])
            Z = np.vstack([sim.z[PRIMARY][k - 1], rng.uniform(lo, hi, (detections - 1, 2))])
            scan = Scan.pack(own.model, [rng.permutation(Z)], own.R, d)
            z = own.observe(sim.z[PRIMARY][k - 1])
            truth = sim.truth[k][[0, 2]]
            for n in names:
                for half_, stmt, label in ((clean, z, n), (dirty, scan, f"{n} in clutter")):
                    t0 = time.perf_counter()
                    est = half_.step(k, stmt, lambda _s: [], [n])[n].mean[0]
                    if rep:
                        ms[label].append((time.perf_counter() - t0) * 1e3)
                        e2 = float(np.sum((est[[0, 2]] - truth) ** 2))
                        sq[label].append(e2)
                        if last and ss is not None and k <= stonesoup_steps:
                            early.setdefault(label, []).append(e2)
            if ss is not None and k <= stonesoup_steps:
                t0 = time.perf_counter()
                est = ss(k, scan.z[:, 0, :].T)
                ms["stonesoup elpf"].append((time.perf_counter() - t0) * 1e3)
                e2 = float(np.sum((est[[0, 2]] - truth) ** 2))
                sq["stonesoup elpf"].append(e2)
                early.setdefault("stonesoup elpf", []).append(e2)
    med = {k: float(np.median(v)) for k, v in ms.items()}
    out = {
        "particles": particles,
        "detections_per_scan": detections,
        "false_alarms_in_gate": in_gate,
        "steps_timed": len(ms["rpf"]),
        "median_ms": med,
        "ratio": {n: med[f"{n} in clutter"] / med[n] for n in names},
        "rmse_m": {k: float(np.sqrt(np.mean(v))) for k, v in sq.items() if v},
        "first_steps": len(early.get("stonesoup elpf", [])),
        "rmse_first_steps_m": {k: float(np.sqrt(np.mean(v))) for k, v in early.items()},
    }
    if "stonesoup elpf" in med:
        out["stonesoup_over_ours"] = {
            n: med["stonesoup elpf"] / med[f"{n} in clutter"] for n in names
        }
    return out


def format_clutter_table(result: dict[str, Any]) -> str:
    """The clutter bench's result as a small text table."""
    lines = [f"{'filter':<18}{'ms/step':>10}{'RMSE [m]':>10}"]
    for name, v in result["median_ms"].items():
        lines.append(f"{name:<18}{v:>10.3f}{result['rmse_m'][name]:>10.1f}")
    for name, v in result["ratio"].items():
        lines.append(f"{name} in clutter / clean: {v:.2f}x")
    for name, v in result.get("stonesoup_over_ours", {}).items():
        lines.append(f"stonesoup elpf / {name} in clutter: {v:.1f}x")
    return "\n".join(lines)
