"""Robust transfer against faulty sources: honest, biased, diverged and stale.

The paper assumes an honest source that is better than the primary. This study feeds the primary
a source with each fault of :mod:`tltrack.engine.faults` and compares the isolated filter, TL and
robust TL (:mod:`tltrack.filters.decision`) on the same runs: robust TL should keep most of TL's
gain from an honest source and never be worse than the isolated filter beyond the MC error.
"""

from __future__ import annotations

from pathlib import Path

from tltrack.studies.common import Runner, Setting, paired, plain, row, run_difference, write

FAULTS = ["none", "bias", "diverged", "stale"]


def robust(setting: Setting, runner: Runner, out: Path) -> Path:
    """The isolated, TL and robust-TL filters of the setting's kind against each fault."""
    iso_name, tl_name, rob_name = (setting.name(r) for r in ("", "tl-", "robust-tl-"))
    cfgs = {f: setting.config(3000, sources=[{"id": "s1", "fault": f}]) for f in FAULTS}
    res = {f: runner.run(cfg, [iso_name, tl_name, rob_name]) for f, cfg in cfgs.items()}
    lines = [
        "# Robust transfer against faulty sources",
        "",
        f"{setting.describe(cfgs['none'])}. Differences are means over runs of the paired per-run "
        "overall RMSE difference; MC error = 2 x SE of that difference.",
        "",
        row(
            [
                "source",
                iso_name,
                tl_name,
                rob_name,
                "robust - isolated (MC err)",
                "robust gain / tl gain",
                "transfer rate (robust)",
                "lost iso / tl / robust",
            ]
        ),
        row(["---"] * 8),
    ]
    for f, r in res.items():
        iso, tl, rob = r[iso_name], r[tl_name], r[rob_name]
        share = (
            run_difference(iso, rob).mean() / run_difference(iso, tl).mean()
            if f == "none"
            else None
        )
        lost = f"{iso.lost_fraction:.1%} / {tl.lost_fraction:.1%} / {rob.lost_fraction:.1%}"
        lines.append(
            row(
                [
                    f,
                    f"{iso.rmse_overall:.2f}",
                    f"{tl.rmse_overall:.2f}",
                    f"{rob.rmse_overall:.2f}",
                    paired(rob, iso),
                    "–" if share is None else f"{share:.1%}",
                    f"{rob.transfer_rate:.1%}",
                    lost,
                ]
            )
        )
    return write(out, "robust", lines, {f: plain(r) for f, r in res.items()})
