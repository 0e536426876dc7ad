"""State-space models: motion (f and Q_v) and measurement (h and Q_w), behind two Protocols.

- :mod:`~tltrack.models.base`: the :class:`MotionModel` and :class:`MeasurementModel` Protocols
  and the state :class:`Layout`;
- motion: :mod:`~tltrack.models.constant_velocity`, :mod:`~tltrack.models.coordinated_turn`;
- sensors: :mod:`~tltrack.models.range_bearing`, on :mod:`~tltrack.models.gaussian_sensor`;
- :mod:`~tltrack.models.observation`: a Gaussian statement about h(x_k), raw or transferred;
- :mod:`~tltrack.models.from_config`: the models a configuration describes.
"""

from tltrack.models.angles import wrap_angle
from tltrack.models.base import Layout, MeasurementModel, MotionModel, PositionFix
from tltrack.models.constant_velocity import ConstantVelocity
from tltrack.models.coordinated_turn import CoordinatedTurn
from tltrack.models.from_config import PRIMARY, intensity, motion_model, sensor
from tltrack.models.observation import Observation
from tltrack.models.range_bearing import RangeBearing

__all__ = [
    "PRIMARY",
    "ConstantVelocity",
    "CoordinatedTurn",
    "Layout",
    "MeasurementModel",
    "MotionModel",
    "Observation",
    "PositionFix",
    "RangeBearing",
    "intensity",
    "motion_model",
    "sensor",
    "wrap_angle",
]
