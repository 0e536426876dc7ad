"""Does the particle filter keep the track everywhere? Every preset and truth mode, paired.

For each preset (the seed's ``paper`` and ``arasaratnam-haykin``) and truth mode (fixed, at
several truth seeds; random; noise-free), on the same runs: the isolated, TL and robust-TL filters
of the studied kind, beside the UKF and TL-UKF. Reported: each filter's share of lost runs, and
the paired per-run differences that the claims rest on: the particle filter against the UKF
(isolated and TL), TL against isolated, and robust TL against isolated.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tltrack.studies.common import Runner, Setting, paired, plain, row, write

PRESETS = ("paper", "arasaratnam-haykin")


def presets(setting: Setting, runner: Runner, out: Path, *, truth_seeds: int = 5) -> Path:
    """Every preset x truth mode (the fixed truth at ``truth_seeds`` seeds)."""
    iso, tl, rob = (setting.name(r) for r in ("", "tl-", "robust-tl-"))
    names = [iso, tl, rob, "ukf", "tl-ukf"]
    modes = [("fixed", s) for s in range(truth_seeds)] + [("random", 0), ("noise-free", 0)]
    res: dict[str, Any] = {}
    cfg = None
    for preset in PRESETS:
        for truth, seed in modes:
            cfg = setting.config(6000, preset=preset, truth=truth, truth_seed=seed)
            res[f"{preset} {truth}" + (f" {seed}" if truth == "fixed" else "")] = (
                cfg,
                runner.run(cfg, names),
            )
    assert cfg is not None
    sources = [n for n in next(iter(res.values()))[1] if n.startswith("source-")]
    lost_names = [*sources, iso, tl, rob, "ukf", "tl-ukf"]
    lines = [
        "# Every preset and truth mode",
        "",
        f"{setting.describe(cfg).split(', ', 2)[2]}; truth seeds 0..{truth_seeds - 1} for the "
        "fixed truth. Lost: error over 100 m in each of the last 10 steps. Differences: means over "
        "runs of the paired per-run overall RMSE difference, MC error (2 x SE) in brackets.",
        "",
        row(["preset truth [seed]", *(f"lost {n}" for n in lost_names)]),
        row(["---"] * (1 + len(lost_names))),
    ]
    for label, (_, r) in res.items():
        lines.append(row([label, *(f"{r[n].lost_fraction:.2%}" for n in lost_names)]))
    lines += [
        "",
        row(
            [
                "preset truth [seed]",
                f"RMSE {iso}",
                f"{iso} - ukf",
                f"{tl} - tl-ukf",
                f"{tl} - {iso}",
                f"{rob} - {iso}",
            ]
        ),
        row(["---"] * 6),
    ]
    for label, (_, r) in res.items():
        lines.append(
            row(
                [
                    label,
                    f"{r[iso].rmse_overall:.2f}",
                    paired(r[iso], r["ukf"]),
                    paired(r[tl], r["tl-ukf"]),
                    paired(r[tl], r[iso]),
                    paired(r[rob], r[iso]),
                ]
            )
        )
    return write(out, "presets", lines, {label: plain(r) for label, (_, r) in res.items()})
