"""What operating on vehicles costs the primary: RMSE and lost share against the share of
transfers lost, the link's delay, the two sensors' rates and the clocks' offset.

Each factor moves alone. The link is the source's :class:`~tltrack.config.LinkSpec` (the engine's
model, :class:`~tltrack.engine.driver.Lossy`): the loss at 0, 10, 30, 50 and 90%; the delay at 0,
1/4, 1/2, 1 and 2 of the primary's period, each with a uniform jitter of half a period. A
transfer made at step k - 1 is for the primary's measurement at step k, so it has a period's
slack, plus the primary's deadline (a quarter period here) after its own measurement; one
arriving later is refused, never used late. The clocks (:mod:`tltrack.config.timeline`): the
source samples 4 times slower, as fast, or 4 times faster than the primary; its clock is ahead
of the primary's by 0, 1/4 or 1/2 of the primary's period, under a clock bound of half a period
(which widens every transfer, :meth:`~tltrack.engine.driver.Sources.clock_spread_s`). The
question: is TL ever worse than the isolated filter, by the paired per-run difference
at 3 standard errors, and does it degrade smoothly as the loss grows?
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tltrack.engine import plots
from tltrack.engine.montecarlo import FilterResult
from tltrack.studies.common import Results, Runner, Setting, plain, row, run_difference, write

LOSSES = [0.0, 0.1, 0.3, 0.5, 0.9]
DELAYS = [0.0, 0.25, 0.5, 1.0, 2.0]  #: in primary periods
JITTER = 0.5  #: in primary periods
DEADLINE = 0.25  #: in primary periods
SIGMAS = 3.0  #: a difference is called worse beyond this many standard errors
RATES = [0.25, 1.0, 4.0]  #: the source's rate over the primary's: 1:4, 1:1, 4:1
OFFSETS = [0.0, 0.25, 0.5]  #: the source's clock ahead of the primary's, in primary periods
CLOCK_BOUND = 0.5  #: max_clock_offset_s in the offset cells, in primary periods


def loss_cell(p: float) -> str:
    return f"loss {p:.0%}"


def delay_cell(d: float) -> str:
    return f"delay {d:g} T"


def rate_cell(r: float) -> str:
    return f"rates {r:g}:1" if r >= 1 else f"rates 1:{1 / r:g}"


def offset_cell(o: float) -> str:
    return f"clock offset {o:g} T"


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


def clock_cells(Ts: float) -> dict[str, dict[str, Any]]:
    """Each clock cell's changes to the config: the source's period, then its clock's offset."""
    out: dict[str, dict[str, Any]] = {
        rate_cell(r): {"sources": [{"id": "s1", "period_s": Ts / r}]} for r in RATES
    }
    for o in OFFSETS:
        out[offset_cell(o)] = {
            "max_clock_offset_s": CLOCK_BOUND * Ts,
            "sources": [{"id": "s1", "clock_offset_s": o * Ts}],
        }
    return out


def cell_names(Ts: float = 1.0) -> list[str]:
    """Every cell the study runs, in its order."""
    return [*cells(Ts), *clock_cells(Ts)]


def verdict(tl: FilterResult, iso: FilterResult) -> tuple[float, float, str]:
    """The paired mean difference TL - isolated, its standard error, and whether TL is worse
    (beyond :data:`SIGMAS` standard errors), better, or neither."""
    d = run_difference(tl, iso)
    se = float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else float("nan")
    mean = float(d.mean())
    if mean > SIGMAS * se:
        return mean, se, "worse"
    return mean, se, "better" if mean < -SIGMAS * se else "same"


def links(setting: Setting, runner: Runner, out: Path, K: int | None = None) -> Path:
    """The isolated, TL and robust-TL filters of the setting's kind (``--kind``; the study
    uses rpf) over each cell's link; ``K``: the preset's steps unless given (tests)."""
    steps = {} if K is None else {"K": K}
    base = setting.config(6000, **steps)
    links_ = cells(base.Ts)
    clocks = clock_cells(base.Ts)
    names = [setting.name(role) for role in ("", "tl-", "robust-tl-")]
    res: dict[str, Results] = {}
    for name, link in links_.items():
        cfg = setting.config(6000, sources=[{"id": "s1", "link": link}], **steps)
        res[name] = runner.run(cfg, names)
    for name, changes in clocks.items():
        res[name] = runner.run(setting.config(6000, **changes, **steps), names)
    iso, tl, rob = names
    _draw(res, names, out)
    lines = [
        "# Operators on vehicles: lossy and late links, their own rates and clocks",
        "",
        f"{setting.describe(base)}. The link: delay and jitter in "
        f"primary periods T = {base.Ts:g} s, the primary's deadline {DEADLINE:g} T after its "
        f"measurement. Rates: the source's over the primary's (which stays at T). Clock offset: "
        f"the source's clock ahead of the primary's, under a clock bound of {CLOCK_BOUND:g} T. "
        f"Each operator is scored at its own samples; a cell whose truth grid is finer than T "
        f"(rates 4:1) simulates its truth anew on that grid. TL - isolated: the mean over runs of "
        f"the paired per-run overall-RMSE difference (standard error); worse / better beyond "
        f"{SIGMAS:g} SE.",
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
    data: dict[str, Any] = {"cells": {}, "links": links_, "clocks": clocks}
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
    rates = [rate_cell(r) for r in RATES]
    offsets = [offset_cell(o) for o in OFFSETS]
    for cells_, x, label, file in (
        (loss, [100 * p for p in LOSSES], "transfers lost [%]", "links_loss.png"),
        (delay, DELAYS, "link delay [primary periods], jitter T/2", "links_delay.png"),
        (rates, [float(x) for x in np.log2(RATES)], "log2(source's rate / primary's)",
         "links_rates.png"),
        (offsets, OFFSETS, f"clock offset [primary periods], bound {CLOCK_BOUND:g} T",
         "links_clocks.png"),
    ):  # fmt: skip
        plots.curves(
            x,
            {n: [res[c][n].rmse_overall for c in cells_] for n in names},
            out / file,
            xlabel=label,
            ylabel="overall RMSE [m]",
            title="RMSE on vehicles",
        )
