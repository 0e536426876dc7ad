"""A scan: every detection one sensor reported at step k, of which at most one is the target.

Where an :class:`~tltrack.models.observation.Observation` is one Gaussian statement about h(x_k),
a scan is a set of them, some of them false alarms and perhaps none the target's. Filters take
both in one list: a particle filter weighs a scan by the measurement-set likelihood, a sigma-point
filter by probabilistic data association (:mod:`tltrack.filters.association`).

A batch of B runs holds B scans of different sizes, so detections are padded to the largest:
``z`` is (n_z, B, M) and ``valid`` (B, M) marks the real ones.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tltrack.models.base import MeasurementModel
from tltrack.models.detection import Detection
from tltrack.models.observation import Observation

Array = NDArray[np.float64]

#: the most detections one scan may hold, in a file or on the wire: a larger one is refused
MAX_DETECTIONS = 4096


@dataclass(frozen=True)
class Scan:
    """The detections of one sensor at step k for a batch, with the sensor's noise ``cov``
    (B, n_z, n_z), its detection process and the PDA gate's probability."""

    sensor: MeasurementModel
    z: Array
    valid: NDArray[np.bool_]
    cov: Array
    detection: Detection
    gate_probability: float = 0.99
    mask: NDArray[np.bool_] | None = None
    origin: str | None = None

    @classmethod
    def pack(
        cls,
        sensor: MeasurementModel,
        scans: Sequence[Array],
        R: Array,
        detection: Detection,
        gate_probability: float = 0.99,
    ) -> Scan:
        """From each run's detections (M_b, n_z), padded to the batch's largest scan."""
        B, n_z = len(scans), sensor.n_z
        M = max((len(s) for s in scans), default=0)
        z = np.zeros((n_z, B, M))
        valid = np.zeros((B, M), dtype=bool)
        for b, s in enumerate(scans):
            z[:, b, : len(s)] = np.asarray(s, dtype=float).T
            valid[b, : len(s)] = True
        cov = np.broadcast_to(np.asarray(R, dtype=float), (B, n_z, n_z))
        return cls(sensor, z, valid, cov, detection, gate_probability)

    @property
    def batch(self) -> int:
        return int(self.valid.shape[0])

    @property
    def counts(self) -> NDArray[np.int64]:
        """Detections per run (B,)."""
        return np.asarray(self.valid.sum(axis=1))


#: what a filter's update takes: Gaussian statements and scans, in one list
Statement = Observation | Scan
