"""Recorded scans from a CSV file: every detection each sensor reported at each step.

Schema (header row required; extra columns are ignored)::

    k,sensor,range_m,bearing_rad,is_clutter
    1,primary,1436.9,0.7861,0
    1,primary,2210.4,-1.9350,1
    1,s1,1433.2,0.7850,0
    3,s1,1440.0,0.7902,

- ``k``: the step, 1..K, K being the configuration's (a row beyond it is refused);
- ``sensor``: ``primary`` or a source id of the configuration;
- one column per measurement component of the sensors, named after it (each sensor kind's
  ``components``; :mod:`tltrack.live.replay` lists them); a row fills its own sensor's columns;
- ``is_clutter`` (optional): 1 or 0 (or ``true``/``false``, or empty when unknown), ground truth
  for scoring only: no filter sees it.

Each row is one detection, so two rows of the same step and sensor are two detections, and a step
with no row for a sensor is an empty scan: the sensor saw nothing. The filters predict through it
(the measurement-set likelihood of no detection is the same for every state the sensor sees, and
PDA keeps the prediction), so an empty scan is not an error.

A malformed row (a missing or non-numeric field, a NaN, a value no sensor can measure
(:mod:`tltrack.models.components`), a step beyond K, an unknown sensor) refuses
the whole file, naming its line, before any filter runs. A scan of more than
:data:`~tltrack.models.scan.MAX_DETECTIONS` detections is refused alone, with the line where it
went over: the filters predict through that step, as through a scan that never arrived, and
:attr:`ScanFile.refused` says why.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from tltrack.config.schema import MAX_STEPS
from tltrack.models import components
from tltrack.models.base import MeasurementModel
from tltrack.models.scan import MAX_DETECTIONS

if TYPE_CHECKING:
    from tltrack.engine.setup import Setup

Array = NDArray[np.float64]
TRUE, FALSE = {"1", "true", "True", "TRUE"}, {"0", "false", "False", "FALSE"}


class ScanFileError(ValueError):
    """The file does not follow the schema; the message says where."""


class ScansDoNotFitError(ValueError):
    """The file's scans contradict the config's detection process."""


@dataclass(frozen=True)
class ScanFile:
    """A file's scans: per sensor id and step k = 1..K, the detections (M_k, n_z), or None for a
    scan refused as too large; ``is_clutter`` likewise (None: not recorded)."""

    path: Path
    K: int
    detections: dict[str, list[Array | None]]
    is_clutter: dict[str, list[NDArray[np.bool_] | None]]
    refused: list[str]
    lines: dict[tuple[str, int], list[int]]  #: (sensor id, k) -> the lines of its detections

    def scan(self, sensor_id: str, k: int) -> Array | None:
        """Sensor ``sensor_id``'s detections at step k (None: refused)."""
        return self.detections[sensor_id][k - 1]

    def counts(self, sensor_id: str) -> NDArray[np.int64]:
        """Detections per step (-1: refused), (K,)."""
        return np.array([-1 if d is None else len(d) for d in self.detections[sensor_id]])


def read_scans(
    path: Path, sensors: Mapping[str, MeasurementModel], K: int | None = None
) -> ScanFile:
    """Read and check ``path`` against the sensors of a configuration and its K (None: the
    file's last step is K)."""
    limit = math.inf if K is None else K
    lines: dict[tuple[str, int], list[int]] = {}
    rows: dict[tuple[str, int], list[list[float]]] = {}
    labels: dict[tuple[str, int], list[bool | None]] = {}
    over: dict[tuple[str, int], int] = {}  #: scan -> the line where it went over the bound
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:  # a spreadsheet's BOM too
            reader = csv.DictReader(fh)
            header = reader.fieldnames or []
            needed = sorted({c for s in sensors.values() for c in s.components})
            missing = [c for c in ("k", "sensor", *needed) if c not in header]
            if missing:
                raise ScanFileError(f"{path}: missing column(s) {', '.join(missing)}")
            labelled = "is_clutter" in header
            for line, row in enumerate(reader, start=2):
                sid, k = _key(path, line, row, sensors, limit)
                kind = sensors[sid].kind
                values = [_number(path, line, row, c, kind) for c in sensors[sid].components]
                lines.setdefault((sid, k), []).append(line)
                got = rows.setdefault((sid, k), [])
                if len(got) == MAX_DETECTIONS:
                    over.setdefault((sid, k), line)
                    continue
                got.append(values)
                if labelled:
                    labels.setdefault((sid, k), []).append(_label(path, line, row["is_clutter"]))
    except OSError as err:
        raise ScanFileError(f"cannot read {path}: {err.strerror}") from None
    except UnicodeDecodeError:
        raise ScanFileError(f"{path}: not a UTF-8 text file") from None
    except csv.Error as err:  # a field over csv's 128 kB
        raise ScanFileError(f"{path}:{reader.line_num + 1}: not CSV: {err}") from None
    if not rows:
        raise ScanFileError(f"{path}: no detections")
    K = max(k for _, k in rows) if K is None else K
    detections: dict[str, list[Array | None]] = {}
    clutter: dict[str, list[NDArray[np.bool_] | None]] = {}
    for sid, model in sensors.items():
        detections[sid], clutter[sid] = [], []
        for k in range(1, K + 1):
            dets = np.array(rows.get((sid, k), []), dtype=float).reshape(-1, model.n_z)
            known = labels.get((sid, k), [])
            truth = None
            if known and all(v is not None for v in known):
                truth = np.array(known, dtype=bool)
            kept = (sid, k) not in over
            detections[sid].append(dets if kept else None)
            clutter[sid].append(truth if kept else None)
    refused = [
        f"{path}:{line}: step {k} of sensor {sid!r} has more than {MAX_DETECTIONS} detections"
        for (sid, k), line in sorted(over.items(), key=lambda item: item[1])
    ]
    return ScanFile(Path(path), K, detections, clutter, refused, lines)


def _key(
    path: Path,
    line: int,
    row: dict[str, str],
    sensors: Mapping[str, MeasurementModel],
    K: float,
) -> tuple[str, int]:
    try:
        k = int(row["k"])
    except (TypeError, ValueError):
        raise ScanFileError(f"{path}:{line}: k must be an integer, not {row['k']!r}") from None
    if k < 1:
        raise ScanFileError(f"{path}:{line}: need k >= 1, not {k}")
    if k > K:
        raise ScanFileError(f"{path}:{line}: k = {k} is beyond the config's K = {K:.0f}")
    if k > MAX_STEPS:  # a step no run has: K empty scans before it, 1e9 of them a hang
        raise ScanFileError(f"{path}:{line}: k = {k} is beyond the {MAX_STEPS} steps of a run")
    if row["sensor"] not in sensors:
        known = list(sensors)
        raise ScanFileError(f"{path}:{line}: unknown sensor {row['sensor']!r} (known: {known})")
    return row["sensor"], k


def _number(path: Path, line: int, row: dict[str, str], name: str, kind: str) -> float:
    try:
        v = float(row[name])
    except (TypeError, ValueError):
        raise ScanFileError(
            f"{path}:{line}: a {kind} sensor needs {name} as a number, not "
            + (repr(row[name]) if row[name] is not None else "a missing field (a short row)")
        ) from None
    want = components.problem(name, v)
    if want is not None:
        raise ScanFileError(f"{path}:{line}: {name} must be {want}, not {row[name]!r}")
    return v


def _label(path: Path, line: int, text: str | None) -> bool | None:
    text = (text or "").strip()
    if text in TRUE or text in FALSE:
        return text in TRUE
    if text == "":
        return None
    raise ScanFileError(f"{path}:{line}: is_clutter must be 1, 0, true, false or empty")


def check_fit(setup: Setup, scans: ScanFile) -> None:
    """A sensor the config says detects every step with no false alarm (pd 1, no clutter) takes
    exactly one detection per step: refuse a file that has none or several, naming the step.
    A scan file's steps are the paper's, on one clock: refuse a config whose operators keep
    their own (:mod:`tltrack.config.timeline`)."""
    if not setup.timeline.synchronous:
        raise ScansDoNotFitError(
            f"{scans.path}: a scan file's step k is every sensor's, on one clock; the config "
            "gives an operator its own period_s, phase_s or clock_offset_s (the engine runs "
            "those: tltrack experiment)"
        )
    for sid in scans.detections:
        if not setup.sensors[sid].detection.trivial:
            continue
        counts = scans.counts(sid)
        wrong = np.flatnonzero((counts != 1) & (counts != -1))
        if len(wrong):
            k = int(wrong[0]) + 1
            lines = ", ".join(map(str, scans.lines.get((sid, k), []))) or "none"
            raise ScansDoNotFitError(
                f"{scans.path}: step {k} of sensor {sid!r} has {counts[k - 1]} detections (lines: "
                f"{lines}), but the config gives {sid!r} pd 1 and no false alarms: give its "
                "detection process (primary_detection or sources[].detection; --pd, "
                "--clutter-rate, --source-pd, --source-clutter-rate)"
            )
