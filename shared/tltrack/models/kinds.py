"""The registries of sensor kinds and motion models (:mod:`tltrack.declare`).

A sensor class declares ``kind``, ``components`` (each name ending in its unit) and
``parameters``, and builds itself with ``build(params, layout, position)``; a motion model
declares ``kind``, ``components``, ``parameters`` (those of ``q1``, ``q2`` it reads) and
``defaults`` (x0, P0_diag and the noise of its scenario), and builds itself with
``build(T, params)``. Plugins register through the entry-point groups ``tltrack.sensors`` and
``tltrack.motion``, or by import path in the user's own config.
"""

from __future__ import annotations

from typing import Any

from tltrack.declare import Parameter, Registry
from tltrack.models.bearing import Bearing
from tltrack.models.constant_acceleration import ConstantAcceleration
from tltrack.models.constant_velocity import ConstantVelocity
from tltrack.models.coordinated_turn import CoordinatedTurn
from tltrack.models.position import Position
from tltrack.models.range_bearing import RangeBearing
from tltrack.models.range_bearing_doppler import RangeBearingDoppler

#: a component's name ends in its unit, e.g. ``range_m``, ``bearing_rad``, ``vx_mps``
UNIT_SUFFIXES = ("_m", "_rad", "_mps", "_mps2", "_radps", "_s", "_1")


def _declares(cls: Any, names: tuple[str, ...], concept: str) -> None:
    missing = [n for n in names if not hasattr(cls, n)]
    if missing:
        raise ValueError(f"{cls!r} is not a {concept}: it does not declare {', '.join(missing)}")
    for c in cls.components:
        if not c.endswith(UNIT_SUFFIXES):
            raise ValueError(f"{cls.kind}: component {c!r} must end in its unit {UNIT_SUFFIXES}")
    for p in cls.parameters:
        if not isinstance(p, Parameter):
            raise ValueError(f"{cls.kind}: parameter {p!r} is not a tltrack.declare.Parameter")


def _check_sensor(cls: Any) -> None:
    _declares(cls, ("kind", "components", "parameters", "build"), "sensor")


def _check_motion(cls: Any) -> None:
    _declares(cls, ("kind", "components", "parameters", "defaults", "build"), "motion model")
    for field in ("x0", "P0_diag"):
        if len(cls.defaults.get(field, ())) != len(cls.components):
            raise ValueError(f"{cls.kind}: defaults[{field!r}] needs one entry per component")


#: sensor kind -> its class
SENSORS: Registry[Any] = Registry(
    "sensor",
    "tltrack.sensors",
    [RangeBearing, Bearing, Position, RangeBearingDoppler],
    name_of=lambda cls: cls.kind,
    check=_check_sensor,
)

#: motion model kind -> its class
MOTIONS: Registry[Any] = Registry(
    "motion model",
    "tltrack.motion",
    [ConstantVelocity, CoordinatedTurn, ConstantAcceleration],
    name_of=lambda cls: cls.kind,
    check=_check_motion,
)
