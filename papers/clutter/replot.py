"""Draw a committed table's figure again from its ``clutter.json``, with the study's plot of
today (:func:`tltrack.studies.clutter.plot`): the numbers are the file's, only the drawing
changes. Each table's figure was redrawn so when the plot gave each filter a colour of its own.

Usage: python papers/clutter/replot.py RESULTS_DIR...   (each holding a clutter.json)"""

import json
import sys
from pathlib import Path

from tltrack.studies.clutter import plot

for folder in map(Path, sys.argv[1:]):
    doc = json.loads((folder / "clutter.json").read_text())
    names = doc["setting"]["filters"]
    cells = doc["cells"].values()
    densities = list(dict.fromkeys(c["clutter_per_gate"] for c in cells))
    lost = {
        pd: {f: [c["filters"][f]["lost_fraction"] for c in cells if c["pd"] == pd] for f in names}
        for pd in dict.fromkeys(c["pd"] for c in cells)
    }
    print(plot(densities, lost, folder / "clutter.png"))
