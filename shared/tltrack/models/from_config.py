"""The models a :class:`~tltrack.config.Config` describes: its motion model and each sensor."""

from __future__ import annotations

from tltrack.config import Config
from tltrack.models.base import MeasurementModel, MotionModel
from tltrack.models.constant_velocity import ConstantVelocity
from tltrack.models.coordinated_turn import CoordinatedTurn
from tltrack.models.range_bearing import RangeBearing

#: the primary operator's sensor id; a source's is its own id
PRIMARY = "primary"


def motion_model(cfg: Config) -> MotionModel:
    """The scenario's motion model."""
    if cfg.scenario == "cv":
        return ConstantVelocity(T=cfg.Ts, q=cfg.q1)
    return CoordinatedTurn(T=cfg.Ts, q1=cfg.q1, q2=cfg.q2)


def sensor(cfg: Config, sensor_id: str = PRIMARY) -> MeasurementModel:
    """The primary's sensor, or that of the source with id ``sensor_id``."""
    pos = cfg.primary_position
    if sensor_id != PRIMARY:
        pos = next(s.position for s in cfg.sources if s.id == sensor_id)
    return RangeBearing(cfg.sigma_r, cfg.sigma_bearing, motion_model(cfg).layout, pos)


def intensity(cfg: Config, sensor_id: str = PRIMARY) -> float:
    """The noise intensity I_w of the primary, or of the source with id ``sensor_id``."""
    if sensor_id == PRIMARY:
        return cfg.primary_intensity
    return next(s.intensity for s in cfg.sources if s.id == sensor_id)
