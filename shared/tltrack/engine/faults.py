"""Faulty sources, for robustness studies: the paper assumes an honest, better source.

- ``bias``: the source's sensor is miscalibrated by 10 sigma of its own noise, in the component
  its kind's miscalibration shifts (a radar's bearing), so its transfers are confidently wrong;
- ``diverged``: the source tracks a ghost: its measurements follow the truth shifted by an offset
  growing 3 m per step in x and y, as a source that lost the target and locked onto clutter;
- ``stale``: its transfers arrive :data:`STALE_LAG` steps late but labelled as current.

Measurement faults are applied where measurements are drawn, so the live services see them too.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tltrack.config import Config
from tltrack.engine.setup import Setup
from tltrack.models.base import MeasurementModel

BIAS_SIGMAS = 10.0
GHOST_DRIFT_M = 3.0  #: per step, in x and in y
STALE_LAG = 3  #: steps

Array = NDArray[np.float64]


def _fault(cfg: Config, sensor_id: str) -> str:
    return next((s.fault for s in cfg.sources if s.id == sensor_id), "none")


def observed_truth(setup: Setup, sensor_id: str, x: Array) -> Array:
    """The trajectory a sensor actually observes: the truth, or a diverged source's ghost."""
    if _fault(setup.cfg, sensor_id) != "diverged":
        return x
    ghost = x.copy()
    drift = GHOST_DRIFT_M * np.arange(len(x))
    ix, iy = setup.layout.pos
    ghost[:, ix] += drift
    ghost[:, iy] += drift
    return ghost


def miscalibration(
    cfg: Config, sensor_id: str, sensor: MeasurementModel, intensity: float
) -> Array | None:
    """The constant offset of a biased source's measurements, else None."""
    if _fault(cfg, sensor_id) != "bias":
        return None
    return sensor.miscalibration(BIAS_SIGMAS, intensity)


def transfer_lag(cfg: Config, sensor_id: str) -> int:
    """Steps by which a source's transfers are late (a stale source), else 0."""
    return STALE_LAG if _fault(cfg, sensor_id) == "stale" else 0
