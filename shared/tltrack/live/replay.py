"""Recorded measurements from a CSV file, so that real sensor data can drive the trackers.

Schema (header row required; extra columns are ignored)::

    k,sensor,range_m,bearing_rad,range_rate_mps,x_m,y_m
    1,primary,,0.7861,,,
    1,s1,1436.9,0.7850,,,

- ``k``: step index 1..K; every step must have a row for the primary and for each source;
- ``sensor``: ``primary`` or a source id of the configuration;
- one column per measurement component, named after it (each sensor kind's ``components``:
  ``range_m`` (m, > 0), ``bearing_rad`` (rad, atan2 convention from the sensor's position, in
  [-pi, pi]), ``range_rate_mps`` (m/s), ``x_m`` and ``y_m`` (m)). A row fills the columns of its
  sensor's kind and leaves the others empty.

A bad file is refused as a whole, with the line number, before anything is published.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from tltrack.models.base import MeasurementModel

REQUIRED = ("k", "sensor")
#: what a component's value must satisfy, beyond being a finite number
CHECKS = {
    "range_m": (lambda v: v > 0, "finite and > 0"),
    "bearing_rad": (lambda v: abs(v) <= math.pi, "finite and in [-pi, pi]"),
}


class ReplayError(ValueError):
    """The CSV does not follow the schema; the message says where."""


def load(path: Path, sensors: dict[str, MeasurementModel]) -> dict[str, NDArray[np.float64]]:
    """sensor id -> (K, n_z) measurements, validated against the schema above."""
    try:
        with open(path, newline="") as fh:
            reader = csv.DictReader(fh)
            header = reader.fieldnames or []
            needed = {c for s in sensors.values() for c in s.components}
            missing = [c for c in (*REQUIRED, *sorted(needed)) if c not in header]
            if missing:
                raise ReplayError(f"{path}: missing column(s) {', '.join(missing)}")
            rows: dict[tuple[int, str], list[float]] = {}
            for line, row in enumerate(reader, start=2):
                k, sid = _key(path, line, row, sensors)
                rows[k, sid] = _values(path, line, row, sensors[sid])
    except OSError as err:
        raise ReplayError(f"cannot read {path}: {err.strerror}") from None
    K = max((k for k, _ in rows), default=0)
    if K == 0:
        raise ReplayError(f"{path}: no measurements")
    out = {}
    for s in sensors:
        gaps = [k for k in range(1, K + 1) if (k, s) not in rows]
        if gaps:
            raise ReplayError(f"{path}: sensor {s!r} has no row for step(s) {gaps[:5]}")
        out[s] = np.array([rows[k, s] for k in range(1, K + 1)])
    return out


def _key(
    path: Path, line: int, row: dict[str, str], sensors: dict[str, MeasurementModel]
) -> tuple[int, str]:
    try:
        k = int(row["k"])
    except (TypeError, ValueError):
        raise ReplayError(f"{path}:{line}: k must be an integer") from None
    if k < 1:
        raise ReplayError(f"{path}:{line}: need k >= 1")
    if row["sensor"] not in sensors:
        known = list(sensors)
        raise ReplayError(f"{path}:{line}: unknown sensor {row['sensor']!r} (known: {known})")
    return k, row["sensor"]


def _values(path: Path, line: int, row: dict[str, str], sensor: MeasurementModel) -> list[float]:
    """The row's measurement of ``sensor``: its kind's columns, each a finite number."""
    values = []
    for name in sensor.components:
        try:
            v = float(row[name])
        except (TypeError, ValueError):
            raise ReplayError(
                f"{path}:{line}: a {sensor.kind} sensor needs {name} as a number"
            ) from None
        ok, want = CHECKS.get(name, (lambda v: True, "finite"))
        if not (math.isfinite(v) and ok(v)):
            raise ReplayError(f"{path}:{line}: {name} must be {want}")
        values.append(v)
    return values
