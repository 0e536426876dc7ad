"""How far a sweep made on another machine is from this machine's: the first runs of each
committed sweep (``results/checkpoint/sweep-*.json``), run here, against the file's.

    .venv/bin/python papers/manoeuvres/other_machine.py [--runs 4]

Each sweep is found by the digest it records without the environment (``made.key``, see
:mod:`tltrack.studies.finished`); the output is the largest difference of run RMSE over the
filters and runs compared, in metres. A batch's last bits depend on its size, so this also
counts the difference between a batch of ``--runs`` here and the file's batches of 22.

The digest holds the numerical code: run it with the code that made the sweeps (commit 3098c15,
``PYTHONPATH=<its checkout>/shared``), or it finds none of them.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np
from tltrack.engine.montecarlo import run_sweep
from tltrack.studies.common import Setting
from tltrack.studies.finished import Finished
from tltrack.studies.manoeuvres import FILTERS, TRUTHS, configs

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
CHECKPOINT = HERE / "results" / "checkpoint"
#: as the study's --tracks names it, from the repository's root: a configuration holds the path
TRACKS = Path("examples/tracks")
#: the committed table's sweeps: 1000 runs, batches of 22, one run timed
RUNS, BATCH, TIMED = 1000, 22, True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=4, help="runs compared per sweep")
    runs = parser.parse_args().runs
    os.chdir(ROOT)
    made = {}
    for file in sorted(CHECKPOINT.glob("sweep-*.json")):
        doc = json.loads(file.read_text(encoding="utf-8"))
        made[doc["made"]["key"]] = (file, doc)
    for truth in TRUTHS:
        for model, cfg in configs(Setting(runs=RUNS), truth, TRACKS).items():
            key = Finished(CHECKPOINT, [cfg], FILTERS, BATCH, TIMED).key
            if key not in made:
                print(f"{truth.label}, {model}: not finished")
                continue
            file, doc = made[key]
            here = run_sweep([cfg.with_(runs=runs)], FILTERS, batch_size=runs, time_steps=False)
            there = doc["results"][0]
            diff = max(
                float(np.max(np.abs(np.asarray(there[f]["run_rmse"][:runs]) - here[0][f].run_rmse)))
                for f in FILTERS
            )
            cpu = doc["made"]["environment"].get("cpu", "unknown")
            print(f"{truth.label}, {model}: made on {cpu}, largest difference {diff:.2g} m")


if __name__ == "__main__":
    main()
