"""State-space models: motion (f and Q_v) and measurement (h and Q_w), behind two Protocols.

- :mod:`~tltrack.models.base`: the :class:`MotionModel` and :class:`MeasurementModel` Protocols
  and the state :class:`Layout`;
- motion: :mod:`~tltrack.models.constant_velocity`, :mod:`~tltrack.models.coordinated_turn`,
  :mod:`~tltrack.models.constant_acceleration`;
- sensors, on :mod:`~tltrack.models.gaussian_sensor`: :mod:`~tltrack.models.range_bearing`,
  :mod:`~tltrack.models.bearing`, :mod:`~tltrack.models.position`,
  :mod:`~tltrack.models.range_bearing_doppler`;
- :mod:`~tltrack.models.kinds`: the registries of sensor kinds and motion models;
- :mod:`~tltrack.models.observation`: a Gaussian statement about h(x_k), raw or transferred.
"""

from tltrack.models.angles import wrap_angle
from tltrack.models.base import Layout, MeasurementModel, MotionModel, PositionFix
from tltrack.models.bearing import Bearing
from tltrack.models.constant_acceleration import ConstantAcceleration
from tltrack.models.constant_velocity import ConstantVelocity
from tltrack.models.coordinated_turn import CoordinatedTurn
from tltrack.models.gaussian_sensor import GaussianSensor
from tltrack.models.kinds import MOTIONS, SENSORS
from tltrack.models.observation import Observation
from tltrack.models.position import Position
from tltrack.models.range_bearing import RangeBearing
from tltrack.models.range_bearing_doppler import RangeBearingDoppler

__all__ = [
    "MOTIONS",
    "SENSORS",
    "Bearing",
    "ConstantAcceleration",
    "ConstantVelocity",
    "CoordinatedTurn",
    "GaussianSensor",
    "Layout",
    "MeasurementModel",
    "MotionModel",
    "Observation",
    "Position",
    "PositionFix",
    "RangeBearing",
    "RangeBearingDoppler",
    "wrap_angle",
]
