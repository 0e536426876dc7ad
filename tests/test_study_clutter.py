"""``tltrack study clutter``: the clutter per gate it asks for is the one drawn, its 5%-loss
density is interpolated in log density, and a tiny study writes its files."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from tltrack.config import detection_of
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.studies import Runner, Setting
from tltrack.studies.clutter import (
    FILTERS,
    MARGIN_SIGMAS,
    clutter,
    configs,
    density_at,
    describe_density,
    factor,
    field_of_view,
    gate_volume,
    measured_per_gate,
)

pytestmark = pytest.mark.unit


def test_the_gate_volume_is_pi_gamma_sqrt_det_r_for_two_components() -> None:
    R = np.diag([400.0, 4e-5])
    assert gate_volume(R) == pytest.approx(math.pi * 9.2103404 * math.sqrt(400.0 * 4e-5))


def test_the_field_of_view_holds_every_noise_free_measurement_with_its_margin() -> None:
    cfg = configs(Setting(runs=1), 0.9, (1.0,), K=30)[0]
    setup = Setup(cfg)
    fov = field_of_view(setup)
    assert fov == {c: tuple(v) for c, v in cfg.primary_detection.fov.items()}  # type: ignore[union-attr]
    from tltrack.engine.scenario import truth

    z = setup.sensor(PRIMARY).h(truth(setup, 0)[1:].T)
    assert setup.sensors[PRIMARY].detection.inside(z).all()
    lo, hi = fov["range_m"]
    margin = MARGIN_SIGMAS * math.sqrt(setup.sensors[PRIMARY].R[0, 0])  # sigma_r = 20 m
    assert lo == pytest.approx(z[0].min() - margin) and hi == pytest.approx(z[0].max() + margin)


@pytest.mark.parametrize("per_gate", [0.5, 4.0])
def test_the_measured_clutter_per_gate_is_the_asked_one_within_poisson_error(
    per_gate: float,
) -> None:
    cfg = configs(Setting(runs=4), 0.9, (per_gate,), K=25)[0]
    got, scans = measured_per_gate(cfg)
    assert scans == 100
    assert abs(got - per_gate) <= 4.0 * math.sqrt(per_gate / scans)


def test_the_clutter_counts_are_the_same_from_the_pool_in_order() -> None:
    """The study counts its cells' false alarms in the gate on its runner's pool
    (:meth:`Runner.map`): every count is the one counted here, in the cells' order."""
    cells = configs(Setting(runs=3), 0.9, (0.0, 4.0, 0.5), K=10)
    here = [measured_per_gate(c) for c in cells]
    assert Runner(workers=2).map(measured_per_gate, cells) == here
    assert here[0] == (0.0, 30) and here[1] != here[2]


def test_the_5pct_density_is_interpolated_in_log_density() -> None:
    grid = (0.0, 0.05, 0.2, 0.5, 1.0, 2.0, 4.0)
    # 3% at 1, 10% at 2: 5% lies 2/7 of the way from log 1 to log 2
    value, note = density_at(grid, [0, 0, 0, 0.01, 0.03, 0.10, 0.5])
    assert note == "" and value == pytest.approx(2 ** (2 / 7))
    assert density_at(grid, [0, 0, 0, 0, 0.05, 0.2, 1])[0] == pytest.approx(1.0)  # on a point
    assert density_at(grid, [0, 0, 0, 0, 0, 0, 0.04]) == (None, "not reached")
    assert density_at(grid, [0.06, 0.5, 1, 1, 1, 1, 1]) == (None, "below the grid")
    assert density_at(grid, [0.0, 0.5, 1, 1, 1, 1, 1]) == (None, "below the grid")  # 0 .. 0.05
    # the first crossing, even if the curve falls back under 5% after it
    assert density_at(grid, [0, 0, 0.05, 0.01, 0.2, 0.3, 0.4])[0] == pytest.approx(0.2)
    assert describe_density((None, "not reached"), grid) == "not reached (> 4)"
    assert describe_density((None, "below the grid"), grid) == "below the grid (<= 0.05)"
    assert factor((2.0, ""), (0.5, ""), grid) == "4.00"
    assert factor((None, "not reached"), (0.5, ""), grid).startswith("> 8.00")


def test_a_tiny_study_writes_its_table_numbers_and_plot(tmp_path: Path) -> None:
    setting = Setting(runs=2, particles=150)
    ticks: list[int] = []
    path = clutter(
        setting,
        Runner(progress=ticks.append, workers=1),
        tmp_path,
        densities=(0.0, 2.0),
        pds=(0.9,),
        K=12,
    )
    assert path == tmp_path / "clutter.md"
    assert (tmp_path / "clutter.png").stat().st_size > 0
    assert sum(ticks) == 2
    text = path.read_text()
    assert "tl-rpf's 5%-loss density over rpf's" in text and "Field of view" in text
    data = json.loads((tmp_path / "clutter.json").read_text())
    cells = data["cells"]
    assert set(cells) == {"pd 0.9 | 0", "pd 0.9 | 2"}
    assert cells["pd 0.9 | 0"]["measured_per_gate"] == 0.0
    assert abs(cells["pd 0.9 | 2"]["measured_per_gate"] - 2.0) <= 4 * math.sqrt(2.0 / 24)
    assert set(cells["pd 0.9 | 2"]["filters"]) >= set(FILTERS)
    assert set(data["lost_5pct_density"]["0.9"]) == set(FILTERS)


def test_a_clean_source_is_the_papers_sensor_and_the_light_one_the_studys() -> None:
    light = configs(Setting(runs=1), 0.9, (0.5,), K=10)[0]
    clean = configs(Setting(runs=1), 0.9, (0.5,), source=(1.0, 0.0), K=10)[0]
    assert clean.sources[0].detection is None
    assert Setup(clean).sensors["s1"].detection.trivial
    got = detection_of(light, "s1")
    assert got.pd == 0.95
    per_gate = got.clutter_rate * gate_volume(Setup(light).sensors["s1"].R) / got.volume
    assert per_gate == pytest.approx(0.05)
    assert clean.primary_detection == light.primary_detection  # the primary's cell is the same
