"""Figures in the style of the paper's: labelled axes with units, a legend, one idea per figure.

Everything is drawn from a saved results document (or tracks), so ``tltrack plot results.json``
redraws the figures without rerunning anything.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only: the machines are headless
import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import NDArray

from tltrack.config import PRIMARY
from tltrack.engine.names import operator_of

_STYLE = {
    "pf": "tab:blue",
    "rpf": "tab:purple",
    "ukf": "tab:green",
    "ckf3": "tab:red",
    "ckf5": "tab:olive",
}


def _style(name: str) -> dict[str, Any]:
    role, _, kind = name.rpartition("-")
    kind = kind.split("/")[0]
    ls = {"tl": "--", "robust-tl": (0, (6, 2, 1, 2)), "source": ":", "fusion": "-."}.get(role, "-")
    marker = {"tl": "+", "robust-tl": "x"}.get(role)
    return {"color": _STYLE.get(kind, "black"), "linestyle": ls, "marker": marker, "markevery": 8}


def _sample_times(cfg: Mapping[str, Any], name: str, n: int) -> Any:
    """When a filter's n estimates are, from a results document's config: its operator's samples
    (a source's own period and phase; the primary's otherwise)."""
    period, phase = cfg["Ts"], cfg.get("primary_phase_s", 0.0)
    sid = operator_of(name, [s["id"] for s in cfg["sources"]])
    if sid != PRIMARY:
        own = next(s for s in cfg["sources"] if s["id"] == sid)
        period, phase = own.get("period_s") or period, own.get("phase_s", 0.0)
    return phase + period * np.arange(1, n + 1)


def rmse_vs_time(doc: Mapping[str, Any], path: Path, title: str = "") -> Path:
    """RMSE(k) of every filter, with the PCRLB as the physical limit (cf. the paper's Fig. 3/5)."""
    fig, ax = plt.subplots(figsize=(8, 4.5))
    cfg = doc["config"]
    for name, r in doc["filters"].items():
        t = _sample_times(cfg, name, len(r["rmse_per_step"]))
        ax.plot(t, r["rmse_per_step"], label=f"{name} ({r['rmse_overall']:.2f} m)", **_style(name))
    for label, bound in doc.get("pcrlb", {}).items():
        ax.plot(
            cfg["Ts"] * np.arange(1, len(bound) + 1),
            bound,
            color="grey",
            lw=1,
            ls="-" if label == "primary" else "--",
            label=f"PCRLB, {label.replace('_', ' ')}"
            + (" (single model)" if "pcrlb_note" in doc else ""),
        )
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position RMSE [m]")
    ax.set_title(title or _describe(doc))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    return _save(fig, path)


def trajectory(
    truth: NDArray[np.float64],
    tracks: Mapping[str, NDArray[np.float64]],
    path: Path,
    title: str = "",
) -> Path:
    """The true path and each filter's estimates for one run (cf. the paper's Fig. 4): positions
    (K + 1, 2) of x_0..x_K, and (K, 2) of each filter's x_hat_1..x_hat_K."""
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    ax.plot(truth[:, 0], truth[:, 1], color="black", lw=2, label="truth")
    ax.plot(truth[0, 0], truth[0, 1], "ko", label="start")
    ax.plot(truth[-1, 0], truth[-1, 1], "kx", ms=9, label="end")
    for name, xy in tracks.items():
        ax.plot(xy[:, 0], xy[:, 1], lw=1, label=name, **_style(name))
    return _plan_view(fig, ax, path, title or "trajectory and estimates, run 0", "datalim")


def scans_and_tracks(
    detections: NDArray[np.float64] | None,
    clutter: NDArray[np.bool_] | None,
    tracks: Mapping[str, NDArray[np.float64]],
    path: Path,
    truth: NDArray[np.float64] | None = None,
    title: str = "",
) -> Path:
    """A sensor's detections of every step (M, 2) as positions, grey (false alarms light grey
    when the file says which they are), under each filter's estimates (K, 2) and the truth."""
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    if detections is not None and len(detections):
        fake = np.zeros(len(detections), bool) if clutter is None else clutter
        bad, good = detections[fake], detections[~fake]
        ax.scatter(bad[:, 0], bad[:, 1], s=4, color="0.8", label="false alarms", zorder=1)
        shown = "detections" if clutter is None else "target's detections"
        ax.scatter(good[:, 0], good[:, 1], s=6, color="0.45", label=shown, zorder=2)
    if truth is not None:
        ax.plot(truth[:, 0], truth[:, 1], color="black", lw=2, label="truth", zorder=3)
    for name, xy in tracks.items():
        ax.plot(xy[:, 0], xy[:, 1], lw=1.2, label=name, zorder=4, **_style(name))
    # around the tracks: false alarms spread over the whole field of view would shrink them to a dot
    drawn = [xy for xy in (*tracks.values(), truth) if xy is not None and len(xy)]
    if drawn:
        lo, hi = np.min([d.min(0) for d in drawn], 0), np.max([d.max(0) for d in drawn], 0)
        pad = max(0.25 * float(np.max(hi - lo)), 300.0)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
    return _plan_view(fig, ax, path, title or "recorded scans and estimates", "box")


def curves(
    x: Sequence[float],
    series: Mapping[str, Sequence[float]],
    path: Path,
    *,
    xlabel: str,
    ylabel: str,
    title: str,
    reference: Mapping[str, Sequence[float]] | None = None,
) -> Path:
    """Measured curves against a swept parameter, with the paper's printed values as markers."""
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for name, ys in series.items():
        ax.plot(x, ys, label=name, **{**_style(name), "marker": "o", "markevery": 1})
    for name, ys in (reference or {}).items():
        ax.plot(
            x,
            ys,
            ls="none",
            marker="s",
            mfc="none",
            color=_style(name)["color"],
            label=f"{name} (paper)",
        )
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return _save(fig, path)


def bars(
    groups: Sequence[str],
    series: Mapping[str, Sequence[float]],
    path: Path,
    *,
    ylabel: str,
    title: str,
    log: bool = False,
) -> Path:
    """One group of bars per configuration, one bar per series (filters, bounds)."""
    fig, ax = plt.subplots(figsize=(max(7.0, 2.2 * len(groups)), 4.5))
    width = 0.8 / max(1, len(series))
    x = np.arange(len(groups))
    for i, (name, ys) in enumerate(series.items()):
        ax.bar(x + (i - (len(series) - 1) / 2) * width, ys, width, label=name)
    ax.set_xticks(x, groups, fontsize=7)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    if log:
        ax.set_yscale("log")
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=7)
    return _save(fig, path)


def distributions(
    samples: Mapping[str, Sequence[float]],
    reference: Mapping[str, float | None],
    path: Path,
    *,
    ylabel: str,
    title: str,
) -> Path:
    """A box per sample set (whiskers 5-95 %), with a reference value as a cross where known; on
    a log scale when the values span more than a decade (a lost track's RMSE is in the km)."""
    names = list(samples)
    fig, ax = plt.subplots(figsize=(max(7.0, 0.9 * len(names)), 4.5))
    ax.boxplot([samples[n] for n in names], whis=(5, 95), showfliers=True)
    values = np.concatenate([np.asarray(samples[n], dtype=float) for n in names])
    values = values[np.isfinite(values) & (values > 0)]
    if values.size and values.max() > 10 * values.min():
        ax.set_yscale("log")
    for j, n in enumerate(names, start=1):
        ref = reference.get(n)
        if ref is not None:
            ax.plot(j, ref, "x", color="tab:red", ms=9, mew=2)
    ax.set_xticks(range(1, len(names) + 1), names, rotation=45, ha="right", fontsize=7)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3, axis="y")
    return _save(fig, path)


def _plan_view(fig: Any, ax: Any, path: Path, title: str, adjustable: str) -> Path:
    """x-y in metres at one scale, titled, gridded, with a legend; saved to ``path``."""
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal", adjustable=adjustable)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return _save(fig, path)


def _describe(doc: Mapping[str, Any]) -> str:
    c = doc["config"]
    return (
        f"scenario {c['scenario']}, preset {c['preset']}, truth {c['truth']}, "
        f"I_p = {c['primary_intensity']:g}, N = {c['particles']}, {c['runs']} runs"
    )


def _save(fig: Any, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
