"""Recorded tracks as truth: a fishing vessel's AIS reports in New York harbour.

A truth file is a CSV with the header ``t,x,y`` (seconds, metres) or ``t,lat,lon`` (degrees);
its reports are resampled to Ts by a spline and put in the sensors' frame, and the filters start
from and are scored against the state derived from the track
(:mod:`tltrack.config.truth_file`). With no ``truth_origin`` the frame's origin, where the
sensors sit by default, is 2 km south-west of the track. This script runs the first ten minutes
of the shipped track:

    python examples/tutorials/recorded_tracks.py --out /tmp/ais
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from tltrack.config import load_config
from tltrack.engine.experiment import run_and_save

TRACK = (
    Path(__file__).resolve().parents[1] / "tracks" / "ais-nyharbor-2020-06-30-mmsi-367370920.csv"
)


def main(out: Path, runs: int = 10, particles: int = 1000) -> dict[str, Any]:
    """Run the isolated and TL filters on the track into ``out``; return results.json's data."""
    cfg = load_config(
        None,
        truth_file=str(TRACK),
        K=600,  # ten minutes at Ts = 1 s; without K, the whole track (2850 steps)
        scenario="ct",
        particles=particles,
        runs=runs,
        seed=1,
    )
    print(f"{TRACK.name}: K = {cfg.K} steps, x0 = {[round(v, 2) for v in cfg.x0]}")
    doc = run_and_save(cfg, ["rpf", "tl-rpf", "ukf", "tl-ukf"], out, workers=1)
    for name, r in doc["filters"].items():
        print(f"{name:12s} RMSE {r['rmse_overall']:7.2f} m")
    print(f"truth: {doc['truth']}")
    print(f"wrote {out / 'results.json'}, {out / 'rmse.png'} and {out / 'trajectory.png'}")
    return doc


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--out", type=Path, default=Path("out/recorded-tracks"))
    main(parser.parse_args().out)
