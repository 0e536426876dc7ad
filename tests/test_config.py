import json

import pytest
from tltrack.config import ConfigError, load_config, make_config

pytestmark = pytest.mark.unit


def test_presets_differ_only_where_notes_say():
    paper = make_config(scenario="ct")
    ah = make_config(scenario="ct", preset="arasaratnam-haykin")
    assert paper.q2 == 1.75e-2 and paper.P0_diag[4] == 0.1
    assert ah.q2 == 1.75e-4 and ah.P0_diag[4] == 1e-4
    assert paper.model_dump(exclude={"preset", "q2", "P0_diag"}) == ah.model_dump(
        exclude={"preset", "q2", "P0_diag"}
    )


@pytest.mark.parametrize(
    ("field", "value"),
    [("particles", -3), ("truth", "sometimes"), ("sigma_r", float("nan")), ("K", 0), ("Ts", 0)],
)
def test_bad_values_are_refused_naming_the_field(field, value):
    with pytest.raises(ConfigError, match=field):
        make_config(**{field: value})


@pytest.mark.parametrize(
    ("changes", "why"),
    [
        # K derived from duration_s escaped K's bound: 1e12 steps asked for 36 TiB
        (
            {"duration_s": 1e12},
            "duration_s = 1e\\+12 s holds K = 1000000000000 steps of the primary",
        ),
        ({"duration_s": 100_001.0}, "at most 100000"),
        # the UKF's sqrt(n + kappa) raised from the first filter made, after validation
        ({"kappa": -5.0}, "kappa = -5: n \\+ kappa must be positive \\(ct: n = 5\\)"),
        # K periods of 1e200 s overflowed the timeline's int64 microseconds
        ({"Ts": 1e200, "K": 3}, "Ts"),
        ({"max_clock_offset_s": 1e300}, "max_clock_offset_s"),
        ({"sources": [{"id": "s1", "period_s": 1e200}]}, "period_s"),
        # a state per 1 ms tick of 1e5 s: 1e8 of them, 4 GB of truth
        ({"K": 100_000, "primary_phase_s": 0.001}, "100000001 of its steps in the episode"),
    ],
    ids=["duration-1e12", "duration-over", "kappa", "Ts", "clock-offset", "source-period", "ticks"],
)
def test_values_that_validated_and_then_failed_are_refused(changes, why):
    with pytest.raises(ConfigError, match=why):
        make_config(**changes)
    assert make_config(kappa=-4.5).kappa == -4.5  # n + kappa > 0: allowed


def test_a_config_file_with_a_byte_order_mark_or_nested_too_deeply(tmp_path):
    """An editor's BOM was "not valid TOML ... at line 1, column 1"; a JSON nested 100000 deep
    raised RecursionError, a traceback."""
    bom = tmp_path / "bom.toml"
    bom.write_text('scenario = "cv"\n', encoding="utf-8-sig")
    assert load_config(bom).scenario == "cv"
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ConfigError, match=r"deep\.json: not valid JSON: nested too deeply"):
        load_config(deep)


def test_unknown_field_and_wrong_dimension_are_refused():
    with pytest.raises(ConfigError, match="partcles"):
        make_config({"partcles": 10})
    with pytest.raises(ConfigError, match="x0"):
        make_config(scenario="cv", x0=[1.0, 2.0, 3.0, 4.0, 5.0])


def test_loads_toml_and_json_with_overrides(tmp_path):
    toml = tmp_path / "c.toml"
    toml.write_text('scenario = "cv"\nparticles = 500\n[[sources]]\nid = "a"\nintensity = 2.0\n')
    cfg = load_config(toml, runs=7)
    assert (cfg.scenario, cfg.particles, cfg.runs, cfg.source.intensity) == ("cv", 500, 7, 2.0)
    js = tmp_path / "c.json"
    js.write_text(json.dumps({"preset": "arasaratnam-haykin", "truth": "noise-free"}))
    assert load_config(js).q2 == 1.75e-4
    bad = tmp_path / "bad.toml"
    bad.write_text("particles = [")
    with pytest.raises(ConfigError, match=r"bad\.toml"):
        load_config(bad)
    with pytest.raises(ConfigError, match=r"sources\.0\.intensity"):
        make_config().with_source_intensity(0.0)


def test_recovery_takes_numpy_booleans_as_the_code_passes_them() -> None:
    import numpy as np

    assert make_config(recovery=np.bool_(True)).recovery is True
