"""Components from outside the package: a sensor named by its import path in a TOML file, a
filter kind installed through an entry point, and messages that name kinds a receiver does not
know (refused, counted, and nothing imported)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import typing
from pathlib import Path

import numpy as np
import pytest
from doubles import Offline, episode_start, received
from livestack import estimates
from tltrack.config import Config, ModeSpec, SensorSpec, SourceSpec, load_config
from tltrack.engine.montecarlo import trace_run
from tltrack.filters.kinds import FILTERS
from tltrack.models.kinds import MOTIONS, SENSORS
from tltrack.services.primary_tracker import tracker as primary_svc
from tltrack.wire import keys
from tltrack.wire.messages import SCHEMA_VERSION, Transfer, encode

ROOT = Path(__file__).resolve().parents[1]
RANGE_ONLY = ROOT / "examples" / "range_only"
PLUGINS = Path(__file__).resolve().parent / "plugins"


def tltrack(
    *args: str, pythonpath: list[Path], env: dict[str, str] | None = None, timeout: float = 600
) -> subprocess.CompletedProcess[str]:
    path = os.pathsep.join([*map(str, pythonpath), os.environ.get("PYTHONPATH", "")])
    full = {**os.environ, "PYTHONPATH": path, "MPLBACKEND": "Agg", **(env or {})}
    argv = [sys.executable, "-m", "tltrack", *args]
    return subprocess.run(argv, env=full, capture_output=True, text=True, timeout=timeout)


# ---- messages never import ------------------------------------------------------------------


@pytest.fixture
def booby_trap(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An importable module that leaves a mark if anyone imports it."""
    (tmp_path / "booby_trap.py").write_text(
        "from pathlib import Path\n"
        f"Path({str(tmp_path / 'imported')!r}).write_text('yes')\n"
        "class Evil:\n    kind = 'evil'\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path / "imported"


@pytest.mark.unit
def test_a_message_naming_an_unknown_kind_is_refused_counted_and_imports_nothing(
    booby_trap: Path,
) -> None:
    svc = Offline("primary_tracker")
    tracker = primary_svc.PrimaryTracker(primary_svc.Settings.model_validate({}), svc)
    tracker.handle(received(keys.episode("e1"), episode_start("e1", 5)))
    radar = {"position": (0.0, 0.0), "sigma_r": 10.0, "sigma_bearing": 3e-3}
    for kind in ("booby_trap:Evil", "sonar"):
        t = Transfer.model_construct(
            episode="e1", sender="s1", k=1, t_sensor=0.0, k_apply=2,
            sensor=SensorSpec.model_construct(kind=kind, **radar),
            eta=[1000.0, 0.1], P_eta=[[100.0, 0.0], [0.0, 1e-4]],
        )  # fmt: skip
        tracker.handle(received(keys.transfer("s1", "e1"), encode(t)))
    cfg = Config.model_validate({}).model_dump(mode="json")
    cfg["sources"][0]["sensor"] = {"kind": "booby_trap:Evil"}
    start = json.loads(json.dumps({"config": cfg}))["config"]
    from tltrack.wire.messages import EpisodeStart

    bad = EpisodeStart.model_construct(
        schema_version=SCHEMA_VERSION, type="episode_start", episode="e2", sender="sensor_sim", k=0,
        t_sensor=0.0, run=0, config=start, K=5, steps_per_sec=0.0,
    )  # fmt: skip
    tracker.handle(received(keys.episode("e2"), encode(bad)))
    counts = svc.rejects.snapshot()
    assert counts["by_reason"].get("unknown_kind") == 3, counts
    assert not booby_trap.exists() and "booby_trap" not in sys.modules
    assert tracker.episodes.get("e2") is None


@pytest.mark.unit
def test_a_kind_is_imported_by_path_from_the_users_own_config_only(
    booby_trap: Path, tmp_path: Path
) -> None:
    with pytest.raises(ValueError, match="not imported"):
        Config.model_validate({"primary_sensor": {"kind": "booby_trap:Evil"}})
    assert not booby_trap.exists()
    (tmp_path / "mine.toml").write_text(
        'scenario = "cv"\n[primary_sensor]\nkind = "doubles:PositionSensor"\nsigma = 3.0\n'
    )
    cfg = load_config(tmp_path / "mine.toml")
    assert cfg.primary_sensor is not None and cfg.primary_sensor.kind == "test-position"
    assert SENSORS.imported["test-position"] == "doubles:PositionSensor"
    with pytest.raises(ValueError, match="sigma must be > 0"):
        Config.model_validate({"primary_sensor": {"kind": "test-position", "sigma": -1.0}})


# ---- declarations ---------------------------------------------------------------------------


def _numeric(annotation: object) -> bool:
    """Does a field's type hold numbers (float, int, or lists and tuples of them)?"""
    if annotation in (float, int):
        return True
    return any(_numeric(a) for a in typing.get_args(annotation) if a is not bool)


@pytest.mark.unit
def test_every_numeric_config_field_and_every_declared_parameter_has_a_unit() -> None:
    missing = [
        f"{model.__name__}.{name}"
        for model in (Config, SourceSpec, SensorSpec, ModeSpec)
        for name, field in model.model_fields.items()
        if _numeric(field.annotation)
        and not (isinstance(field.json_schema_extra, dict) and field.json_schema_extra.get("unit"))
    ]
    assert not missing, f"numeric fields without a unit: {missing}"
    for registry in (SENSORS, MOTIONS, FILTERS):
        for kind in registry.names():
            for p in registry.get(kind).parameters:
                assert p.unit and p.doc, (kind, p.name)


# ---- through the CLI and the live services ---------------------------------------------------


@pytest.fixture(scope="module")
def ekf_site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A site folder with the EKF plugin's distribution metadata: its entry point."""
    site = tmp_path_factory.mktemp("site")
    info = site / "ekfplugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: ekfplugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[tltrack.filters]\nekf = ekfplugin:ExtendedKalmanFilter\n"
    )
    return site


@pytest.mark.integration
def test_a_filter_kind_installed_as_a_plugin_runs_in_every_role(
    ekf_site: Path, tmp_path: Path
) -> None:
    names = "ekf,tl-ekf,robust-tl-ekf,source-ekf"
    args = ["experiment", "--scenario", "cv", "--filters", names, "--runs", "4", "--workers", "1"]
    done = tltrack(*args, "--out", str(tmp_path), pythonpath=[ekf_site, PLUGINS])
    assert done.returncode == 0, done.stderr[-3000:]
    res = json.loads((tmp_path / "results.json").read_text())["filters"]
    assert set(res) == set(names.split(","))
    rmse = {n: r["rmse_overall"] for n, r in res.items()}
    assert all(np.isfinite(v) for v in rmse.values()), rmse
    # the better source's transfer helps the noisier primary, judged or not
    assert rmse["tl-ekf"] < rmse["ekf"] and rmse["robust-tl-ekf"] < rmse["ekf"], rmse


@pytest.mark.integration
def test_a_range_only_source_from_a_toml_file_runs_offline_and_live_with_the_same_numbers(
    tmp_path: Path,
) -> None:
    """examples/range_only: the sensor's class in one file, named in the TOML by import path;
    its transfer crosses the federated stack's routers, and the lock-step primary equals the
    engine."""
    toml = str(RANGE_ONLY / "source.toml")
    common = ["--config", toml, "--particles", "300", "--seed", "3"]
    done = tltrack(
        "experiment", *common, "--filters", "rpf,tl-rpf", "--runs", "2", "--workers", "1",
        "--out", str(tmp_path / "offline"), pythonpath=[RANGE_ONLY],
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    doc = json.loads((tmp_path / "offline" / "results.json").read_text())
    assert doc["config"]["sources"][0]["sensor"]["kind"] == "range-only"
    K = 15
    live = tltrack(
        "demo", *common, "--steps", str(K), "--pace", "0", "--out", str(tmp_path / "live"),
        pythonpath=[RANGE_ONLY], env={"TLTRACK_PRIMARY_LOCKSTEP": "true"},
    )  # fmt: skip
    assert live.returncode == 0, live.stdout[-2000:] + live.stderr[-3000:]
    got = estimates(tmp_path / "live" / "scorer.sqlite")
    sys.path.insert(0, str(RANGE_ONLY))
    try:
        cfg = load_config(toml, K=K, particles=300, seed=3, recovery=True)  # the trackers' own
    finally:
        sys.path.remove(str(RANGE_ONLY))
    offline = trace_run(cfg, ["tl-rpf", "rpf", "source-rpf"], run=0)
    for name, x in offline.items():
        live_x = np.array([got[name][k][0] for k in range(1, K + 1)])
        np.testing.assert_allclose(live_x, x, rtol=0, atol=1e-9, err_msg=name)
    assert [got["tl-rpf"][k][1] for k in range(1, K + 1)] == [False] + [True] * (K - 1)
