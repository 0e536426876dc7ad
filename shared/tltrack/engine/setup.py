"""The models a :class:`~tltrack.config.Config` describes, built once: its :class:`Setup`.

An experiment's batch, a live episode, a study or a test builds one :class:`Setup` from its
config and reads the motion model and every operator's sensor (with its Q_w) from it, instead of
rebuilding them from the config wherever they are needed.

A sensor is described by a :class:`~tltrack.config.SensorSpec` (kind, position, parameters): in
the config for each operator, and on the wire in every transfer, so that a primary can use a
source's transfer without being configured for that source's sensor (:func:`from_spec`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from numpy.typing import NDArray

from tltrack.config import PRIMARY, Config, SensorSpec, detection_of, position_of
from tltrack.config.timeline import US, Timeline
from tltrack.engine.pcrlb import pcrlb
from tltrack.models.base import Layout, MeasurementModel, MotionModel
from tltrack.models.coordinated_turn import CoordinatedTurn
from tltrack.models.detection import Detection
from tltrack.models.kinds import MOTIONS, SENSORS
from tltrack.models.modes import MotionModes, Straight
from tltrack.models.observation import Observation
from tltrack.models.scan import Scan, Statement

Array = NDArray[np.float64]

__all__ = ["PRIMARY", "OwnSensor", "Setup", "from_spec", "intensity", "motion_model", "sensor_spec"]


def motion_model(cfg: Config, period: float | None = None) -> MotionModel:
    """The scenario's motion model over ``period`` (default Ts), with the noise parameters it
    declares."""
    cls = MOTIONS.get(cfg.scenario)
    T = cfg.Ts if period is None else period
    return cls.build(T, {p.name: float(getattr(cfg, p.name)) for p in cls.parameters})


def motion_modes(cfg: Config, period: float | None = None) -> MotionModes | None:
    """The filters' modes over ``period`` (default Ts), each in the coordinated turn's state,
    with their Markov chain; the modes start equally likely."""
    if cfg.motion_modes is None:
        return None
    T = cfg.Ts if period is None else period
    models: list[MotionModel] = [
        Straight(T, m.q1) if m.kind == "cv" else CoordinatedTurn(T, m.q1, m.q2)
        for m in cfg.motion_modes
    ]
    kinds = [m.kind for m in cfg.motion_modes]
    names = tuple(
        k if kinds.count(k) == 1 else f"{k}{kinds[: i + 1].count(k)}" for i, k in enumerate(kinds)
    )
    M = len(models)
    Pi = np.asarray(cfg.mode_transition if cfg.mode_transition is not None else np.eye(M))
    return MotionModes(names, tuple(models), Pi, np.full(M, 1.0 / M))


def sensor_spec(cfg: Config, sensor_id: str = PRIMARY) -> SensorSpec:
    """The full description of an operator's sensor: every parameter and its position filled in
    (a parameter left out takes its default: an inherited one, the config's top-level field of
    its name, as the flat ``sigma_r`` and ``sigma_bearing``)."""
    if sensor_id == PRIMARY:
        spec = cfg.primary_sensor
    else:
        spec = next(s for s in cfg.sources if s.id == sensor_id).sensor
    spec = spec or SensorSpec.model_validate({})
    given = spec.params
    params = {}
    for p in spec.declared:
        value = given.get(p.name) or (getattr(cfg, p.name) if p.inherit else p.default)
        if value is None:
            raise ValueError(f"{sensor_id}: a {spec.kind} sensor needs {p.name} [{p.unit}]")
        params[p.name] = float(value)
    return SensorSpec(kind=spec.kind, position=position_of(cfg, sensor_id), **params)


@lru_cache(maxsize=64)
def from_spec(spec: SensorSpec, layout: Layout) -> MeasurementModel:
    """The sensor a full :func:`sensor_spec` describes, reading states of ``layout``."""
    return SENSORS.get(spec.kind).build(spec.params, layout, spec.position or (0.0, 0.0))


def intensity(cfg: Config, sensor_id: str = PRIMARY) -> float:
    """The noise intensity I_w of the primary, or of the source with id ``sensor_id``."""
    if sensor_id == PRIMARY:
        return cfg.primary_intensity
    return next(s.intensity for s in cfg.sources if s.id == sensor_id)


@dataclass(frozen=True)
class OwnSensor:
    """An operator's sensor, its full description, its Q_w and its detection process: what
    turns its z into an :class:`~tltrack.models.observation.Observation`, or its scans into a
    :class:`~tltrack.models.scan.Scan`."""

    model: MeasurementModel
    spec: SensorSpec
    R: Array
    detection: Detection
    gate_probability: float

    def observe(self, z: Array) -> Observation:
        """z_k (n_z,) or a batch's (n_z, B) with the sensor's own Q_w."""
        return Observation.broadcast(self.model, z, self.R)

    def scan(self, scans: list[Array]) -> Scan:
        """Each run's detections at k, (M_b, n_z), as one scan of the batch."""
        return Scan.pack(self.model, scans, self.R, self.detection, self.gate_probability)

    def report(self, detections: Array) -> Statement:
        """What the filters of one run take of the sensor's report at k, (M, n_z): its one
        detection as z_k for the paper's sensor (which reports exactly one), else the scan."""
        if self.detection.trivial:
            return self.observe(detections[0])
        return self.scan([detections])

    def statement(self, z: Array, scans: list[Array] | None) -> Statement:
        """What the filters take at k: the scans when the sensor misses or has false alarms,
        else z_k (n_z, B) itself, as the paper's filters take it."""
        return self.observe(z) if scans is None else self.scan(scans)


@dataclass(frozen=True)
class Setup:
    """A config's motion model and each operator's sensor, built once.

    ``period``: the step of the motion models (default Ts); an operator that samples at its own
    period builds its filters from :meth:`operator`'s setup.
    """

    cfg: Config
    period: float | None = None

    @cached_property
    def motion(self) -> MotionModel:
        """The scenario's model: the truth's, and the filters' unless they have modes."""
        return motion_model(self.cfg, self.period)

    @cached_property
    def timeline(self) -> Timeline:
        """The config's timeline, built once (``Config.timeline`` builds one at each read)."""
        return self.cfg.timeline

    @cached_property
    def modes(self) -> MotionModes | None:
        """The filters' motion modes (config ``motion_modes``), or None: the scenario's model."""
        return motion_modes(self.cfg, self.period)

    def operator(self, sensor_id: str) -> Setup:
        """This setup as operator ``sensor_id``'s filters step: over its own period."""
        period = self.timeline.clocks[sensor_id].period_us / US
        return self if period == (self.period or self.cfg.Ts) else Setup(self.cfg, period)

    def start(self, sensor_id: str, x0_hat: Array) -> tuple[Array, Array]:
        """Operator ``sensor_id``'s prior (x0_hat (n_x, B), P0) at its step 0, one period before
        its first sample: the initial estimate at t = 0 carried over its phase (mean through f,
        covariance F P0 F' + Q with F at the config's x0); at phase 0, (x0_hat, P0) itself."""
        phase = self.timeline.clocks[sensor_id].phase_us / US
        if phase == 0:
            return x0_hat, self.P0
        model = self.motion.with_period(phase)
        F = model.F(np.asarray(self.cfg.x0, dtype=float))
        return model.f(x0_hat), F @ self.P0 @ F.T + model.Q

    @property
    def layout(self) -> Layout:
        return self.motion.layout

    @property
    def source_ids(self) -> list[str]:
        return [s.id for s in self.cfg.sources]

    @property
    def sensor_ids(self) -> list[str]:
        """The primary's, then every source's."""
        return [PRIMARY, *self.source_ids]

    @cached_property
    def sensors(self) -> dict[str, OwnSensor]:
        out = {}
        for sid in self.sensor_ids:
            spec = sensor_spec(self.cfg, sid)
            model = from_spec(spec, self.layout)
            R = model.R(intensity(self.cfg, sid))
            detection = detection_of(self.cfg, sid)
            out[sid] = OwnSensor(model, spec, R, detection, self.cfg.pda_gate_probability)
        return out

    def sensor(self, sensor_id: str = PRIMARY) -> MeasurementModel:
        return self.sensors[sensor_id].model

    def intensity(self, sensor_id: str = PRIMARY) -> float:
        return intensity(self.cfg, sensor_id)

    @cached_property
    def P0(self) -> Array:
        return np.diag(self.cfg.P0_diag)

    def pcrlb(self, sensor_ids: list[str], truths: Array) -> Array:
        """The position PCRLB per k of a filter given ``sensor_ids``' measurements, averaged over
        the true trajectories ``truths`` (R, K + 1, n_x) (:mod:`tltrack.engine.pcrlb`)."""
        pairs = [(self.sensor(i), self.sensors[i].R) for i in sensor_ids]
        return pcrlb(self.motion, pairs, truths, self.P0)
