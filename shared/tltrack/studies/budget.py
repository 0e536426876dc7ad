"""The communication budget: RMSE against the share of steps that use a transfer (the hybrid
primary of the paper's future work)."""

from __future__ import annotations

from pathlib import Path

from tltrack.engine import plots
from tltrack.studies.common import Runner, Setting, plain, row, write

BUDGETS = [0.05, 0.1, 0.25, 0.5, 0.75, 1.0]


def budget(setting: Setting, runner: Runner, out: Path) -> Path:
    """Robust TL under each budget, beside the isolated filter."""
    iso, rob = setting.name(), setting.name("robust-tl-")
    cfgs = {b: setting.config(3000, transfer_budget=b) for b in BUDGETS}
    res = {b: runner.run(cfg, [iso, rob]) for b, cfg in cfgs.items()}
    rate = [res[b][rob].transfer_rate for b in BUDGETS]
    rmse = [res[b][rob].rmse_overall for b in BUDGETS]
    plots.curves(
        rate,
        {rob: rmse, iso: [res[b][iso].rmse_overall for b in BUDGETS]},
        out / "budget.png",
        xlabel="share of steps with a transfer",
        ylabel="overall RMSE [m]",
        title="RMSE against the transfer rate",
    )
    lines = [
        "# Communication budget",
        "",
        f"{setting.describe(cfgs[1.0])}.",
        "",
        row(["budget", "transfer rate", f"RMSE {rob}", f"RMSE {iso}"]),
        row(["---"] * 4),
    ]
    lines += [
        row([b, f"{r:.1%}", f"{m:.2f}", f"{res[b][iso].rmse_overall:.2f}"])
        for b, r, m in zip(BUDGETS, rate, rmse, strict=True)
    ]
    return write(out, "budget", lines, {str(b): plain(r) for b, r in res.items()})
