"""Several source operators: does the primary gain from a second source, and does robust TL
shield it from a biased one among honest ones?"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tltrack.engine import plots
from tltrack.filters.kinds import FILTERS
from tltrack.studies.common import Runner, Setting, bound, paired, plain, row, write


def sources(setting: Setting, runner: Runner, out: Path) -> Path:
    """The primary's RMSE against the number of sources, honest or with one biased among them."""
    iso, tl, rob = (setting.name(r) for r in ("", "tl-", "robust-tl-"))
    fusion = [setting.name("fusion-")] if FILTERS.get(setting.kind).particle else []
    filters = [iso, tl, rob, *fusion]
    setups: dict[str, list[dict[str, Any]]] = {
        f"{n} honest": [{"id": f"s{i + 1}"} for i in range(n)] for n in (1, 2, 4)
    }
    setups |= {
        f"{n - 1} honest + 1 biased": [{"id": f"s{i + 1}"} for i in range(n - 1)]
        + [{"id": f"s{n}", "fault": "bias"}]
        for n in (2, 4)
    }
    res, bounds = {}, {}
    for label, srcs in setups.items():
        cfg = setting.config(3000, sources=srcs)
        res[label] = runner.run(cfg, filters)
        bounds[label] = float(np.mean(bound(cfg)))
    one, two = res["1 honest"][tl], res["2 honest"][tl]
    mixed = res["1 honest + 1 biased"][rob]
    lines = [
        "# Several source operators",
        "",
        f"{setting.describe(cfg)}; sources at the origin, I_s = 1; the biased one is "
        "miscalibrated by 10 sigma of its bearing.",
        "",
        row(["sources", *filters, "PCRLB, all data (mean over k)"]),
        row(["---"] * (len(filters) + 2)),
    ]
    for label, r in res.items():
        lines.append(
            row([label, *(f"{r[f].rmse_overall:.2f}" for f in filters), f"{bounds[label]:.2f}"])
        )
    lines += [
        "",
        "Checks (difference, MC error):",
        "",
        f"- 2 honest vs 1 honest, {tl}: {paired(two, one)}",
        f"- 1 honest + 1 biased, {rob} vs isolated {iso}: "
        f"{paired(mixed, res['1 honest + 1 biased'][iso])}",
        f"- 1 honest + 1 biased, {rob} vs {tl} with the honest source alone: {paired(mixed, one)}",
    ]
    labels = list(res)
    plots.curves(
        range(len(labels)),
        {f: [res[lb][f].rmse_overall for lb in labels] for f in filters},
        out / "sources.png",
        xlabel="configuration: " + " | ".join(labels),
        ylabel="overall RMSE [m]",
        title="Primary RMSE against the sources it hears",
    )
    return write(out, "sources", lines, {lb: plain(r) for lb, r in res.items()})
