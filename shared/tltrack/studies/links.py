"""What a lossy, late link between vehicles costs the primary: RMSE and lost share against the
share of transfers lost, and against the link's delay.

Each factor moves alone over the source's :class:`~tltrack.config.LinkSpec` (the engine's model
of the link, :class:`~tltrack.engine.driver.Lossy`): the loss at 0, 10, 30, 50 and 90%; the delay at
0, 1/4, 1/2, 1 and 2 of the primary's period, each with a uniform jitter of half a period. A
transfer made at step k - 1 is for the primary's measurement at step k, so it has a period's
slack, plus the primary's deadline (a quarter period here) after its own measurement; one
arriving later is refused, never used late. The question (issue 34): is TL ever worse than the
isolated filter, by the paired per-run difference at 3 standard errors, and does it degrade
smoothly as the loss grows?
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tltrack.engine import plots
from tltrack.studies.common import Results, Runner, Setting, plain, row, run_difference, write

LOSSES = [0.0, 0.1, 0.3, 0.5, 0.9]
DELAYS = [0.0, 0.25, 0.5, 1.0, 2.0]  #: in primary periods
JITTER = 0.5  #: in primary periods
DEADLINE = 0.25  #: in primary periods
SIGMAS = 3.0  #: a difference is called worse beyond this many standard errors


def loss_cell(p: float) -> str:
    return f"loss {p:.0%}"


def delay_cell(d: float) -> str:
    return f"delay {d:g} T"


def cells(Ts: float) -> dict[str, dict[str, float]]:
    """Each cell's link: the loss sweep at no delay, then the delay sweep with jitter."""
    out = {loss_cell(p): {"loss": p, "deadline_s": DEADLINE * Ts} for p in LOSSES}
    for d in DELAYS:
        out[delay_cell(d)] = {
            "delay_s": d * Ts,
            "jitter_s": JITTER * Ts,
            "deadline_s": DEADLINE * Ts,
        }
    return out


def verdict(tl: Any, iso: Any) -> tuple[float, float, str]:
    """The paired mean difference TL - isolated, its standard error, and whether TL is worse
    (beyond :data:`SIGMAS` standard errors), better, or neither."""
    d = run_difference(tl, iso)
    se = float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else float("nan")
    mean = float(d.mean())
    if mean > SIGMAS * se:
        return mean, se, "worse"
    return mean, se, "better" if mean < -SIGMAS * se else "same"


def links(setting: Setting, runner: Runner, out: Path, K: int | None = None) -> Path:
    """The isolated, TL and robust-TL filters of the setting's kind (``--kind``; issue 34 asks
    for rpf) over each cell's link; ``K``: the preset's steps unless given (tests)."""
    steps = {} if K is None else {"K": K}
    base = setting.config(6000, **steps)
    links_ = cells(base.Ts)
    names = [setting.name(role) for role in ("", "tl-", "robust-tl-")]
    res: dict[str, Results] = {}
    for name, link in links_.items():
        cfg = setting.config(6000, sources=[{"id": "s1", "link": link}], **steps)
        res[name] = runner.run(cfg, names)
    iso, tl, rob = names
    _draw(res, names, out)
    lines = [
        "# Operators on vehicles: lossy and late links",
        "",
        f"{setting.describe(base)}. The link: delay and jitter in "
        f"primary periods T = {base.Ts:g} s, the primary's deadline {DEADLINE:g} T after its "
        f"measurement. TL - isolated: the mean over runs of the paired per-run overall-RMSE "
        f"difference (standard error); worse / better beyond {SIGMAS:g} SE.",
        "",
        row(
            [
                "link",
                f"RMSE {iso}",
                f"RMSE {tl}",
                f"RMSE {rob}",
                "lost iso / tl / robust",
                "transfers used (tl)",
                f"{tl} - {iso}",
                f"{rob} - {iso}",
            ]
        ),
        row(["---"] * 8),
    ]
    data: dict[str, Any] = {"cells": {}, "links": links_}
    worse = []
    for name, r in res.items():
        a, b, c = r[iso], r[tl], r[rob]
        d_tl, d_rob = verdict(b, a), verdict(c, a)
        if d_tl[2] == "worse":
            worse.append(name)
        lines.append(
            row(
                [
                    name,
                    f"{a.rmse_overall:.2f}",
                    f"{b.rmse_overall:.2f}",
                    f"{c.rmse_overall:.2f}",
                    f"{a.lost_fraction:.1%} / {b.lost_fraction:.1%} / {c.lost_fraction:.1%}",
                    f"{b.transfer_rate:.1%}",
                    f"{d_tl[0]:+.2f} ({d_tl[1]:.2f}) {d_tl[2]}",
                    f"{d_rob[0]:+.2f} ({d_rob[1]:.2f}) {d_rob[2]}",
                ]
            )
        )
        data["cells"][name] = {**plain(r), "tl_vs_isolated": d_tl, "robust_vs_isolated": d_rob}
    lines += [
        "",
        f"TL worse than the isolated filter (beyond {SIGMAS:g} SE) in: "
        + (", ".join(worse) if worse else "no cell") + ".",
    ]  # fmt: skip
    data["tl_worse_in"] = worse
    return write(out, "links", lines, data)


def _draw(res: dict[str, Results], names: list[str], out: Path) -> None:
    loss = [loss_cell(p) for p in LOSSES]
    delay = [delay_cell(d) for d in DELAYS]
    for cells_, x, label, file in (
        (loss, [100 * p for p in LOSSES], "transfers lost [%]", "links_loss.png"),
        (delay, DELAYS, "link delay [primary periods], jitter T/2", "links_delay.png"),
    ):
        plots.curves(
            x,
            {n: [res[c][n].rmse_overall for c in cells_] for n in names},
            out / file,
            xlabel=label,
            ylabel="overall RMSE [m]",
            title="RMSE over a lossy, late link",
        )
