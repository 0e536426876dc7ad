"""The examples run as a user would run them, and say what they claim."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_a_range_only_primary_from_its_own_file_is_helped_by_the_radars_transfer(
    tmp_path: Path,
) -> None:
    """examples/range_only/primary.toml names the sensor's class by its import path."""
    folder = EXAMPLES / "range_only"
    env = {**os.environ, "PYTHONPATH": str(folder), "MPLBACKEND": "Agg"}
    argv = [sys.executable, "-m", "tltrack", "experiment", "--config", str(folder / "primary.toml")]
    argv += ["--filters", "pf,tl-pf", "--particles", "2000", "--runs", "3", "--workers", "1"]
    done = subprocess.run(
        [*argv, "--out", str(tmp_path)], env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    doc = json.loads((tmp_path / "results.json").read_text())
    rmse = {n: r["rmse_overall"] for n, r in doc["filters"].items()}
    assert doc["config"]["primary_sensor"]["kind"] == "range-only"
    # a range alone leaves the cross-range direction to the prior: the radar's transfer fixes it
    assert rmse["tl-pf"] < 0.5 * rmse["pf"], rmse
    bound = doc["pcrlb"]
    assert all(w <= p for w, p in zip(bound["with_source"], bound["primary"], strict=True))
