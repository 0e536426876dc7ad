"""Truth trajectories, sensor measurements and initial estimates for one Monte-Carlo run.

The seed says only that its trajectory is "identical to the simulation realization" of earlier
papers; NOTES.md shows the RMSE depends heavily on how it was drawn, so all three readings exist:

- ``fixed``: one realization from ``truth_seed``, shared by every run (the default);
- ``random``: a fresh realization per run;
- ``noise-free``: f applied with no process noise.

Measurements and the filters' initial estimate x0_hat ~ N(x0, P0) are fresh per run (the
cubature-KF benchmark's convention), each from its own stream.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tltrack.config import Config
from tltrack.engine.faults import bearing_bias, observed_truth
from tltrack.engine.streams import stream
from tltrack.models.measurement import RangeBearing, wrap_angle
from tltrack.models.motion import motion_model

Array = NDArray[np.float64]

PRIMARY = "primary"


def sensor(cfg: Config, sensor_id: str = PRIMARY) -> RangeBearing:
    """The range-bearing model of the primary or of the source with that id."""
    pos = cfg.primary_position
    if sensor_id != PRIMARY:
        pos = next(s.position for s in cfg.sources if s.id == sensor_id)
    return RangeBearing(cfg.sigma_r, cfg.sigma_bearing, pos)


def intensity(cfg: Config, sensor_id: str = PRIMARY) -> float:
    if sensor_id == PRIMARY:
        return cfg.primary_intensity
    return next(s.intensity for s in cfg.sources if s.id == sensor_id)


def truth(cfg: Config, run: int) -> Array:
    """The true states x_0..x_K of one run, shape (K + 1, n_x)."""
    model = motion_model(cfg)
    x = np.empty((cfg.K + 1, cfg.n_x))
    x[0] = cfg.x0
    if cfg.truth == "noise-free":
        for k in range(1, cfg.K + 1):
            x[k] = model.f(x[k - 1])
        return x
    g = (
        stream(cfg.truth_seed, 0, "truth")
        if cfg.truth == "fixed"
        else stream(cfg.seed, run, "truth")
    )
    eps = g.standard_normal((cfg.K, model.Q_sqrt.shape[1]))
    for k in range(1, cfg.K + 1):
        x[k] = model.f(x[k - 1]) + model.Q_sqrt @ eps[k - 1]
    return x


def measurements(cfg: Config, run: int, x: Array, sensor_id: str = PRIMARY) -> Array:
    """z_1..z_K of one sensor along truth ``x``, shape (K, 2), bearing wrapped to (-pi, pi]."""
    s = sensor(cfg, sensor_id)
    I_w = intensity(cfg, sensor_id)
    L = np.linalg.cholesky(s.R(I_w))
    eps = stream(cfg.seed, run, f"meas/{sensor_id}").standard_normal((cfg.K, 2))
    z = s.h(observed_truth(cfg, sensor_id, x)[1:].T).T + eps @ L.T
    z[:, 1] = wrap_angle(z[:, 1] + bearing_bias(cfg, sensor_id, I_w))
    return z


def initial_estimate(cfg: Config, run: int) -> Array:
    """x0_hat ~ N(x0, P0): every filter of the run starts here, not at the true x0."""
    eps = stream(cfg.seed, run, "init").standard_normal(cfg.n_x)
    return np.asarray(cfg.x0) + np.sqrt(cfg.P0_diag) * eps


@dataclass(frozen=True)
class Run:
    """Everything the filters of one run are given, and the truth they are scored against."""

    run: int
    truth: Array  # (K + 1, n_x)
    z: dict[str, Array]  # sensor id -> (K, 2)
    x0_hat: Array  # (n_x,)


def simulate(cfg: Config, run: int) -> Run:
    """The truth, every sensor's measurements and the initial estimate of one run."""
    x = truth(cfg, run)
    ids = [PRIMARY, *(s.id for s in cfg.sources)]
    return Run(run, x, {i: measurements(cfg, run, x, i) for i in ids}, initial_estimate(cfg, run))
