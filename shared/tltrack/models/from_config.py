"""The models a :class:`~tltrack.config.Config` describes: its motion model and each sensor.

A sensor is described by a :class:`~tltrack.config.SensorSpec` (kind, position, noise
parameters): in the config for each operator, and on the wire in every transfer, so that a primary
can use a source's transfer without being configured for that source's sensor.
"""

from __future__ import annotations

from collections.abc import Callable

from tltrack.config import SENSOR_PARAMETERS, Config, SensorSpec
from tltrack.models.base import Layout, MeasurementModel, MotionModel
from tltrack.models.bearing import Bearing
from tltrack.models.constant_acceleration import ConstantAcceleration
from tltrack.models.constant_velocity import ConstantVelocity
from tltrack.models.coordinated_turn import CoordinatedTurn
from tltrack.models.position import Position
from tltrack.models.range_bearing import RangeBearing
from tltrack.models.range_bearing_doppler import RangeBearingDoppler

#: the primary operator's sensor id; a source's is its own id
PRIMARY = "primary"

Params = dict[str, float]

#: sensor kind -> its class, built from (parameters, layout, position)
SENSORS: dict[str, Callable[[Params, Layout, tuple[float, float]], MeasurementModel]] = {
    "range-bearing": lambda p, layout, at: RangeBearing(
        p["sigma_r"], p["sigma_bearing"], layout, at
    ),
    "bearing": lambda p, layout, at: Bearing(p["sigma_bearing"], layout, at),
    "position": lambda p, layout, at: Position(layout, at, sigma_pos=p["sigma_pos"]),
    "range-bearing-doppler": lambda p, layout, at: RangeBearingDoppler(
        p["sigma_r"], p["sigma_bearing"], layout, at, sigma_rr=p["sigma_rr"]
    ),
}


def motion_model(cfg: Config) -> MotionModel:
    """The scenario's motion model."""
    if cfg.scenario == "cv":
        return ConstantVelocity(T=cfg.Ts, q=cfg.q1)
    if cfg.scenario == "ca":
        return ConstantAcceleration(T=cfg.Ts, q=cfg.q1)
    return CoordinatedTurn(T=cfg.Ts, q1=cfg.q1, q2=cfg.q2)


def sensor_spec(cfg: Config, sensor_id: str = PRIMARY) -> SensorSpec:
    """The full description of an operator's sensor: every parameter and its position filled in
    (a parameter left out takes its default, the flat fields ``sigma_r`` and ``sigma_bearing``
    included)."""
    if sensor_id == PRIMARY:
        spec, position = cfg.primary_sensor, cfg.primary_position
    else:
        src = next(s for s in cfg.sources if s.id == sensor_id)
        spec, position = src.sensor, src.position
    spec = spec or SensorSpec()
    flat = {"sigma_r": cfg.sigma_r, "sigma_bearing": cfg.sigma_bearing}
    params = {
        name: getattr(spec, name) or default or flat[name]
        for name, default in SENSOR_PARAMETERS[spec.kind].items()
    }
    at = spec.position or position or (0.0, 0.0)
    return SensorSpec(kind=spec.kind, position=at, **params)


def from_spec(spec: SensorSpec, layout: Layout) -> MeasurementModel:
    """The sensor a full :func:`sensor_spec` describes, reading states of ``layout``."""
    params = {name: float(getattr(spec, name)) for name in SENSOR_PARAMETERS[spec.kind]}
    return SENSORS[spec.kind](params, layout, spec.position or (0.0, 0.0))


def sensor(cfg: Config, sensor_id: str = PRIMARY) -> MeasurementModel:
    """The primary's sensor, or that of the source with id ``sensor_id``."""
    return from_spec(sensor_spec(cfg, sensor_id), motion_model(cfg).layout)


def intensity(cfg: Config, sensor_id: str = PRIMARY) -> float:
    """The noise intensity I_w of the primary, or of the source with id ``sensor_id``."""
    if sensor_id == PRIMARY:
        return cfg.primary_intensity
    return next(s.intensity for s in cfg.sources if s.id == sensor_id)
