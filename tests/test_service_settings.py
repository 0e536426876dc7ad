"""Every service's settings share one base (:class:`tltrack.live.service.ServiceSettings`): a
misspelt log level is refused at start with the field named, from a flag or the environment,
where it used to pass and then crash :mod:`logging` with a traceback; so is a Zenoh endpoint
that zenoh would crash on or dial for ever, in a service and in ``tltrack router``."""

import importlib

import pytest
from tltrack.app import app
from tltrack.live.service import ServiceSettings, load_settings
from typer.testing import CliRunner

pytestmark = pytest.mark.unit

SERVICES = {  # the module of each service's Settings: its environment prefix
    "tltrack.services.sensor.sensor": "TLTRACK_SENSOR_",
    "tltrack.services.sensor_sim.simulator": "TLTRACK_SIM_",
    "tltrack.services.scorer.scorer": "TLTRACK_SCORER_",
    "tltrack.services.dashboard.settings": "TLTRACK_DASHBOARD_",
    "tltrack.services.source_tracker.tracker": "TLTRACK_SOURCE_",
    "tltrack.services.primary_tracker.tracker": "TLTRACK_PRIMARY_",
}


def _settings(module: str) -> type[ServiceSettings]:
    cls = importlib.import_module(module).Settings
    assert issubclass(cls, ServiceSettings)
    return cls


@pytest.mark.parametrize("module", SERVICES)
def test_a_log_level_is_taken_in_any_case(module: str) -> None:
    assert load_settings(_settings(module), ["--log_level=debug"]).log_level == "DEBUG"


@pytest.mark.parametrize("module", SERVICES)
def test_a_misspelt_log_level_stops_the_service_naming_the_field(
    module: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    cls = _settings(module)
    with pytest.raises(SystemExit) as flag:
        load_settings(cls, ["--log_level=LOUD"])
    monkeypatch.setenv(f"{SERVICES[module]}LOG_LEVEL", "verbose")
    with pytest.raises(SystemExit) as env:
        load_settings(cls, [])
    assert flag.value.code == env.value.code == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and all("log_level" in line and "'INFO'" in line for line in err), err


@pytest.mark.parametrize("module", SERVICES)
def test_a_bad_zenoh_endpoint_stops_the_service_naming_it(
    module: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("TLTRACK_ZENOH_ENDPOINTS", "tcp/127.0.0.1:7447,tcp-127.0.0.1")
    with pytest.raises(SystemExit) as stop:
        load_settings(_settings(module), [])
    assert stop.value.code == 2
    assert "endpoints" in (err := capsys.readouterr().err) and "'tcp-127.0.0.1'" in err


@pytest.mark.parametrize(
    ("args", "env", "said"),
    [
        (["--listen", "tcp/0.0.0.0"], {}, "'tcp/0.0.0.0': its address must be host:port"),
        (["--connect", "tls/r:99999"], {}, "the port 0-65535"),
        ([], {"TLTRACK_ZENOH_LEASE_MS": "1"}, "lease_ms: Input should be greater than"),
    ],
)
def test_a_router_refuses_a_bad_endpoint_or_setting_at_start(
    args: list[str], env: dict[str, str], said: str
) -> None:
    r = CliRunner().invoke(app, ["router", *args], env=env)
    assert r.exit_code == 2 and said in " ".join(r.output.split()), r.output


def test_run_router_refuses_a_bad_endpoint_before_opening_a_session() -> None:
    """Its other callers (the demo, topologies, tests) pass endpoints the CLI never checked: a
    settings copy would skip validation and leave zenoh to fail as the session opens."""
    from tltrack.live.router import run_router

    with pytest.raises(ValueError, match="its address must be host:port"):
        run_router(["tcp/127.0.0.1"], announce=False)
    with pytest.raises(ValueError, match="zenoh has no protocol 'bogus'"):
        run_router(["tcp/127.0.0.1:0"], connect=["bogus/x"], announce=False)


@pytest.mark.parametrize(
    ("module", "flag", "said"),
    [
        ("tltrack.services.sensor_sim.simulator", '--wait_for=["primary"]', "operator:service"),
        ("tltrack.services.sensor_sim.simulator", '--wait_for=["a:scorer"]', "operator 'a'"),
        ("tltrack.services.sensor_sim.simulator", '--wait_for=["primary:b c"]', "name 'b c'"),
        ("tltrack.services.sensor.sensor", "--replay_csv=/nonexistent.csv", "does not point"),
        ("tltrack.services.sensor_sim.simulator", "--replay_csv=/nonexistent.csv", "does not"),
        ("tltrack.services.sensor_sim.simulator", "--wait_timeout_s=inf", "less than or equal"),
        ("tltrack.services.sensor_sim.simulator", "--linger_s=1e12", "less than or equal"),
        ("tltrack.services.primary_tracker.tracker", "--deadline_ms=inf", "less than or equal"),
        ("tltrack.services.primary_tracker.tracker", "--gap_timeout_s=inf", "less than or equal"),
        ("tltrack.services.source_tracker.tracker", "--max_episodes=10000", "less than or equal"),
    ],
)
def test_what_a_sensor_would_wait_on_or_fail_at_is_refused_at_start(
    module: str, flag: str, said: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """A token no service declares was awaited until the timeout (or crashed the wait); a
    missing replay file was found only once an episode started."""
    with pytest.raises(SystemExit) as stop:
        load_settings(_settings(module), [flag])
    assert stop.value.code == 2 and said in capsys.readouterr().err


@pytest.mark.parametrize(
    ("module", "env", "said"),
    [
        ("sensor_sim", {"TLTRACK_SIM_ZENOH": "{bad"}, 'field "zenoh"'),
        ("sensor", {"TLTRACK_SENSOR_ZENOH": "{bad"}, 'field "zenoh"'),
    ],
)
def test_a_value_that_is_not_its_json_is_refused_not_a_traceback(
    module: str, env: dict[str, str], said: str, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    """pydantic-settings raised SettingsError, which load_settings let through."""
    names = {"sensor_sim": "sensor_sim.simulator", "sensor": "sensor.sensor"}
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    with pytest.raises(SystemExit) as stop:
        load_settings(_settings(f"tltrack.services.{names[module]}"), [])
    assert stop.value.code == 2 and said in capsys.readouterr().err


@pytest.mark.parametrize("db", ["folder", "garbage.sqlite", "missing/folder/x.sqlite"])
def test_the_scorer_refuses_a_db_it_cannot_write_at_start(tmp_path, db: str) -> None:
    """Each was a traceback (sqlite3's, or FileNotFoundError's)."""
    import subprocess
    import sys

    (tmp_path / "folder").mkdir()
    (tmp_path / "garbage.sqlite").write_bytes(bytes(range(256)) * 8)
    (tmp_path / "missing").write_text("a file where a folder should be")
    r = subprocess.run(
        [sys.executable, "-m", "tltrack.services.scorer", "--db", str(tmp_path / db)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2 and "no SQLite file the scorer can write" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


def test_sensor_sim_refuses_a_replay_its_sensors_would_make_at_start(tmp_path, capsys) -> None:
    """Refused once a router had answered: without one, it waited for ever."""
    rows = tmp_path / "rows.csv"
    rows.write_text("k,sensor,range_m,bearing_rad\n1,primary,100,0.1\n")
    settings = _settings("tltrack.services.sensor_sim.simulator")
    with pytest.raises(SystemExit) as stop:
        load_settings(settings, [f"--replay_csv={rows}", "--measurements=false"])
    assert stop.value.code == 2 and "each operator's sensor replays" in capsys.readouterr().err


def test_a_router_on_a_port_in_use_says_so() -> None:
    """zenoh's refusal was a traceback."""
    import socket

    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        r = CliRunner().invoke(app, ["router", "--listen", f"tcp/127.0.0.1:{port}"])
    said = " ".join(r.output.split())
    assert r.exit_code == 1 and "the router did not start" in said, r.output
    assert "Address already in use" in said and ".rs:" not in said


def test_a_service_that_finds_no_router_in_time_says_so(tmp_path) -> None:
    import os
    import socket
    import subprocess
    import sys

    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    env = {
        **os.environ,
        "TLTRACK_ZENOH_ENDPOINTS": f"tcp/127.0.0.1:{port}",
        "TLTRACK_ZENOH_CONNECT_TIMEOUT_MS": "300",
    }
    r = subprocess.run(
        [sys.executable, "-m", "tltrack.services.scorer", "--db", str(tmp_path / "s.sqlite")],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert r.returncode == 1 and "scorer: no zenoh session with" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and "Unable to connect" in r.stderr


@pytest.mark.parametrize(
    ("module", "args"),
    [
        ("tltrack.services.sensor.sensor", ["--sensor", ""]),
        ("tltrack.services.source_tracker.tracker", ["--source_id="]),
        ("tltrack.services.sensor_sim.simulator", ["--config", ""]),
    ],
)
def test_an_empty_flag_is_refused_not_read_as_its_default(
    module: str, args: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    """The settings drop an empty value: `--sensor ''` ran as the default sensor in silence."""
    with pytest.raises(SystemExit) as stop:
        load_settings(_settings(module), args)
    assert stop.value.code == 2 and "given an empty value" in capsys.readouterr().err


def test_a_misspelt_variable_is_named_not_ignored_in_silence(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("TLTRACK_SENSOR_SENSORR", "s1")
    monkeypatch.setenv("TLTRACK_ZENOH_LEASE", "3000")
    monkeypatch.setenv("TLTRACK_ZENOH_LEASE_MS", "3000")  # a setting: not named
    load_settings(_settings("tltrack.services.sensor.sensor"), [])
    said = capsys.readouterr().err
    assert "TLTRACK_SENSOR_SENSORR is no setting of this service" in said
    assert "TLTRACK_ZENOH_LEASE is no setting" in said and "LEASE_MS" not in said


def test_a_plugin_that_fails_to_import_is_refused_not_a_traceback(
    tmp_path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "broken_plugin.py").write_text("raise RuntimeError('half-installed')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("TLTRACK_PLUGINS", "sensor=broken_plugin:Radar")
    with pytest.raises(SystemExit) as stop:
        load_settings(_settings("tltrack.services.sensor.sensor"), [])
    assert stop.value.code == 2 and "half-installed" in capsys.readouterr().err


def test_sensor_sim_waits_for_a_json_list_or_tokens_separated_by_commas(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """As the zenoh endpoints are read: the comma form was a traceback."""
    settings = _settings("tltrack.services.sensor_sim.simulator")
    want = ["primary:primary_tracker", "referee:scorer"]
    for given in (
        '["primary:primary_tracker","referee:scorer"]',
        "primary:primary_tracker, referee:scorer",
    ):
        monkeypatch.setenv("TLTRACK_SIM_WAIT_FOR", given)
        assert load_settings(settings, []).wait_for == want  # type: ignore[attr-defined]
    monkeypatch.setenv("TLTRACK_SIM_WAIT_FOR", "[bad")
    with pytest.raises(SystemExit) as stop:
        load_settings(settings, [])
    assert (
        stop.value.code == 2 and "wait_for: Value error, Expecting value" in capsys.readouterr().err
    )
