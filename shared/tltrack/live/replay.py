"""Recorded scans from a CSV file, so that real sensor data can drive the live services.

The file is a scan file (:mod:`tltrack.engine.scan_file`: its schema, its checks): each row one
detection, any number per step and sensor, a step with no row an empty scan. For example::

    k,sensor,range_m,bearing_rad,range_rate_mps,x_m,y_m
    1,primary,,0.7861,,,
    1,s1,1436.9,0.7850,,,

K is the file's last step. A sensor the configuration says detects at every step with no false
alarm (the paper's) must have exactly one row per step; a scan of more than 4096 detections refuses
the file here (offline, ``tltrack track`` skips it instead). ``tltrack track --scans`` runs the
same files offline.

The measurement components (each sensor kind's ``components``): ``range_m`` (m, > 0),
``bearing_rad`` (rad, atan2 convention from the sensor's position, in [-pi, pi]),
``range_rate_mps`` (m/s), ``x_m`` and ``y_m`` (m). A row fills the columns of its sensor's kind
and leaves the others empty.

A bad file is refused as a whole, with the line number, before anything is published.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from tltrack.engine.scan_file import ScanFileError, check_fit, read_scans
from tltrack.engine.setup import Setup


class ReplayError(ValueError):
    """The CSV does not follow the schema; the message says where."""


def load(
    path: Path, setup: Setup, sensor_ids: Sequence[str]
) -> list[dict[str, NDArray[np.float64]]]:
    """Per step k = 1..K, each sensor's detections (M_k, n_z), validated against the schema
    above and the sensors' detection processes."""
    try:
        scans = read_scans(path, {sid: setup.sensor(sid) for sid in sensor_ids})
        check_fit(setup, scans)
    except (ScanFileError, ValueError) as err:
        raise ReplayError(str(err)) from None
    if scans.refused:
        raise ReplayError(f"{scans.refused[0]}: the live replay refuses the file")
    return [
        {sid: d for sid in sensor_ids if (d := scans.scan(sid, k)) is not None}
        for k in range(1, scans.K + 1)
    ]
