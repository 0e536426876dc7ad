"""What multiple-model filtering buys on manoeuvring targets: one model against the class's modes.

Truths, each at most 1200 s (:data:`TRUTHS`): the shipped AIS track (a ship), the stated turn
sequence and a light aircraft circling in wind (simulated, :mod:`~tltrack.studies.tracks`), and
five real flights' approaches (aircraft; ``scripts/extract_flights.py`` chose them by a rule fixed
before any filter ran). On each, ``rpf``, ``tl-rpf``, ``ukf`` and ``tl-ukf`` run on the same runs
twice: with the class's single coordinated turn (its ``ct`` fit) and with its modes
(``target_class``, :mod:`~tltrack.config.target_classes`); no other setting changes.

Reported per truth and filter: RMSE, the lost share (the engine's rule), the diverged share (run
RMSE over 100 m), the share of NIS windows above their 99% band, and TL - isolated paired, with
its Monte-Carlo error.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tltrack.config import Config
from tltrack.config.target_classes import TARGET_CLASSES
from tltrack.engine import plots
from tltrack.engine.montecarlo import FilterResult
from tltrack.studies.common import Runner, Setting, paired, plain, row, write

#: the longest truth, in seconds
LONGEST_S = 1200.0
#: a run whose overall RMSE passes this has diverged [m] (the study's criterion)
DIVERGED_M = 100.0
FILTERS = ("rpf", "tl-rpf", "ukf", "tl-ukf")


@dataclass(frozen=True)
class Truth:
    """A truth file of ``examples/tracks`` and the class of target it is."""

    label: str
    file: str
    target_class: str


#: the study's truths: a file of examples/tracks each, and its target class
TRUTHS = (
    Truth("ship (AIS)", "ais-nyharbor-2020-06-30-mmsi-367370920.csv", "ship"),
    Truth("turn sequence", "sim-turn-sequence.csv", "aircraft"),
    Truth("circling aircraft", "sim-circling-aircraft.csv", "aircraft"),
    *(
        Truth(f"flight {n}", f"flight-{n}.csv", "aircraft")
        for n in ("DDD004", "EEE005", "FFF006", "HHH008", "KKK011")
    ),
)
#: the two configurations on every truth
MODELS = ("one model", "modes")
#: configurations the study runs (for a progress bar)
CONFIGS = len(TRUTHS) * len(MODELS)


def configs(
    setting: Setting, truth: Truth, tracks: Path, longest_s: float = LONGEST_S
) -> dict[str, Config]:
    """The truth's two configurations: the class's single coordinated turn, and its modes, over
    the track's first ``longest_s`` seconds at most."""
    path = tracks / truth.file
    if not path.is_file():
        raise ValueError(f"{path}: no such track (give --tracks, the folder of examples/tracks)")
    cls = TARGET_CLASSES[truth.target_class]
    base = setting.config(6000, truth_file=path, scenario="ct")
    K = min(base.K, int(longest_s / base.Ts))
    return {
        "one model": base.with_(K=K, q1=cls.single["q1"], q2=cls.single["q2"]),
        "modes": base.with_(K=K, target_class=truth.target_class),
    }


def diverged(r: FilterResult) -> float:
    """The share of runs whose overall RMSE passes :data:`DIVERGED_M`."""
    return float(np.mean(~(np.asarray(r.run_rmse) <= DIVERGED_M)))


def manoeuvres(
    setting: Setting,
    runner: Runner,
    out: Path,
    *,
    tracks: Path = Path("examples/tracks"),
    longest_s: float = LONGEST_S,
) -> Path:
    """Every truth of :data:`TRUTHS`, one model against the modes (each truth at most
    ``longest_s`` seconds long)."""
    # every truth's track read and checked before the first run: a missing fifth lost four
    every = {truth.label: configs(setting, truth, tracks, longest_s) for truth in TRUTHS}
    results = {
        label: {m: runner.run(c, FILTERS) for m, c in cfgs.items()} for label, cfgs in every.items()
    }
    cfg = every[TRUTHS[-1].label]["modes"]
    lines = [
        "# Manoeuvring targets: one model against the class's modes",
        "",
        f"`{cfg.preset}`, I_p = {cfg.primary_intensity:g}, N = {cfg.particles}, {cfg.runs} "
        f"runs, seed {cfg.seed}; each truth at most {longest_s:g} s. "
        f"Diverged: run RMSE over {DIVERGED_M:g} m. NIS: the share of 20-step windows above "
        "the 99% band. TL - iso: the paired per-run RMSE difference, MC error (2 SE) in brackets.",
        "",
        row(["truth", "model", *(f"RMSE {f}" for f in FILTERS), "lost", "diverged", "NIS above"]),
        row(["---"] * (3 + len(FILTERS) + 2)),
    ]
    for label, by_model in results.items():
        for model, r in by_model.items():
            lines.append(
                row(
                    [
                        label,
                        model,
                        *(f"{r[f].rmse_overall:.1f}" for f in FILTERS),
                        " / ".join(f"{r[f].lost_fraction:.1%}" for f in FILTERS),
                        " / ".join(f"{diverged(r[f]):.1%}" for f in FILTERS),
                        " / ".join(f"{r[f].nis_above_band:.0%}" for f in FILTERS),
                    ]
                )
            )
    lines += [
        "",
        "Lost, diverged and NIS above: " + " / ".join(FILTERS) + ".",
        "",
        row(["truth", "model", "tl-rpf - rpf", "tl-ukf - ukf"]),
        row(["---"] * 4),
    ]
    for label, by_model in results.items():
        for model, r in by_model.items():
            lines.append(
                row([label, model, paired(r["tl-rpf"], r["rpf"]), paired(r["tl-ukf"], r["ukf"])])
            )
    groups = list(results)
    series = {
        f"{f}, {m}": [results[g][m][f].rmse_overall for g in groups]
        for m in MODELS
        for f in ("rpf", "tl-rpf")
    }
    plots.bars(
        groups,
        series,
        out / "manoeuvres.png",
        ylabel="position RMSE [m]",
        title="rpf and tl-rpf: one coordinated turn against the class's modes",
        log=True,
    )
    lines += ["", "![RMSE per truth, one model against the modes](manoeuvres.png)"]
    data = {f"{label} | {m}": plain(r) for label, by in results.items() for m, r in by.items()}
    return write(out, "manoeuvres", lines, data)
