"""The examples run as a user would run them, and say what they claim."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_a_user_defined_range_only_sensor_runs_tl_pf_through_the_public_api() -> None:
    argv = [sys.executable, str(EXAMPLES / "range_only.py"), "--runs", "3", "--particles", "2000"]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    rmse = dict(re.findall(r"^\s*(\S+): overall RMSE\s+([\d.]+) m", done.stdout, re.M))
    assert set(rmse) == {"pf", "tl-pf", "source-pf"}, done.stdout
    # a range alone leaves the cross-range direction to the prior: the radar's transfer fixes it
    assert float(rmse["tl-pf"]) < 0.5 * float(rmse["pf"]), done.stdout
