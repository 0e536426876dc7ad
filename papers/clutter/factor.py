"""The study's headline, tl-rpf's 5%-loss clutter density over rpf's at pd = 0.9, at the study's
N = 6000: the study's grid (0, 0.05, 0.2, ...) has both filters past 5% lost at its first
non-zero point, so this sweep puts its points below it. Same setting as the study (paper preset,
fixed truth, 50-sigma field of view); only the grid and the filters differ. The source is the
study's (pd 0.95, 0.05 false alarms per gate), or with ``clean`` the paper's sensor (pd 1, none).

Usage: python papers/clutter/factor.py RUNS OUT_DIR [clean]"""

import sys
from pathlib import Path

from tltrack.app.common import progress_bar
from tltrack.studies import Runner, Setting
from tltrack.studies.clutter import SOURCE_PD, SOURCE_PER_GATE, clutter

#: false alarms per 99% gate, refined below the study's first non-zero point (every filter
#: is past 5% lost at 0.05 with the study's source)
DENSITIES = (0.0, 0.002, 0.005, 0.01, 0.02, 0.05)
#: ... and on to the study's 0.2 and 1 with a clean source, which TL may take further
CLEAN_DENSITIES = (*DENSITIES, 0.2, 1.0)
FILTERS = ("rpf", "tl-rpf", "robust-tl-rpf")

runs, out = int(sys.argv[1]), Path(sys.argv[2])
clean = sys.argv[3:] == ["clean"]
source = (1.0, 0.0) if clean else (SOURCE_PD, SOURCE_PER_GATE)
densities = CLEAN_DENSITIES if clean else DENSITIES
with progress_bar(runs, "clutter factor") as bar:
    task = bar.add_task("clutter factor", total=runs)  # one sweep: each run counts once
    runner = Runner(lambda n: bar.advance(task, n), workers=2)
    path = clutter(
        Setting(runs=runs),
        runner,
        out,
        densities=densities,
        pds=(0.9,),
        filters=FILTERS,
        source=source,
    )
print(path.read_text())
