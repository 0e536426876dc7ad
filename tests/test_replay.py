"""The live replay's CSV: one column per measurement component, whatever each sensor's kind; any
number of rows per step where the sensor has a detection process, exactly one where it has not."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from tltrack.config import make_config
from tltrack.engine.setup import Setup
from tltrack.live.replay import ReplayError, load

pytestmark = pytest.mark.unit

CFG = make_config(
    primary_sensor={"kind": "bearing"},
    sources=[{"id": "s1", "sensor": {"kind": "range-bearing-doppler", "position": [-3000, 0]}}],
)
SETUP = Setup(CFG)
IDS = ["primary", "s1"]
HEADER = "k,sensor,range_m,bearing_rad,range_rate_mps,x_m,y_m\n"


def write(tmp_path: Path, rows: str, header: str = HEADER) -> Path:
    p = tmp_path / "meas.csv"
    p.write_text(header + rows)
    return p


def test_each_row_fills_its_own_sensors_components(tmp_path: Path) -> None:
    rows = "1,primary,,0.78,,,\n1,s1,4000,0.2,-3.5,,\n2,s1,4010,0.21,-3.4,,\n2,primary,,0.79,,,\n"
    got = load(write(tmp_path, rows), SETUP, IDS)
    np.testing.assert_array_equal([step["primary"] for step in got], [[[0.78]], [[0.79]]])
    np.testing.assert_array_equal(
        [step["s1"] for step in got], [[[4000, 0.2, -3.5]], [[4010, 0.21, -3.4]]]
    )


@pytest.mark.parametrize(
    ("rows", "message"),
    [
        ("1,primary,,,,,\n", ":2: a bearing sensor needs bearing_rad"),
        ("1,primary,,0.7,,,\n1,s1,-5,0.2,1,,\n", ":3: range_m must be finite and in (0, 1e9]"),
        ("1,primary,,4.0,,,\n", ":2: bearing_rad must be finite and in [-pi, pi]"),
        ("1,primary,,0.7,,,\n1,s1,5,0.2,nan,,\n", ":3: range_rate_mps must be finite"),
        ("1,radar,,0.7,,,\n", ":2: unknown sensor 'radar'"),
        ("x,primary,,0.7,,,\n", ":2: k must be an integer"),
        ("1,primary,,0.7,,,\n", "step 1 of sensor 's1' has 0 detections (lines: none)"),
    ],
)
def test_a_bad_file_is_refused_whole_naming_the_line(
    tmp_path: Path, rows: str, message: str
) -> None:
    with pytest.raises(ReplayError, match=re.escape(message)):
        load(write(tmp_path, rows), SETUP, IDS)


def test_a_missing_column_of_a_sensor_in_use_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ReplayError, match=r"missing column.*range_rate_mps"):
        load(write(tmp_path, "1,primary,0.7\n", "k,sensor,bearing_rad,range_m\n"), SETUP, IDS)


def test_two_rows_of_one_step_of_the_papers_sensor_are_refused_naming_both_lines(
    tmp_path: Path,
) -> None:
    """They used to keep the second row without a word: a measurement lost."""
    rows = "1,primary,,0.78,,,\n1,s1,4000,0.2,-3.5,,\n1,s1,4005,0.2,-3.5,,\n"
    with pytest.raises(ReplayError, match=re.escape("sensor 's1' has 2 detections (lines: 3, 4)")):
        load(write(tmp_path, rows), SETUP, IDS)


def test_a_sensor_in_clutter_replays_every_row_and_empty_steps(tmp_path: Path) -> None:
    cfg = CFG.with_(primary_detection={"pd": 0.8, "clutter_rate": 2.0})
    rows = "1,primary,,0.78,,,\n1,primary,,0.1,,,\n1,s1,4000,0.2,-3.5,,\n2,s1,4010,0.21,-3.4,,\n"
    got = load(write(tmp_path, rows), Setup(cfg), IDS)
    assert [step["primary"].shape for step in got] == [(2, 1), (0, 1)]
