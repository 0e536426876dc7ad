"""Recorded measurements from a CSV file, so that real sensor data can drive the trackers.

Schema (header row required; extra columns are ignored)::

    k,sensor,range_m,bearing_rad
    1,primary,1442.1,0.7861
    1,s1,1436.9,0.7850

- ``k``: step index 1..K; every step must have a row for the primary and for each source;
- ``sensor``: ``primary`` or a source id of the configuration;
- ``range_m`` (m, > 0) and ``bearing_rad`` (rad, atan2 convention, from the sensor's position).

A bad file is refused as a whole, with the line number, before anything is published.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

REQUIRED = ("k", "sensor", "range_m", "bearing_rad")


class ReplayError(ValueError):
    """The CSV does not follow the schema; the message says where."""


def load(path: Path, sensors: list[str]) -> dict[str, NDArray[np.float64]]:
    """sensor id -> (K, 2) measurements, validated against the schema above."""
    try:
        with open(path, newline="") as fh:
            reader = csv.DictReader(fh)
            missing = [c for c in REQUIRED if c not in (reader.fieldnames or [])]
            if missing:
                raise ReplayError(f"{path}: missing column(s) {', '.join(missing)}")
            rows: dict[tuple[int, str], tuple[float, float]] = {}
            for line, row in enumerate(reader, start=2):
                rows[_parse(path, line, row, sensors)] = (
                    float(row["range_m"]),
                    float(row["bearing_rad"]),
                )
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


def _parse(path: Path, line: int, row: dict[str, str], sensors: list[str]) -> tuple[int, str]:
    try:
        k, r, b = int(row["k"]), float(row["range_m"]), float(row["bearing_rad"])
    except (TypeError, ValueError):
        raise ReplayError(f"{path}:{line}: k, range_m and bearing_rad must be numbers") from None
    if k < 1 or not (math.isfinite(r) and r > 0) or not (math.isfinite(b) and abs(b) <= math.pi):
        raise ReplayError(f"{path}:{line}: need k >= 1, range_m > 0, |bearing_rad| <= pi")
    if row["sensor"] not in sensors:
        raise ReplayError(f"{path}:{line}: unknown sensor {row['sensor']!r} (known: {sensors})")
    return k, row["sensor"]
