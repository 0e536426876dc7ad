"""Detections as points on the map: what a plan view (the dashboard, ``tltrack track``'s
picture) draws of a scan.

A detection is in its sensor's coordinates (range and bearing, say). Only a sensor whose single
measurement fixes a position (:class:`~tltrack.models.base.PositionFix`) can be drawn as a point;
a bearing alone is a ray, and is not drawn.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tltrack.engine.scenario import Run
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.models.base import MeasurementModel, PositionFix

Array = NDArray[np.float64]


def plan(sensor: MeasurementModel, z: Array) -> Array | None:
    """The detections z (M, n_z) as positions (M, 2), or None for a sensor that fixes none."""
    if not isinstance(sensor, PositionFix):
        return None
    z = np.asarray(z, dtype=float).reshape(-1, sensor.n_z)
    if not len(z):
        return np.zeros((0, 2))
    no_noise = np.zeros((len(z), sensor.n_z, sensor.n_z))
    return sensor.to_position(z.T, no_noise)[0].T


def primary_scan(setup: Setup, run: Run, k: int) -> tuple[Array, NDArray[np.bool_]] | None:
    """The primary's scan at step k as the simulation drew it: positions (M, 2) and which are
    false alarms (ground truth, the referee's to know), or None when its sensor fixes no
    position."""
    xy = plan(setup.sensor(PRIMARY), run.detections(PRIMARY, k))
    if xy is None:
        return None
    drawn = run.scans.get(PRIMARY)
    clutter = drawn.is_clutter[k - 1] if drawn else np.zeros(len(xy), bool)
    return xy, clutter
