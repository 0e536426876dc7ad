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
