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
