"""Operators with different sensors: transfer between a radar and a passive or a GNSS operator.

Transfer exists because operators' systems differ. Each pair below runs the isolated primary,
TL (the source's transfer) and centralized fusion (the source's raw measurements too, the bound
that transfer trades away for privacy), beside the PCRLB of the primary alone and with the
source's data. A bearing-only primary alone, from a fixed position, cannot observe range: its
isolated filter keeps the prior's range and drifts with it, so its error grows without bound
while TL's stays near fusion's.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tltrack.engine import plots
from tltrack.studies.common import Runner, Setting, bound, paired, plain, row, write

#: label -> (the primary's sensor, the source's sensor)
PAIRS: dict[str, tuple[dict[str, Any], dict[str, Any]]] = {
    "bearing primary, radar source at (-3000, -5000)": (
        {"kind": "bearing", "position": [0.0, 0.0]},
        {"kind": "range-bearing", "position": [-3000.0, -5000.0]},
    ),
    "bearing primary, radar source at (4000, -1000)": (
        {"kind": "bearing", "position": [0.0, 0.0]},
        {"kind": "range-bearing", "position": [4000.0, -1000.0]},
    ),
    "bearing primary, radar source at the primary": (
        {"kind": "bearing", "position": [0.0, 0.0]},
        {"kind": "range-bearing", "position": [0.0, 0.0]},
    ),
    "position primary, Doppler-radar source at (-3000, -5000)": (
        {"kind": "position", "position": [0.0, 0.0]},
        {"kind": "range-bearing-doppler", "position": [-3000.0, -5000.0]},
    ),
}


def heterogeneous(setting: Setting, runner: Runner, out: Path) -> Path:
    """Isolated, TL and fusion for each pair of :data:`PAIRS`, against the PCRLB."""
    iso, tl, fus = setting.name(), setting.name("tl-"), f"fusion-{setting.kind}"
    res, cfgs, bounds = {}, {}, {}
    for label, (primary, source) in PAIRS.items():
        cfg = setting.config(6000, primary_sensor=primary, sources=[{"id": "s1", "sensor": source}])
        cfgs[label] = cfg
        res[label] = runner.run(cfg, [iso, tl, fus])
        bounds[label] = (float(np.mean(bound(cfg, False))), float(np.mean(bound(cfg))))
    first = next(iter(cfgs.values()))
    lines = [
        "# Operators with different sensors",
        "",
        f"{setting.describe(first)}; I_s = 1. RMSE is the overall RMSE (mean over k of "
        "RMSE(k)); PCRLB is its mean over k along the truth; TL - fusion is the paired per-run "
        "difference (MC error).",
        "",
        row(
            [
                "pair",
                iso,
                tl,
                fus,
                "TL / fusion",
                "TL / isolated",
                "TL - fusion (MC err)",
                "PCRLB alone",
                "PCRLB with source",
                "lost iso / tl / fusion",
            ]
        ),
        row(["---"] * 10),
    ]
    for label, r in res.items():
        a, b, c = r[iso], r[tl], r[fus]
        lost = f"{a.lost_fraction:.1%} / {b.lost_fraction:.1%} / {c.lost_fraction:.1%}"
        lines.append(
            row(
                [
                    label,
                    f"{a.rmse_overall:.2f}",
                    f"{b.rmse_overall:.2f}",
                    f"{c.rmse_overall:.2f}",
                    f"{b.rmse_overall / c.rmse_overall:.2f}",
                    f"{b.rmse_overall / a.rmse_overall:.2f}",
                    paired(b, c),
                    f"{bounds[label][0]:.2f}",
                    f"{bounds[label][1]:.2f}",
                    lost,
                ]
            )
        )
    _figure(res, bounds, [iso, tl, fus], out)
    lines += ["", "![RMSE of each pair against the PCRLB](heterogeneous.png)"]
    return write(out, "heterogeneous", lines, {lb: plain(r) for lb, r in res.items()})


def _figure(
    res: dict[str, Any], bounds: dict[str, tuple[float, float]], names: list[str], out: Path
) -> None:
    labels = list(res)
    series = {n: [res[lb][n].rmse_overall for lb in labels] for n in names}
    series["PCRLB, primary alone"] = [bounds[lb][0] for lb in labels]
    series["PCRLB, with the source"] = [bounds[lb][1] for lb in labels]
    plots.bars(
        [lb.replace(", ", "\n") for lb in labels],
        series,
        out / "heterogeneous.png",
        ylabel="overall RMSE [m] (log scale)",
        title="Transfer between operators with different sensors",
        log=True,
    )
