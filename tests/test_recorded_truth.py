"""A recorded track as the truth, through the config, the engine and the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from tltrack.config import ConfigError, make_config
from tltrack.config.load import complete_from_truth_file, load_config
from tltrack.config.truth_file import StateLayout, TruthFileError, file_truth
from tltrack.engine.montecarlo import run_batch
from tltrack.engine.scenario import truth
from tltrack.engine.setup import Setup
from tltrack.filters.kinds import FILTERS
from tltrack.models.kinds import MOTIONS
from typer.testing import CliRunner

pytestmark = pytest.mark.unit

TRACK = Path(__file__).resolve().parents[1] / "examples" / "tracks"
#: the AIS track the README describes (examples/tracks holds other tracks too: glob order is
#: the file system's, which picked a 1200-step flight in a fresh clone)
SHIP = TRACK / "ais-nyharbor-2020-06-30-mmsi-367370920.csv"


def test_a_truth_file_sets_the_truth_mode_k_and_x0() -> None:
    cfg = load_config(None, truth_file=SHIP)
    assert cfg.truth == "file" and cfg.K > 2000
    x = truth(Setup(cfg), 0)
    assert x.shape == (cfg.K + 1, 5)
    np.testing.assert_allclose(x[0], cfg.x0)
    np.testing.assert_array_equal(truth(Setup(cfg), 7), x)  # one track for every run
    shorter = load_config(None, truth_file=SHIP, K=50)
    np.testing.assert_array_equal(truth(Setup(shorter), 0), x[:51])


def test_a_truth_mode_and_a_truth_file_together_are_refused() -> None:
    with pytest.raises(ConfigError, match="either truth_file or truth"):
        make_config(truth_file=SHIP, truth="random")
    with pytest.raises(ConfigError, match="either truth_file or truth"):
        complete_from_truth_file({"truth_file": SHIP, "truth": "fixed"})


def test_k_may_only_shorten_the_track() -> None:
    with pytest.raises(TruthFileError, match="longer than the track"):
        complete_from_truth_file({"truth_file": SHIP, "K": 100_000})


def test_a_sensor_on_the_track_is_refused_naming_it_and_the_step() -> None:
    cfg = load_config(None, truth_file=SHIP)
    x, y = truth(Setup(cfg), 0)[40, [0, 2]]
    with pytest.raises(TruthFileError, match=r"s1.*step"):
        complete_from_truth_file(
            {"truth_file": SHIP, "sources": [{"id": "s1", "position": [x + 30, y]}]}
        )


def test_a_config_not_completed_from_its_file_is_refused_by_the_engine() -> None:
    cfg = make_config(truth_file=SHIP)  # x0 left at the scenario's: not the track's start
    with pytest.raises(TruthFileError, match="x0 is not the track's first state"):
        file_truth(cfg)


def test_the_truth_files_layouts_are_the_motion_models() -> None:
    for scenario in MOTIONS.names():
        lay = StateLayout.of(MOTIONS.get(scenario).components)
        model = Setup(make_config(scenario=scenario)).motion
        assert (lay.n, lay.pos, lay.vel) == (model.n, model.layout.pos, model.layout.vel)
    assert StateLayout.of(MOTIONS.get("ct").components).turn_rate == 4


@pytest.mark.parametrize("scenario", ["cv", "ct", "ca"])
def test_every_filter_kind_runs_on_the_shipped_track(scenario: str) -> None:
    cfg = load_config(None, truth_file=SHIP, scenario=scenario, K=60, particles=200)
    names = [f"{r}{k}" for k in FILTERS.names() for r in ("", "tl-")]
    stats = run_batch(cfg, names, [0, 1])
    for name in names:  # runs, and stays in the picture (a bootstrap PF with N = 200 may drift)
        rmse = np.sqrt(stats[name].sq_err / 2)
        assert np.all(np.isfinite(rmse)) and rmse[-1] < 1000.0, (name, rmse[-1])


def test_the_cli_records_the_file_and_its_hash(tmp_path: Path) -> None:
    from tltrack.app import app

    out = tmp_path / "e"
    short = tmp_path / "short.toml"  # the track's first 60 steps (all 2850 took half a minute)
    short.write_text("K = 60\n")
    argv = ["experiment", "--config", str(short), "--truth-file", str(SHIP)]
    argv += ["--filters", "ukf,tl-ukf", "--runs", "2"]
    done = CliRunner().invoke(app, [*argv, "--workers", "1", "--out", str(out)])
    assert done.exit_code == 0, done.output
    doc = json.loads((out / "results.json").read_text())
    assert doc["truth"]["mode"] == "file" and doc["truth"]["file"] == SHIP.name
    assert doc["truth"]["K"] == doc["config"]["K"] == 60
    assert len(doc["truth"]["sha256"]) == 64 and doc["config"]["truth"] == "file"
    bad = CliRunner().invoke(app, [*argv, "--truth", "fixed", "--out", str(out)])
    assert bad.exit_code == 2 and "either truth_file or truth" in bad.output


def test_a_config_files_truth_file_is_found_from_that_files_folder(tmp_path, monkeypatch) -> None:
    """As its author wrote it, wherever the command runs; an option given beside stays as given."""
    import shutil

    folder = tmp_path / "study"
    folder.mkdir()
    shutil.copy(SHIP, folder / "ship.csv")
    (folder / "c.toml").write_text('truth_file = "ship.csv"\nscenario = "cv"\n')
    monkeypatch.chdir(tmp_path)
    cfg = load_config(folder / "c.toml")
    assert cfg.truth == "file" and cfg.truth_file == folder / "ship.csv"
    assert load_config(folder / "c.toml", truth_file=str(SHIP)).truth_file == SHIP
