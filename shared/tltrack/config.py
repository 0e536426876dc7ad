"""One validated configuration for every experiment, service and test.

The seed paper's Table 1 is the default preset, ``paper``. docs/background.md ("parameter
traps") explains why a second preset, ``arasaratnam-haykin``, exists: the seed prints
q2 = 1.75e-2 and P0(omega) = 0.1, which look like unit slips of the cubature-KF benchmark it says
it copies (q2 = 1.75e-4, P0(omega) = 1e-4). Both keep the seed's Q_v form.

A configuration is built from a scenario and a preset; any field given explicitly (from a TOML or
JSON file, or a CLI flag) overrides the preset's value. Unknown fields are refused, so a typo never
passes silently.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, FiniteFloat, ValidationError, model_validator

Scenario = Literal["cv", "ct", "ca"]
Preset = Literal["paper", "arasaratnam-haykin"]
TruthMode = Literal["fixed", "random", "noise-free", "file"]
SourceFault = Literal["none", "bias", "diverged", "stale"]
#: the posterior approximations a filter may use (tltrack.engine.registry builds them)
FilterKind = Literal["pf", "rpf", "ukf", "ckf3", "ckf5"]
#: the kinds that are particle filters (they take N, a random stream, fusion and recovery)
PARTICLE_KINDS = ("pf", "rpf")
#: the kinds of sensor an operator may have (tltrack.models.from_config builds them)
SensorKind = Literal["range-bearing", "bearing", "position", "range-bearing-doppler"]
#: each kind's noise parameters and their defaults (None: the config's flat field of that name)
SENSOR_PARAMETERS: dict[str, dict[str, float | None]] = {
    "range-bearing": {"sigma_r": None, "sigma_bearing": None},
    "bearing": {"sigma_bearing": None},
    "position": {"sigma_pos": 10.0},
    "range-bearing-doppler": {"sigma_r": None, "sigma_bearing": None, "sigma_rr": 1.0},
}
#: measurement components per sensor kind
SENSOR_NZ = {"range-bearing": 2, "bearing": 1, "position": 2, "range-bearing-doppler": 3}

_DEG = math.pi / 180.0

#: Scenario 1 (constant velocity) and Scenario 2 (coordinated turn), as printed in the seed, and a
#: constant-acceleration scenario of ours: x = [x, vx, ax, y, vy, ay], a slow target (a boat, a
#: drone) starting where Scenario 2 does at 30 m/s with a 0.5 m/s^2 lateral acceleration, so that
#: it stays within about 5 km of the sensors over 100 steps; q1 is the variance of the
#: acceleration's increment per step (m^2/s^4, a discrete Wiener-process acceleration): it
#: wanders by about 0.1 m/s^2 per step.
SCENARIO_DEFAULTS: dict[str, dict[str, Any]] = {
    "cv": {
        "x0": [100.0, 10.0, 100.0, 10.0],
        "P0_diag": [50.0, 1.0, 50.0, 1.0],
        "q1": 0.1,
        "q2": 0.0,
    },
    "ct": {
        "x0": [1000.0, 300.0, 1000.0, 0.0, -3.0 * _DEG],
        "P0_diag": [100.0, 10.0, 100.0, 10.0, 100e-3],
        "q1": 0.1,
        "q2": 1.75e-2,
    },
    "ca": {
        "x0": [1000.0, 30.0, 0.0, 1000.0, 0.0, 0.5],
        "P0_diag": [100.0, 10.0, 0.1, 100.0, 10.0, 0.1],
        "q1": 0.01,
        "q2": 0.0,
    },
}

#: the state dimension of each scenario's motion model
STATE_DIM = {"cv": 4, "ct": 5, "ca": 6}

#: Differences of each preset from the seed's values, per scenario (none where it names none).
PRESET_OVERRIDES: dict[str, dict[str, dict[str, Any]]] = {
    "paper": {},
    "arasaratnam-haykin": {"ct": {"q2": 1.75e-4, "P0_diag": [100.0, 10.0, 100.0, 10.0, 1e-4]}},
}


def preset_values(scenario: str, preset: str) -> dict[str, Any]:
    """The scenario's seed values with the preset's differences applied."""
    return {**SCENARIO_DEFAULTS[scenario], **PRESET_OVERRIDES[preset].get(scenario, {})}


Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
Latitude = Annotated[float, Field(ge=-90, le=90, allow_inf_nan=False)]
Longitude = Annotated[float, Field(ge=-180, le=180, allow_inf_nan=False)]
Point = tuple[FiniteFloat, FiniteFloat]


class SensorSpec(BaseModel):
    """One operator's sensor: its kind, where it sits, and the noise parameters of that kind.

    A parameter left out takes its default (:data:`SENSOR_PARAMETERS`); one that the kind does not
    have is refused. The operator's intensity I_w scales the resulting noise covariance.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    kind: SensorKind = "range-bearing"
    position: Point | None = None
    sigma_r: Positive | None = None
    sigma_bearing: Positive | None = None
    sigma_pos: Positive | None = None
    sigma_rr: Positive | None = None

    @model_validator(mode="after")
    def _parameters_of_its_kind(self) -> SensorSpec:
        own = SENSOR_PARAMETERS[self.kind]
        for name in ("sigma_r", "sigma_bearing", "sigma_pos", "sigma_rr"):
            if getattr(self, name) is not None and name not in own:
                raise ValueError(f"{name} is not a parameter of a {self.kind} sensor")
        return self

    @property
    def n_z(self) -> int:
        return SENSOR_NZ[self.kind]


class SourceSpec(BaseModel):
    """One source operator: its id, sensor, filter kind, and (for robustness studies) a fault.

    ``filter`` is the kind of the source's own filter; None: the kind of the TL primary it feeds.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    id: str = Field("s1", pattern=r"^[A-Za-z0-9_-]{1,32}$")
    intensity: float = Field(1.0, gt=0, allow_inf_nan=False)
    position: Point | None = Field(None, description="the sensor's position; default (0, 0)")
    fault: SourceFault = "none"
    filter: FilterKind | None = None
    sensor: SensorSpec | None = Field(None, description="default: the paper's range-bearing")

    @model_validator(mode="after")
    def _one_position(self) -> SourceSpec:
        if self.position is not None and self.sensor is not None and self.sensor.position:
            raise ValueError(f"source {self.id}: give either position or sensor.position, not both")
        return self


class Config(BaseModel):
    """Every parameter of a dual-tracking experiment. Units are SI, angles in radians."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    scenario: Scenario = "ct"
    preset: Preset = "paper"
    Ts: float = Field(1.0, gt=0, allow_inf_nan=False, description="sampling period [s]")
    K: int = Field(100, ge=1, le=100_000, description="time steps per run")
    x0: list[float] = Field(description="true initial state")
    P0_diag: list[float] = Field(description="diagonal of the initial covariance P0")
    q1: float = Field(ge=0, allow_inf_nan=False, description="acceleration noise [m^2/s^4]")
    q2: float = Field(ge=0, allow_inf_nan=False, description="turn-rate noise [rad^2/s^3]")
    sigma_r: float = Field(10.0, gt=0, allow_inf_nan=False, description="range std [m]")
    sigma_bearing: float = Field(
        math.sqrt(10.0) * 1e-3, gt=0, allow_inf_nan=False, description="bearing std [rad]"
    )
    primary_intensity: float = Field(4.0, gt=0, allow_inf_nan=False)
    primary_position: Point | None = Field(None, description="the sensor's position; (0, 0)")
    primary_sensor: SensorSpec | None = Field(None, description="default: the paper's radar")
    sources: list[SourceSpec] = Field(
        default_factory=lambda: [SourceSpec.model_validate({})], min_length=1
    )
    truth: TruthMode = "fixed"
    truth_seed: int = Field(0, ge=0)
    truth_file: Path | None = Field(
        None, description="a recorded track (CSV t,x,y or t,lat,lon) as the truth"
    )
    truth_origin: tuple[Latitude, Longitude] | None = Field(
        None, description="(lat, lon) of the frame's origin for a t,lat,lon truth file"
    )
    truth_max_gap_s: float = Field(
        120.0, gt=0, allow_inf_nan=False, description="longest gap between a truth file's reports"
    )
    seed: int = Field(0, ge=0)
    particles: int = Field(6000, ge=10, le=10_000_000)
    runs: int = Field(100, ge=1)
    kappa: float = Field(2.0, allow_inf_nan=False, description="UKF scaling parameter")
    lost_threshold_m: float = Field(100.0, gt=0, allow_inf_nan=False)
    gate_probability: float = Field(
        0.999, gt=0, lt=1, description="robust TL: probability an honest transfer passes the gate"
    )
    recovery: bool = Field(False, description="reinitialise a particle filter that lost track")
    rpf_bandwidth: float = Field(
        0.0,
        ge=0,
        lt=1,
        allow_inf_nan=False,
        description="rpf: the regularisation kernel's bandwidth h (0: off; docs/rpf.md)",
    )
    transfer_budget: float | None = Field(
        None, gt=0, le=1, description="robust TL: at most this share of steps with a transfer"
    )

    @model_validator(mode="before")
    @classmethod
    def _fill_from_preset(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        if data.get("truth_file") is not None:
            if data.get("truth") not in (None, "file"):
                raise ValueError(
                    f"give either truth_file or truth (the mode {data['truth']!r}), not both"
                )
            data = {**data, "truth": "file"}
        scenario = data.get("scenario", "ct")
        preset = data.get("preset", "paper")
        if scenario not in SCENARIO_DEFAULTS or preset not in PRESET_OVERRIDES:
            return data  # the field validators name the bad value
        return {**preset_values(scenario, preset), **data}

    @model_validator(mode="after")
    def _check_dimensions(self) -> Config:
        n = STATE_DIM[self.scenario]
        for name in ("x0", "P0_diag"):
            values = getattr(self, name)
            if len(values) != n:
                raise ValueError(f"{name} must have {n} entries for scenario {self.scenario!r}")
            if not all(math.isfinite(v) for v in values):
                raise ValueError(f"{name} must be finite")
        if any(v <= 0 for v in self.P0_diag):
            raise ValueError("P0_diag must be positive")
        if (self.truth == "file") != (self.truth_file is not None):
            raise ValueError("truth 'file' needs a truth_file, and a truth_file needs truth 'file'")
        ids = [s.id for s in self.sources]
        if len(set(ids)) != len(ids):
            raise ValueError(f"sources: duplicate id in {ids}")
        sensor = self.primary_sensor
        if self.primary_position is not None and sensor is not None and sensor.position:
            raise ValueError("give either primary_position or primary_sensor.position, not both")
        return self

    @property
    def n_x(self) -> int:
        return len(self.x0)

    @property
    def source(self) -> SourceSpec:
        """The first source: the paper's single source operator."""
        return self.sources[0]

    def with_(self, **changes: Any) -> Config:
        """A validated copy with some fields changed; raises :class:`ConfigError`.

        Changing the scenario or preset re-fills every field that still has the old preset's value.
        """
        data = self.model_dump()
        if {"scenario", "preset"} & changes.keys():
            old = preset_values(self.scenario, self.preset)
            data = {k: v for k, v in data.items() if k not in old or old[k] != v}
        return make_config(data, **changes)

    def with_source_intensity(self, intensity: float) -> Config:
        """The same experiment with the (first) source's noise intensity changed."""
        first = {**self.sources[0].model_dump(), "intensity": intensity}
        return self.with_(sources=[first, *self.sources[1:]])


class ConfigError(ValueError):
    """A configuration was refused; the message names the offending field."""


def describe_validation_error(err: ValidationError) -> str:
    """One line per problem, each starting with the field's dotted path."""
    lines = []
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"]) or "(config)"
        lines.append(f"{loc}: {e['msg']}")
    return "; ".join(lines)


def make_config(data: dict[str, Any] | None = None, **overrides: Any) -> Config:
    """Build a config from a mapping plus keyword overrides, raising :class:`ConfigError`."""
    merged = {**(data or {}), **{k: v for k, v in overrides.items() if v is not None}}
    try:
        return Config.model_validate(merged)
    except ValidationError as err:
        raise ConfigError(describe_validation_error(err)) from None


def load_config(path: str | Path, **overrides: Any) -> Config:
    """Load a TOML or JSON file (by extension); keyword overrides win over the file."""
    return make_config(read_mapping(path), **overrides)


def read_mapping(path: str | Path) -> dict[str, Any]:
    """The top-level table of a TOML or JSON config file (by extension), not yet validated."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as err:
        raise ConfigError(f"cannot read config file {p}: {err.strerror}") from None
    try:
        data = tomllib.loads(text) if p.suffix.lower() == ".toml" else json.loads(text)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as err:
        raise ConfigError(
            f"{p}: not valid {p.suffix.lstrip('.').upper() or 'JSON'}: {err}"
        ) from None
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: the top level must be a table/object")
    return data
