"""How much clutter does each filter stand? The lost share against the false alarms in the gate.

The clutter density is given as ``clutter_per_gate``: the mean number of false alarms per scan
inside the 99% gate of the sensor's own noise around the target's noise-free measurement,
{z : (z - h(x))' R^-1 (z - h(x)) <= chi2_{n_z}(0.99)}, of volume V_G = pi gamma sqrt(det R) for
n_z = 2 (:func:`gate_volume`). False alarms are uniform over the field of view (volume V), so
clutter_rate = clutter_per_gate V / V_G.

With the default field of view (20 km x 2 pi) one false alarm per gate is tens of thousands of
detections per scan, so the study sizes each sensor's field of view around the truth
(:func:`field_of_view`): the extent of the truth's noise-free measurements plus
:data:`MARGIN_SIGMAS` of the sensor's noise standard deviations on each side. The truth is fixed
(one trajectory for every run), so that box holds every run's target.

Grid: :data:`DENSITIES` x :data:`PDS` for the primary; the source has light clutter
(:data:`SOURCE_PER_GATE` per gate, pd :data:`SOURCE_PD`). One sweep per pd: its configurations
differ only in the primary's detection process, so the truths and the sources (their filters and
transfers) are shared across the sweep's cells, and the runs are paired across cells.

Reported per cell: the clutter per gate measured from the scans the engine drew (the same
streams: :func:`measured_per_gate`), and per filter the RMSE and the lost share. Headline: per pd,
the density at which each filter's lost share reaches 5%, interpolated in log density
(:func:`density_at`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import NDArray

from tltrack.config import Config
from tltrack.engine.registry import parse
from tltrack.engine.scenario import simulate, truth
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.filters import chi2
from tltrack.filters.association import gate_volume
from tltrack.studies.common import Results, Runner, Setting, plain, row, write

Array = NDArray[np.float64]

#: the primary's clutter densities, false alarms per scan inside the 99% gate of its noise
DENSITIES = (0.0, 0.05, 0.2, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)
#: the primary's probabilities of detection
PDS = (1.0, 0.9, 0.7)
#: the source's light clutter, false alarms per scan inside its gate
SOURCE_PER_GATE = 0.05
#: the source's probability of detection
SOURCE_PD = 0.95
#: the gate's probability: the clutter is counted in this gate of the sensor's own noise
GATE_PROBABILITY = 0.99
#: the field of view's margin beyond the truth's measurements, in noise standard deviations: far
#: enough that no cloud near the target meets the edge, beyond which a particle explains every
#: detection as clutter (at 10, the edge trapped clouds in a turn: papers/clutter/README.md)
MARGIN_SIGMAS = 50.0
#: the lost share whose density the headline reports
LOST_LEVEL = 0.05
FILTERS = ("rpf", "tl-rpf", "robust-tl-rpf", "fusion-rpf", "ukf", "tl-ukf")
#: sweeps the study runs (one per pd), for a progress bar
SWEEPS = len(PDS)


def _arc(angles: Array) -> tuple[float, float]:
    """The shortest arc [lo, hi] (lo > hi across +-pi) holding every angle."""
    a = np.sort(np.mod(angles + math.pi, 2 * math.pi) - math.pi)
    gaps = np.diff(np.r_[a, a[0] + 2 * math.pi])
    i = int(np.argmax(gaps))  # the arc starts after the largest gap
    return float(a[(i + 1) % len(a)]), float(a[i])


def field_of_view(setup: Setup, sensor_id: str = PRIMARY) -> dict[str, tuple[float, float]]:
    """Each component's interval: the extent of run 0's noise-free measurements, plus
    :data:`MARGIN_SIGMAS` noise standard deviations each side (a bearing arc wider than the
    circle becomes the circle)."""
    own = setup.sensors[sensor_id]
    z = own.model.h(truth(setup, 0)[1:].T)  # (n_z, K)
    sigma = np.sqrt(np.diag(own.R))
    fov = {}
    for i, c in enumerate(own.model.components):
        m = MARGIN_SIGMAS * float(sigma[i])
        if c.endswith("_rad"):
            lo, hi = _arc(z[i])
            width = (hi - lo) % (2 * math.pi) + 2 * m
            if width >= 2 * math.pi:
                fov[c] = (-math.pi, math.pi)
            else:
                wrap = lambda v: float(np.mod(v + math.pi, 2 * math.pi) - math.pi)  # noqa: E731
                fov[c] = (wrap(lo - m), wrap(hi + m))
        else:
            lo, hi = float(z[i].min()) - m, float(z[i].max()) + m
            if c == "range_m":
                lo = max(lo, 0.0)
            fov[c] = (lo, hi)
    return fov


def detection(
    setup: Setup, sensor_id: str, per_gate: float, pd: float, fov: dict[str, tuple[float, float]]
) -> dict[str, Any]:
    """The config's detection process with ``per_gate`` false alarms per gate over ``fov``."""
    from tltrack.models.detection import Detection

    own = setup.sensors[sensor_id]
    volume = Detection(tuple(own.model.components), fov=fov).volume
    rate = per_gate * volume / gate_volume(own.R)
    return {"pd": pd, "clutter_rate": rate, "fov": {c: list(v) for c, v in fov.items()}}


def configs(
    setting: Setting,
    pd: float,
    densities: Sequence[float] = DENSITIES,
    source: tuple[float, float] = (SOURCE_PD, SOURCE_PER_GATE),
    **changes: Any,
) -> list[Config]:
    """One configuration per density at ``pd``, differing only in the primary's detection;
    ``source`` is the sources' (pd, clutter per gate), (1, 0) the paper's sensor."""
    base = setting.config(6000, preset="paper", truth="fixed", **changes)
    setup = Setup(base)
    sid = setup.source_ids[0]
    if source != (1.0, 0.0):
        src = detection(setup, sid, source[1], source[0], field_of_view(setup, sid))
        sources = [{**s.model_dump(exclude_none=True), "detection": src} for s in base.sources]
        base = base.with_(sources=sources)
    fov = field_of_view(setup)
    return [base.with_(primary_detection=detection(setup, PRIMARY, d, pd, fov)) for d in densities]


def measured_per_gate(cfg: Config, sensor_id: str = PRIMARY) -> tuple[float, int]:
    """The false alarms per scan inside the 99% gate of the sensor's noise around the truth's
    noise-free measurement, over every run and step of ``cfg`` (the engine's own draws), and
    how many scans that mean is over."""
    setup = Setup(cfg)
    own = setup.sensors[sensor_id]
    Ri = np.linalg.inv(own.R)
    gamma = chi2.quantile(GATE_PROBABILITY, own.model.n_z)
    count, scans = 0, 0
    for run in range(cfg.runs):
        sim = simulate(setup, run)
        if sensor_id not in sim.scans:
            scans += cfg.K
            continue
        drawn = sim.scans[sensor_id]
        h = own.model.h(sim.truth[1:].T)  # (n_z, K)
        for k, (Z, c) in enumerate(zip(drawn.detections, drawn.is_clutter, strict=True)):
            nu = own.model.residual(Z[c].T, h[:, k : k + 1])  # (n_z, M)
            count += int((np.einsum("im,ij,jm->m", nu, Ri, nu) <= gamma).sum())
            scans += 1
    return count / scans, scans


def density_at(
    densities: Sequence[float], lost: Sequence[float], level: float = LOST_LEVEL
) -> tuple[float | None, str]:
    """The density at which the lost share first reaches ``level``, interpolated linearly in
    log density between the grid's points on either side, and a note: ``""``, ``"not reached"``
    (below ``level`` everywhere) or ``"below the grid"`` (reached at the grid's first point, or
    between a zero density and the first positive one, where log density has no interval)."""
    for i, (d, v) in enumerate(zip(densities, lost, strict=True)):
        if v < level:
            continue
        if i == 0 or densities[i - 1] <= 0:
            return None, "below the grid"
        d0, v0 = densities[i - 1], lost[i - 1]
        t = (level - v0) / (v - v0)
        return float(math.exp(math.log(d0) + t * (math.log(d) - math.log(d0)))), ""
    return None, "not reached"


def describe_density(found: tuple[float | None, str], densities: Sequence[float]) -> str:
    value, note = found
    if value is not None:
        return f"{value:.3g}"
    positive = [d for d in densities if d > 0]
    if note == "not reached":
        return f"not reached (> {max(densities):g})"
    return f"below the grid (<= {min(positive):g})" if positive else note


def factor(
    a: tuple[float | None, str], b: tuple[float | None, str], densities: Sequence[float]
) -> str:
    """a's 5%-loss density over b's, or the bound the grid allows."""
    (va, na), (vb, nb) = a, b
    positive = [d for d in densities if d > 0]
    top, bottom = max(densities), min(positive) if positive else 0.0
    if va is not None and vb is not None:
        return f"{va / vb:.2f}"
    if va is None and na == "not reached" and vb is not None:
        return f"> {top / vb:.2f} (the first not reached on the grid)"
    if va is not None and vb is None and nb == "below the grid" and bottom > 0:
        return f">= {va / bottom:.2f} (the second below the grid)"
    if va is None and vb is None and na == nb:
        return f"undetermined (both {na})"
    return f"undetermined ({na or f'{va:.3g}'} against {nb or f'{vb:.3g}'})"


def plot(
    densities: Sequence[float],
    lost: dict[float, dict[str, list[float]]],
    path: Path,
) -> Path:
    """Lost share against clutter per gate (log x; the zero density drawn at half the first
    positive one), one line per filter, one panel per pd. Each filter has a colour of its own
    (four of them are particle filters) and its role's line style; the particle filters have
    round markers, the others square."""
    from tltrack.engine.plots import _style

    positive = [d for d in densities if d > 0]
    zero_at = min(positive) / 2 if positive else 1.0
    xs = [d if d > 0 else zero_at for d in densities]
    fig, axes = plt.subplots(1, len(lost), figsize=(4.2 * len(lost), 4.3), sharey=True)
    axes = np.atleast_1d(axes)
    for ax, (pd, by_filter) in zip(axes, lost.items(), strict=True):
        for i, (name, ys) in enumerate(by_filter.items()):
            marker = "o" if parse(name).particle else "s"
            style = {**_style(name), "color": f"C{i}", "marker": marker}
            ax.plot(xs, [100 * y for y in ys], label=name, **{**style, "markevery": 1})
        ax.axhline(100 * LOST_LEVEL, color="grey", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_xlabel(f"false alarms per 99% gate (0 drawn at {zero_at:g})")
        ax.set_title(f"pd = {pd:g}")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("lost runs [%]")
    handles, labels = axes[0].get_legend_handles_labels()  # below the panels, off the lines
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def clutter(
    setting: Setting,
    runner: Runner,
    out: Path,
    *,
    densities: Sequence[float] = DENSITIES,
    pds: Sequence[float] = PDS,
    filters: Sequence[str] = FILTERS,
    source: tuple[float, float] = (SOURCE_PD, SOURCE_PER_GATE),
    **changes: Any,
) -> Path:
    """Every filter of ``filters`` at every (pd, density) of the grid, the sources' (pd, clutter
    per gate) ``source``; ``changes`` go to the base configuration (a test's short K)."""
    names = list(filters)
    swept: dict[float, list[Results]] = {}
    cells: dict[float, list[Config]] = {}
    for pd in pds:
        cells[pd] = configs(setting, pd, densities, source, **changes)
        swept[pd] = runner.sweep(cells[pd], names, time_steps=False)
    # every scan drawn again to count its false alarms in the gate (at 200 runs, 5 min on one
    # core): in the pool
    counted = iter(runner.map(measured_per_gate, [c for pd in pds for c in cells[pd]]))
    measured = {pd: [next(counted) for _ in cells[pd]] for pd in pds}
    base = cells[pds[0]][0]
    setup = Setup(base)
    sid = setup.source_ids[0]
    fov = dict(base.primary_detection.fov) if base.primary_detection else {}
    src = next(s for s in base.sources if s.id == sid).detection
    src_text = (
        "the paper's sensor: every scan its target's measurement alone"
        if src is None
        else f"pd {src.pd:g}, {source[1]:g} per gate (clutter_rate {src.clutter_rate:.4g}) over "
        "its own field of view"
    )
    src_gate = gate_volume(setup.sensors[sid].R)
    own_gate = gate_volume(setup.sensors[PRIMARY].R)
    fov_text = ", ".join(f"{c} [{lo:.4g}, {hi:.4g}]" for c, (lo, hi) in fov.items())
    lost = {pd: {f: [r[f].lost_fraction for r in swept[pd]] for f in names} for pd in pds}
    found = {pd: {f: density_at(densities, lost[pd][f]) for f in names} for pd in pds}
    lines = [
        "# Clutter: the lost share against the false alarms in the gate",
        "",
        f"`{base.preset}`, fixed truth (seed {base.truth_seed}), I_p = "
        f"{base.primary_intensity:g}, N = {base.particles}, K = {base.K}, {base.runs} runs per "
        f"cell, seed {base.seed}. Clutter per gate: mean false alarms per scan inside the 99% "
        "gate of the sensor's own noise around the target's noise-free measurement (gate "
        f"volume {own_gate:.4g} for the primary, {src_gate:.4g} for the source). Field of view "
        f"(sized around the truth: its noise-free measurements' extent plus {MARGIN_SIGMAS:g} "
        f"noise standard deviations each side): {fov_text}; clutter_rate = clutter per gate x "
        f"{fov_and_gate(base, PRIMARY):.4g}. Source: {src_text}. Lost: error over "
        f"{base.lost_threshold_m:g} m in each of the last 10 steps. Measured: false alarms "
        "counted in that gate in the scans drawn (every run and step), with 2 Poisson SE.",
        "",
        row(["pd", "per gate", "measured (2 SE)", *(f"RMSE {f}" for f in names), "lost"]),
        row(["---"] * (4 + len(names))),
    ]
    data: dict[str, Any] = {
        "setting": {
            "preset": base.preset,
            "truth": base.truth,
            "particles": base.particles,
            "runs": base.runs,
            "K": base.K,
            "seed": base.seed,
            "filters": names,
            "fov": {c: list(v) for c, v in fov.items()},
            "margin_sigmas": MARGIN_SIGMAS,
            "gate_volume": own_gate,
            "source_detection": None if src is None else src.model_dump(),
        },
        "cells": {},
        "lost_5pct_density": {},
    }
    for pd in pds:
        for d, r, cfg, (m, n) in zip(densities, swept[pd], cells[pd], measured[pd], strict=True):
            se = math.sqrt(m / n) if n else float("nan")
            lines.append(
                row(
                    [
                        f"{pd:g}",
                        f"{d:g}",
                        f"{m:.3f} ({2 * se:.3f})",
                        *(f"{r[f].rmse_overall:.1f}" for f in names),
                        " / ".join(f"{r[f].lost_fraction:.0%}" for f in names),
                    ]
                )
            )
            assert cfg.primary_detection is not None
            data["cells"][f"pd {pd:g} | {d:g}"] = {
                "pd": pd,
                "clutter_per_gate": d,
                "clutter_rate": cfg.primary_detection.clutter_rate,
                "measured_per_gate": m,
                "measured_scans": n,
                "filters": plain(r),
            }
        data["lost_5pct_density"][f"{pd:g}"] = {
            f: {"density": v, "note": note} for f, (v, note) in found[pd].items()
        }
    lines += [
        "",
        "Lost: " + " / ".join(names) + ".",
        "",
        f"## Clutter per gate at which the lost share reaches {LOST_LEVEL:.0%}",
        "",
        "Interpolated linearly in log density between the grid's points on either side.",
        "",
        row(["pd", *names]),
        row(["---"] * (1 + len(names))),
    ]
    for pd in pds:
        lines.append(row([f"{pd:g}", *(describe_density(found[pd][f], densities) for f in names)]))
    if "tl-rpf" in names and "rpf" in names:
        lines += ["", "tl-rpf's 5%-loss density over rpf's, per pd:", ""]
        data["tl_rpf_over_rpf"] = {}
        for pd in pds:
            text = factor(found[pd]["tl-rpf"], found[pd]["rpf"], densities)
            data["tl_rpf_over_rpf"][f"{pd:g}"] = text
            lines.append(f"- pd = {pd:g}: {text}")
    plot(densities, lost, out / "clutter.png")
    lines += ["", "![lost share against clutter per gate](clutter.png)"]
    return write(out, "clutter", lines, data)


def fov_and_gate(cfg: Config, sensor_id: str = PRIMARY) -> float:
    """V / V_G: the false alarms per scan of one false alarm per gate."""
    from tltrack.config import detection_of

    setup = Setup(cfg)
    return detection_of(cfg, sensor_id).volume / gate_volume(setup.sensors[sensor_id].R)
