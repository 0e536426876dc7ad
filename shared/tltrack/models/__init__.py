"""State-space models: motion (what f and Q_v are) and measurement (what h and Q_w are)."""

from tltrack.models.measurement import RangeBearing, wrap_angle
from tltrack.models.motion import ConstantVelocity, CoordinatedTurn, MotionModel, motion_model
from tltrack.models.observation import Observation

__all__ = [
    "ConstantVelocity",
    "CoordinatedTurn",
    "MotionModel",
    "Observation",
    "RangeBearing",
    "motion_model",
    "wrap_angle",
]
