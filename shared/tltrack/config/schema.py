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

import math
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    FiniteFloat,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from tltrack.config.target_classes import TARGET_CLASSES, TargetClassName
from tltrack.config.timeline import Clock, Timeline, us
from tltrack.declare import Parameter, UnknownKindError
from tltrack.filters.kinds import FILTERS
from tltrack.models.detection import Detection
from tltrack.models.kinds import MOTIONS, SENSORS

Preset = Literal["paper", "arasaratnam-haykin"]
TruthMode = Literal["fixed", "random", "noise-free", "file"]
SourceFault = Literal["none", "bias", "diverged", "stale"]

#: Differences of each preset from the seed's values (the motion models' ``defaults``), per
#: scenario (none where it names none).
PRESET_OVERRIDES: dict[str, dict[str, dict[str, Any]]] = {
    "paper": {},
    "arasaratnam-haykin": {"ct": {"q2": 1.75e-4, "P0_diag": [100.0, 10.0, 100.0, 10.0, 1e-4]}},
}


def preset_values(scenario: str, preset: str) -> dict[str, Any]:
    """The scenario's seed values with the preset's differences applied."""
    defaults = MOTIONS.get(scenario).defaults
    return {**defaults, **PRESET_OVERRIDES[preset].get(scenario, {})}


def _class_fields(data: dict[str, Any], Ts: Any) -> dict[str, Any]:
    """What the mapping's ``target_class`` fills at its period ``Ts`` (the modes and their
    chain); nothing when the mapping gives its own ``motion_modes``."""
    name = data.get("target_class")
    if name not in TARGET_CLASSES or data.get("motion_modes") is not None:
        return {}
    if not isinstance(Ts, int | float) or not math.isfinite(Ts) or Ts <= 0:
        return {}  # Ts's validator names it
    return TARGET_CLASSES[name].fields(float(Ts))


def trusted(info: ValidationInfo) -> bool:
    """Was this validation asked for by the user's own file or command line (not a message)?

    Only then may a kind be named by its import path (:mod:`tltrack.declare`).
    """
    return bool(info.context and info.context.get("trusted"))


def _kind(registry: Any, name: str, info: ValidationInfo) -> str:
    """``name`` as its registry's declared kind, or a validation error of type ``unknown_kind``."""
    try:
        return str(registry.canonical(name, trusted=trusted(info)))
    except UnknownKindError as err:
        raise PydanticCustomError("unknown_kind", "{msg}", {"msg": str(err)}) from None


def unit(u: str) -> dict[str, Any]:
    """A field's unit, for ``json_schema_extra``: every numeric field declares one (SI; "1" for
    a pure number or a count)."""
    return {"unit": u}


def _filter_kind(v: str) -> str:
    return FILTERS.canonical(v, trusted=True)


#: a filter kind in a service's own settings (trusted: a plugin may be named by import path)
FilterKindName = Annotated[str, AfterValidator(_filter_kind)]

#: the primary operator's sensor id; a source's is its own id
PRIMARY = "primary"
#: the most false alarms a scan may be asked to draw on average: the clutter study's densest cell
#: draws about 40,000; a rate of 1e9 asked for 15 GiB in a single run of 100 particles
MAX_CLUTTER_RATE = 1_000_000
#: the most steps a run may have (K, or duration_s / Ts)
MAX_STEPS = 100_000
#: the most steps of the grid of every operator's sample times an episode may hold: the truth
#: holds a state at each (K = 100000 with a phase of 1 ms asked for 1e8, 4 GB)
MAX_TICKS = 10_000_000
#: the longest period, clock offset: 1e6 s (11.6 days); K of them stay well inside the int64
#: microseconds of the timeline (:mod:`tltrack.config.timeline`), where 1e200 s overflowed
LONGEST_S = 1e6

Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
Latitude = Annotated[float, Field(ge=-90, le=90, allow_inf_nan=False)]
Longitude = Annotated[float, Field(ge=-180, le=180, allow_inf_nan=False)]
Point = tuple[FiniteFloat, FiniteFloat]


# Checks before pydantic's coercion, which would read ``runs = true`` as 1, ``"1"`` as 1 and
# ``recovery = "yes"`` as true: a value of the wrong type in a file is a mistake to name.


def _whole_number(v: Any) -> Any:
    if isinstance(v, bool | str):
        raise ValueError(f"a whole number, not {v!r}")
    return v


def _true_or_false(v: Any) -> Any:
    if not isinstance(v, bool | np.bool_):
        raise ValueError(f"true or false, not {v!r}")
    return bool(v)


#: a whole number, not a boolean or a string (a float with no fraction passes, as pydantic's own)
Count = Annotated[int, BeforeValidator(_whole_number)]
#: true or false, not a string or a number
Flag = Annotated[bool, BeforeValidator(_true_or_false)]


class SensorSpec(BaseModel):
    """One operator's sensor: its kind, where it sits, and the parameters its kind declares.

    Fields every sensor has (``position``) are declared here; the kind's own parameters (its
    class's ``parameters``, :mod:`tltrack.models.kinds`) sit beside ``kind``, and one that the
    kind does not declare is refused. A parameter left out takes its default. The operator's
    intensity I_w scales the resulting noise covariance.
    """

    model_config = ConfigDict(extra="allow", frozen=True)

    kind: str = Field("range-bearing", description="a registered sensor kind")
    position: Point | None = Field(
        None, description="where the sensor sits (x, y)", json_schema_extra=unit("m")
    )

    @field_validator("kind")
    @classmethod
    def _registered(cls, v: str, info: ValidationInfo) -> str:
        return _kind(SENSORS, v, info)

    @model_validator(mode="after")
    def _parameters_of_its_kind(self) -> SensorSpec:
        declared = {p.name: p for p in self.declared}
        extra = self.__pydantic_extra__ or {}
        for name, value in extra.items():
            if name not in declared:
                own = ", ".join(declared) or "none"
                raise ValueError(
                    f"{name} is not a parameter of a {self.kind} sensor (its parameters: {own})"
                )
            if isinstance(value, float) and not math.isfinite(value):
                raise PydanticCustomError("finite_number", "{name} must be finite", {"name": name})
            extra[name] = declared[name].check(value)
        return self

    @property
    def declared(self) -> tuple[Parameter, ...]:
        """The parameters its kind declares."""
        return tuple(SENSORS.get(self.kind).parameters)

    @property
    def params(self) -> dict[str, float]:
        """The parameters given (a full :func:`~tltrack.engine.setup.sensor_spec` has them all)."""
        return dict(self.__pydantic_extra__ or {})

    @property
    def n_z(self) -> int:
        return len(SENSORS.get(self.kind).components)

    def __hash__(self) -> int:
        return hash((self.kind, self.position, tuple(sorted(self.params.items()))))


class DetectionSpec(BaseModel):
    """An operator's detection process (:mod:`tltrack.models.detection`): missed detections,
    false alarms and the field of view, in its sensor's measurement components. The defaults are
    the paper's sensor: the target's measurement in every scan, and nothing else."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    pd: float = Field(
        1.0,
        gt=0,
        le=1,
        allow_inf_nan=False,
        description="probability of detecting the target in a scan",
        json_schema_extra=unit("1"),
    )
    clutter_rate: float = Field(
        0.0,
        ge=0,
        le=MAX_CLUTTER_RATE,
        allow_inf_nan=False,
        description="mean false alarms per scan (Poisson; at most a million, the memory's bound)",
        json_schema_extra=unit("1"),
    )
    fov: dict[str, tuple[FiniteFloat, FiniteFloat]] = Field(
        default_factory=dict,
        description="field of view: component name (range_m, bearing_rad, x_m, y_m, "
        "range_rate_mps) -> [lo, hi]; a bearing sector across +-pi has lo > hi",
        json_schema_extra=unit("each component's own"),
    )


class LinkSpec(BaseModel):
    """The engine's model of a source's link to the primary (:class:`~tltrack.engine.driver.Lossy`):
    each transfer is lost, or arrives late by ``delay_s`` plus a uniform jitter, and the primary
    takes it only if it came within ``deadline_s`` of its own measurement. Live, the real link and
    the primary tracker's own deadline apply instead, and this is ignored."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    loss: float = Field(
        0.0,
        ge=0,
        le=1,
        allow_inf_nan=False,
        description="probability that a transfer is lost",
        json_schema_extra=unit("1"),
    )
    delay_s: float = Field(
        0.0,
        ge=0,
        allow_inf_nan=False,
        description="from the source's step to the transfer's arrival",
        json_schema_extra=unit("s"),
    )
    jitter_s: float = Field(
        0.0,
        ge=0,
        allow_inf_nan=False,
        description="a uniform extra delay in [0, jitter_s]",
        json_schema_extra=unit("s"),
    )
    deadline_s: float = Field(
        0.25,
        ge=0,
        allow_inf_nan=False,
        description="the primary's wait for the transfer after its own measurement (live: the "
        "primary tracker's deadline_ms)",
        json_schema_extra=unit("s"),
    )


class ModeSpec(BaseModel):
    """One motion mode of the filters (``motion_modes``), in the coordinated turn's state:
    ``cv`` holds the turn rate at 0, ``ct`` turns with turn-rate noise q2."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    kind: Literal["cv", "ct"]
    q1: float = Field(
        ge=0,
        allow_inf_nan=False,
        description="acceleration noise",
        json_schema_extra=unit("m^2/s^4"),
    )
    q2: float = Field(
        0.0,
        ge=0,
        allow_inf_nan=False,
        description="turn-rate noise (ct only)",
        json_schema_extra=unit("rad^2/s^3"),
    )

    @model_validator(mode="after")
    def _no_turn_noise_when_straight(self) -> ModeSpec:
        if self.kind == "cv" and self.q2 != 0.0:
            raise ValueError("a cv mode holds the turn rate at 0: it has no q2")
        return self


class SourceSpec(BaseModel):
    """One source operator: its id, sensor, filter kind, and (for robustness studies) a fault.

    ``filter`` is the kind of the source's own filter; None: the kind of the TL primary it feeds.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    id: str = Field("s1", pattern=r"^[A-Za-z0-9_-]{1,32}$")
    intensity: float = Field(
        1.0,
        gt=0,
        allow_inf_nan=False,
        description="its noise intensity I_w",
        json_schema_extra=unit("1"),
    )
    position: Point | None = Field(
        None, description="the sensor's position; default (0, 0)", json_schema_extra=unit("m")
    )
    fault: SourceFault = "none"
    filter: str | None = Field(None, description="a registered filter kind")
    sensor: SensorSpec | None = Field(None, description="default: the paper's range-bearing")
    detection: DetectionSpec | None = Field(None, description="default: no miss, no clutter")
    link: LinkSpec | None = Field(
        None, description="the engine's lossy, late link to the primary; default: perfect"
    )
    period_s: float | None = Field(
        None,
        gt=0,
        le=LONGEST_S,
        allow_inf_nan=False,
        description="its sensor's sampling period; default: Ts",
        json_schema_extra=unit("s"),
    )
    phase_s: float = Field(
        0.0,
        ge=0,
        allow_inf_nan=False,
        description="its first sample is at phase_s + period_s, in [0, period_s)",
        json_schema_extra=unit("s"),
    )
    clock_offset_s: float = Field(
        0.0,
        allow_inf_nan=False,
        description="what its clock reads minus the true time, within max_clock_offset_s",
        json_schema_extra=unit("s"),
    )

    @field_validator("filter")
    @classmethod
    def _registered(cls, v: str | None, info: ValidationInfo) -> str | None:
        return None if v is None else _kind(FILTERS, v, info)

    @model_validator(mode="after")
    def _one_position(self) -> SourceSpec:
        if self.position is not None and self.sensor is not None and self.sensor.position:
            raise ValueError(f"source {self.id}: give either position or sensor.position, not both")
        return self

    @model_validator(mode="after")
    def _one_kind_of_lateness(self) -> SourceSpec:
        if self.fault == "stale" and self.link is not None:
            raise ValueError(f"source {self.id}: a stale source's lateness is its fault; no link")
        return self


class Config(BaseModel):
    """Every parameter of a dual-tracking experiment. Units are SI, angles in radians."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    scenario: str = Field("ct", description="the truth's and the filters' motion model")
    preset: Preset = "paper"
    Ts: float = Field(
        1.0,
        gt=0,
        le=LONGEST_S,
        allow_inf_nan=False,
        description="sampling period",
        json_schema_extra=unit("s"),
    )
    K: Count = Field(
        100,
        ge=1,
        le=MAX_STEPS,
        description="the primary's steps per run (given duration_s: derived from it)",
        json_schema_extra=unit("1"),
    )
    duration_s: float | None = Field(
        None,
        gt=0,
        allow_inf_nan=False,
        description="an episode's length; default: primary_phase_s + K Ts",
        json_schema_extra=unit("s"),
    )
    primary_phase_s: float = Field(
        0.0,
        ge=0,
        allow_inf_nan=False,
        description="the primary samples every Ts from primary_phase_s, in [0, Ts)",
        json_schema_extra=unit("s"),
    )
    primary_clock_offset_s: float = Field(
        0.0,
        allow_inf_nan=False,
        description="what the primary's clock reads minus the true time",
        json_schema_extra=unit("s"),
    )
    max_clock_offset_s: float = Field(
        0.0,
        ge=0,
        le=LONGEST_S,
        allow_inf_nan=False,
        description="every operator's clock is within this of the truth; a transfer's time is "
        "as uncertain (0: the paper's shared clock)",
        json_schema_extra=unit("s"),
    )
    x0: list[float] = Field(
        description="true initial state", json_schema_extra=unit("the motion model's components")
    )
    P0_diag: list[float] = Field(
        description="diagonal of the initial covariance P0",
        json_schema_extra=unit("the squares of the motion model's components"),
    )
    q1: float = Field(
        ge=0,
        allow_inf_nan=False,
        description="acceleration noise",
        json_schema_extra=unit("m^2/s^4"),
    )
    q2: float = Field(
        ge=0,
        allow_inf_nan=False,
        description="turn-rate noise",
        json_schema_extra=unit("rad^2/s^3"),
    )
    sigma_r: float = Field(
        10.0,
        gt=0,
        allow_inf_nan=False,
        description="range std, for every sensor that does not set its own",
        json_schema_extra=unit("m"),
    )
    sigma_bearing: float = Field(
        math.sqrt(10.0) * 1e-3,
        gt=0,
        allow_inf_nan=False,
        description="bearing std, for every sensor that does not set its own",
        json_schema_extra=unit("rad"),
    )
    primary_intensity: float = Field(
        4.0, gt=0, allow_inf_nan=False, description="the primary's I_w", json_schema_extra=unit("1")
    )
    primary_position: Point | None = Field(
        None, description="the sensor's position; (0, 0)", json_schema_extra=unit("m")
    )
    primary_sensor: SensorSpec | None = Field(None, description="default: the paper's radar")
    primary_detection: DetectionSpec | None = Field(
        None, description="the primary's detection process; default: no miss, no clutter"
    )
    sources: list[SourceSpec] = Field(
        default_factory=lambda: [SourceSpec.model_validate({})], min_length=1
    )
    truth: TruthMode = "fixed"
    truth_seed: Count = Field(
        0, ge=0, description="seed of the fixed truth", json_schema_extra=unit("1")
    )
    truth_file: Path | None = Field(
        None,
        description="a recorded track (CSV t,x,y or t,lat,lon) as the truth; a relative path in "
        "a config file is from that file's folder",
    )
    truth_origin: tuple[Latitude, Longitude] | None = Field(
        None,
        description="(lat, lon) of the frame's origin for a t,lat,lon truth file",
        json_schema_extra=unit("deg"),
    )
    truth_max_gap_s: float = Field(
        120.0,
        gt=0,
        allow_inf_nan=False,
        description="longest gap between a truth file's reports",
        json_schema_extra=unit("s"),
    )
    seed: Count = Field(
        0, ge=0, description="master seed of every random stream", json_schema_extra=unit("1")
    )
    particles: Count = Field(
        6000, ge=10, le=10_000_000, description="particles per PF", json_schema_extra=unit("1")
    )
    runs: Count = Field(
        100,
        ge=1,
        le=1_000_000,
        description="Monte-Carlo runs (at most a million: 100 times the paper's)",
        json_schema_extra=unit("1"),
    )
    kappa: float = Field(
        2.0,
        allow_inf_nan=False,
        description="UKF scaling parameter; n + kappa > 0",
        json_schema_extra=unit("1"),
    )
    lost_threshold_m: float = Field(
        100.0,
        gt=0,
        allow_inf_nan=False,
        description="a run whose error stays above this through its last 10 steps is lost",
        json_schema_extra=unit("m"),
    )
    gate_probability: float = Field(
        0.999,
        gt=0,
        lt=1,
        description="robust TL: probability an honest transfer passes the gate",
        json_schema_extra=unit("1"),
    )
    pda_gate_probability: float = Field(
        0.99,
        gt=0,
        lt=1,
        description="UKF/CKF in clutter: probability the target's detection is in the PDA gate",
        json_schema_extra=unit("1"),
    )
    recovery: Flag = Field(False, description="reinitialise a particle filter that lost track")
    rpf_bandwidth: float = Field(
        0.0,
        ge=0,
        lt=1,
        allow_inf_nan=False,
        description="rpf: the regularisation kernel's bandwidth h (0: off; papers/rpf/README.md)",
        json_schema_extra=unit("1"),
    )
    transfer_budget: float | None = Field(
        None,
        gt=0,
        le=1,
        allow_inf_nan=False,
        description="robust TL: at most this share of steps with a transfer",
        json_schema_extra=unit("1"),
    )
    motion_modes: list[ModeSpec] | None = Field(
        None,
        min_length=1,
        description="the filters' motion modes (the truth keeps the scenario's model); "
        "none: the scenario's single model",
    )
    mode_transition: list[list[float]] | None = Field(
        None,
        description="the modes' Markov chain: row i, the probabilities of each mode after mode i",
        json_schema_extra=unit("1"),
    )
    target_class: TargetClassName | None = Field(
        None,
        description="a kind of target (ship, aircraft) whose fitted motion_modes and "
        "mode_transition the filters take unless given; none: the scenario's single model",
    )
    filter_options: dict[str, dict[str, float]] = Field(
        default_factory=dict,
        description="per filter kind, values of the parameters it declares (e.g. "
        "{rpf = {rpf_beta = 0.5}}); a parameter that is also a top-level field is set there",
        json_schema_extra=unit("each parameter's own"),
    )

    @model_validator(mode="before")
    @classmethod
    def _fill_from_preset(cls, data: Any, info: ValidationInfo) -> Any:
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
        if not isinstance(scenario, str) or preset not in PRESET_OVERRIDES:
            return data  # the field validators name the bad value
        try:
            scenario = MOTIONS.canonical(scenario, trusted=trusted(info))
        except UnknownKindError:
            return data  # the scenario's validator names it
        values = {**preset_values(scenario, preset), **data, "scenario": scenario}
        Ts = values.get("Ts", cls.model_fields["Ts"].default)
        filled = _class_fields(values, Ts)  # a copy's model_dump holds None for each
        return {**values, **{k: v for k, v in filled.items() if values.get(k) is None}}

    @field_validator("scenario")
    @classmethod
    def _registered(cls, v: str, info: ValidationInfo) -> str:
        return _kind(MOTIONS, v, info)

    @field_validator("filter_options")
    @classmethod
    def _declared_options(
        cls, v: dict[str, dict[str, float]], info: ValidationInfo
    ) -> dict[str, dict[str, float]]:
        out = {}
        for kind, values in v.items():
            name = _kind(FILTERS, kind, info)
            declared = {p.name: p for p in FILTERS.get(name).parameters}
            for p in values:
                if p not in declared:
                    own = ", ".join(declared) or "none"
                    raise ValueError(f"{kind}: {p} is not one of its parameters ({own})")
                if p in cls.model_fields:
                    raise ValueError(f"{kind}: set {p} as the top-level field {p}")
            out[name] = {p: declared[p].check(x, f"{kind}.") for p, x in values.items()}
        return out

    @model_validator(mode="after")
    def _check_dimensions(self) -> Config:
        n = len(MOTIONS.get(self.scenario).components)
        for name in ("x0", "P0_diag"):
            values = getattr(self, name)
            if len(values) != n:
                raise ValueError(f"{name} must have {n} entries for scenario {self.scenario!r}")
            if not all(math.isfinite(v) for v in values):
                raise ValueError(f"{name} must be finite")
        if any(v <= 0 for v in self.P0_diag):
            raise ValueError("P0_diag must be positive")
        if n + self.kappa <= 0:  # the UKF's sigma points spread by sqrt(n + kappa)
            raise ValueError(
                f"kappa = {self.kappa:g}: n + kappa must be positive ({self.scenario}: n = {n})"
            )
        if (self.truth == "file") != (self.truth_file is not None):
            raise ValueError("truth 'file' needs a truth_file, and a truth_file needs truth 'file'")
        ids = [s.id for s in self.sources]
        if len(set(ids)) != len(ids):
            raise ValueError(f"sources: duplicate id in {ids}")
        if PRIMARY in ids:
            raise ValueError(f"sources: the id {PRIMARY!r} is the primary's own sensor's")
        sensor = self.primary_sensor
        if self.primary_position is not None and sensor is not None and sensor.position:
            raise ValueError("give either primary_position or primary_sensor.position, not both")
        self._check_modes()
        self._check_clocks()
        for sid in self.sensor_ids:
            try:
                detection_of(self, sid)
            except ValueError as err:
                where = "primary_detection" if sid == PRIMARY else f"sources.{sid}.detection"
                raise ValueError(f"{where}: {err}") from None
        return self

    def _check_clocks(self) -> None:
        own = [("primary", "Ts", self.Ts, self.primary_phase_s, self.primary_clock_offset_s)]
        own += [
            (f"sources.{s.id}", "period_s", s.period_s or self.Ts, s.phase_s, s.clock_offset_s)
            for s in self.sources
        ]
        for who, period, T, phase, offset in own:
            where = "primary_" if who == "primary" else f"{who}."
            if phase >= T:
                raise ValueError(f"{where}phase_s = {phase:g} s is not in [0, {period} = {T:g} s)")
            if abs(offset) > self.max_clock_offset_s:
                raise ValueError(
                    f"{where}clock_offset_s = {offset:g} s is beyond max_clock_offset_s = "
                    f"{self.max_clock_offset_s:g} s"
                )
        if self.duration_s is not None:
            K = Clock(us(self.Ts), us(self.primary_phase_s)).count(us(self.duration_s))
            if K < 1:
                raise ValueError(f"duration_s = {self.duration_s:g} s holds no primary sample")
            if "K" in self.model_fields_set and self.K != K:
                raise ValueError(f"give duration_s or K, not both: duration_s holds K = {K}")
            if K > MAX_STEPS:
                raise ValueError(
                    f"duration_s = {self.duration_s:g} s holds K = {K} steps of the primary, "
                    f"at most {MAX_STEPS}"
                )
            object.__setattr__(self, "K", K)
        timeline = self.timeline
        grid = timeline.grid_us  # refuses periods and phases with no common grid
        if timeline.ticks > MAX_TICKS:  # the truth holds a state per tick
            raise ValueError(
                f"the sample times fall on a grid of {grid / 1000:g} ms: {timeline.ticks} of its "
                f"steps in the episode, at most {MAX_TICKS} (fewer steps, or periods and phases "
                "on a coarser grid)"
            )
        if self.truth == "file" and grid != us(self.Ts):
            raise ValueError("a truth file is resampled at Ts: every period and phase must be Ts's")

    @property
    def timeline(self) -> Timeline:
        """When each operator samples, and what its clock reads then."""
        clocks = {
            PRIMARY: Clock(us(self.Ts), us(self.primary_phase_s), us(self.primary_clock_offset_s))
        }
        for s in self.sources:
            clocks[s.id] = Clock(us(s.period_s or self.Ts), us(s.phase_s), us(s.clock_offset_s))
        duration = self.duration_s
        return Timeline(
            clocks,
            us(duration) if duration is not None else clocks[PRIMARY].sample(self.K),
            PRIMARY,
        )

    def _check_modes(self) -> None:
        modes, Pi = self.motion_modes, self.mode_transition
        if self.target_class is not None and self.scenario != "ct":
            raise ValueError(
                f"target_class {self.target_class}: its modes share the coordinated turn's "
                "state: use scenario ct"
            )
        if modes is None:
            if Pi is not None:
                raise ValueError("mode_transition needs motion_modes")
            return
        if self.scenario != "ct":
            raise ValueError("motion_modes share the coordinated turn's state: use scenario ct")
        M = len(modes)
        if Pi is None:
            if M > 1:
                raise ValueError(f"motion_modes: give mode_transition, a {M}x{M} matrix")
            return
        ok = len(Pi) == M and all(len(r) == M for r in Pi)
        if not ok or any(not (math.isfinite(p) and p >= 0) for r in Pi for p in r):
            raise ValueError(f"mode_transition must be {M}x{M}, of probabilities")
        if any(abs(sum(r) - 1.0) > 1e-9 for r in Pi):
            raise ValueError("mode_transition: each row must sum to 1")

    def filter_parameters(self, kind: str) -> dict[str, float]:
        """The values of every parameter filter ``kind`` declares: a top-level field of that
        name, else :attr:`filter_options`, else the declared default."""
        out = {}
        for p in FILTERS.get(kind).parameters:
            given = self.filter_options.get(kind, {}).get(p.name)
            if given is None and p.name in type(self).model_fields:
                given = getattr(self, p.name)
            value = p.default if given is None else given
            if value is None:
                raise ConfigError(f"filter kind {kind} needs {p.name} [{p.unit}]: {p.doc}")
            out[p.name] = float(value)
        return out

    @property
    def n_x(self) -> int:
        return len(self.x0)

    @property
    def sensor_ids(self) -> list[str]:
        """The primary's sensor id, then every source's."""
        return [PRIMARY, *(s.id for s in self.sources)]

    @property
    def source(self) -> SourceSpec:
        """The first source: the paper's single source operator."""
        return self.sources[0]

    def with_(self, *, trusted_changes: bool = False, **changes: Any) -> Config:
        """A validated copy with some fields changed; raises :class:`ConfigError`.

        Changing the scenario or preset re-fills every field that still has the old preset's value.
        ``trusted_changes``: the changes are the user's own (:func:`make_config`).
        """
        data = self.model_dump()
        if {"scenario", "preset"} & changes.keys():
            old = preset_values(self.scenario, self.preset)
            data = {k: v for k, v in data.items() if k not in old or old[k] != v}
        if self.target_class is not None and {"Ts", "target_class"} & changes.keys():
            filled = TARGET_CLASSES[self.target_class].fields(self.Ts)
            modes = [ModeSpec(**m) for m in filled["motion_modes"]]
            if self.motion_modes == modes and self.mode_transition == filled["mode_transition"]:
                data = {k: v for k, v in data.items() if k not in filled}  # the class fills anew
        return make_config(data, trusted=trusted_changes, **changes)

    def with_source_intensity(self, intensity: float) -> Config:
        """The same experiment with the (first) source's noise intensity changed."""
        first = {**self.sources[0].model_dump(), "intensity": intensity}
        return self.with_(sources=[first, *self.sources[1:]])


class ConfigError(ValueError):
    """A configuration was refused; the message names the offending field."""


def describe_validation_error(err: ValidationError) -> str:
    """One line per problem, each starting with the field's dotted path."""
    lines = []
    errors = err.errors()
    unknown_base = any(
        (e["loc"] == ("scenario",) and e["type"] == "unknown_kind") or e["loc"] == ("preset",)
        for e in errors
    )
    if unknown_base:  # no defaults without a scenario and a preset: say only which is unknown
        errors = [e for e in errors if e["type"] != "missing"]
    for e in errors:
        loc = ".".join(str(p) for p in e["loc"]) or "(config)"
        lines.append(f"{loc}: {e['msg']}")
    return "; ".join(lines)


def make_config(
    data: dict[str, Any] | None = None, *, trusted: bool = False, **overrides: Any
) -> Config:
    """Build a config from a mapping plus keyword overrides, raising :class:`ConfigError`.

    ``trusted``: the mapping is the user's own (a file, the command line), so its kinds may be
    named by import path and installed plugins are loaded (:mod:`tltrack.declare`).
    """
    merged = {**(data or {}), **{k: v for k, v in overrides.items() if v is not None}}
    try:
        return Config.model_validate(merged, context={"trusted": trusted})
    except ValidationError as err:
        raise ConfigError(describe_validation_error(err)) from None


def position_of(cfg: Config, sensor_id: str = PRIMARY) -> tuple[float, float]:
    """Where an operator's sensor sits: its sensor's position, else the operator's, else the
    origin."""
    if sensor_id == PRIMARY:
        spec, position = cfg.primary_sensor, cfg.primary_position
    else:
        src = next(s for s in cfg.sources if s.id == sensor_id)
        spec, position = src.sensor, src.position
    at = (spec.position if spec is not None else None) or position or (0.0, 0.0)
    return (float(at[0]), float(at[1]))


def detection_of(cfg: Config, sensor_id: str = PRIMARY) -> Detection:
    """An operator's detection process, checked against its sensor's components."""
    if sensor_id == PRIMARY:
        spec, given = cfg.primary_sensor, cfg.primary_detection
    else:
        src = next(s for s in cfg.sources if s.id == sensor_id)
        spec, given = src.sensor, src.detection
    components = tuple(SENSORS.get(spec.kind if spec is not None else "range-bearing").components)
    d = given or DetectionSpec.model_validate({})
    return Detection(components, d.pd, d.clutter_rate, dict(d.fov))
