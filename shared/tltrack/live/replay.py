"""Recorded measurements from a CSV file, so that real sensor data can drive the live services.

The file is a scan file (:mod:`tltrack.engine.scan_file`: its schema, its checks), with one
detection per step and sensor: a live measurement message carries one z_k. For example::

    k,sensor,range_m,bearing_rad,range_rate_mps,x_m,y_m
    1,primary,,0.7861,,,
    1,s1,1436.9,0.7850,,,

K is the file's last step. A step with no row, or with two rows, for a sensor is refused, naming
the lines: two rows of one step used to keep the second without a word. ``tltrack track --scans``
runs the same files offline, with any number of rows per step.

The measurement components (each sensor kind's ``components``): ``range_m`` (m, > 0),
``bearing_rad`` (rad, atan2 convention from the sensor's position, in [-pi, pi]),
``range_rate_mps`` (m/s), ``x_m`` and ``y_m`` (m). A row fills the columns of its sensor's kind
and leaves the others empty.

A bad file is refused as a whole, with the line number, before anything is published.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from tltrack.engine.scan_file import ScanFileError, read_scans
from tltrack.models.base import MeasurementModel


class ReplayError(ValueError):
    """The CSV does not follow the schema; the message says where."""


def load(path: Path, sensors: dict[str, MeasurementModel]) -> dict[str, NDArray[np.float64]]:
    """sensor id -> (K, n_z) measurements, validated against the schema above."""
    try:
        scans = read_scans(path, sensors)
    except ScanFileError as err:
        raise ReplayError(str(err)) from None
    if scans.refused:
        raise ReplayError(scans.refused[0])
    out = {}
    for sid in sensors:
        counts = scans.counts(sid)
        if gaps := [int(k) + 1 for k in np.flatnonzero(counts == 0)]:
            raise ReplayError(f"{path}: sensor {sid!r} has no row for step(s) {gaps[:5]}")
        if many := [int(k) + 1 for k in np.flatnonzero(counts > 1)]:
            k = many[0]
            lines = ", ".join(map(str, scans.lines[sid, k]))
            raise ReplayError(
                f"{path}: sensor {sid!r} has {counts[k - 1]} rows for step {k} (lines {lines}): "
                "the live replay takes one per step (tltrack track --scans takes any number)"
            )
        out[sid] = np.concatenate([d for d in scans.detections[sid] if d is not None])
    return out
