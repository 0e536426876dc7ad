"""Does transfer help at every primary noise intensity? TL against isolated, I_p = 2 .. 8.

The paper's Fig. 6 sweeps I_p with the source at I_s = 1. Here, for each preset with a fixed
truth, the isolated and TL filters of the studied kind run on the same runs at every I_p (the
source, which does not depend on I_p, runs once for the whole sweep), and the paired difference
TL - isolated is reported with its MC error.
"""

from __future__ import annotations

from pathlib import Path

from tltrack.engine import plots
from tltrack.studies.common import Runner, Setting, mc_error, plain, row, run_difference, write

INTENSITIES = (2, 3, 4, 5, 6, 7, 8)
PRESETS = ("paper", "arasaratnam-haykin")


def intensities(setting: Setting, runner: Runner, out: Path) -> Path:
    """TL - isolated at each I_p, for each preset, fixed truth."""
    iso, tl = setting.name(), setting.name("tl-")
    lines = [
        "# Transfer at every primary intensity",
        "",
        row(["preset", "I_p", f"RMSE {iso}", f"RMSE {tl}", f"{tl} - {iso} (MC err)", "lost"]),
        row(["---"] * 6),
    ]
    curves, data = {}, {}
    cfg = None
    for preset in PRESETS:
        cfgs = [
            setting.config(6000, preset=preset, truth="fixed", primary_intensity=i)
            for i in INTENSITIES
        ]
        cfg = cfgs[0]
        swept = runner.sweep(cfgs, [iso, tl])
        gains = []
        for i, r in zip(INTENSITIES, swept, strict=True):
            d = run_difference(r[tl], r[iso])
            gains.append(-d.mean())
            lost = f"{r[iso].lost_fraction:.2%} / {r[tl].lost_fraction:.2%}"
            lines.append(
                row(
                    [
                        preset,
                        i,
                        f"{r[iso].rmse_overall:.2f}",
                        f"{r[tl].rmse_overall:.2f}",
                        f"{d.mean():+.3f} ({mc_error(d):.3f})",
                        lost,
                    ]
                )
            )
            data[f"{preset} {i}"] = plain(r)
        curves[f"{tl} gain, {preset}"] = gains
    assert cfg is not None
    lines[1:1] = ["", f"{setting.describe(cfg).split(', ', 3)[3]}; truth fixed.", ""]
    plots.curves(
        INTENSITIES,
        curves,
        out / "intensities.png",
        xlabel="primary noise intensity I_p (I_s = 1)",
        ylabel="RMSE iso - RMSE TL [m]",
        title="The gain of transfer at every I_p",
    )
    lines += ["", "![the gain of transfer against I_p](intensities.png)"]
    return write(out, "intensities", lines, data)
