"""Truth trajectories, sensor measurements and initial estimates for one Monte-Carlo run.

The seed says only that its trajectory is "identical to the simulation realization" of earlier
papers; the RMSE depends heavily on how it was drawn (docs/background.md, "the truth"), so all
three readings exist:

- ``fixed``: one realization from ``truth_seed``, shared by every run (the default);
- ``random``: a fresh realization per run;
- ``noise-free``: f applied with no process noise;
- ``file``: a recorded track (:mod:`tltrack.config.truth_file`), the same for every run.

Measurements and the filters' initial estimate x0_hat ~ N(x0, P0) are fresh per run (the
cubature-KF benchmark's convention), each from its own stream. A sensor that misses the target or
reports false alarms (:mod:`tltrack.models.detection`) also has scans, drawn from the stream
``detect/<sensor>`` around the same z_k, so its z_k are those of the clean sensor.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from tltrack.config import Config
from tltrack.config.truth_file import file_truth
from tltrack.engine.faults import miscalibration, observed_truth
from tltrack.engine.setup import PRIMARY, Setup
from tltrack.engine.streams import stream

Array = NDArray[np.float64]


def truth(setup: Setup, run: int) -> Array:
    """The true states of one run on the truth grid (:mod:`tltrack.config.timeline`), shape
    (ticks + 1, n_x): x_0..x_K when every operator samples every Ts, as in the paper."""
    cfg = setup.cfg
    if cfg.truth == "file":
        return file_truth(cfg)
    timeline = setup.timeline
    ticks = timeline.ticks
    model = setup.motion if timeline.grid_s == cfg.Ts else setup.motion.with_period(timeline.grid_s)
    x = np.empty((ticks + 1, cfg.n_x))
    x[0] = cfg.x0
    if cfg.truth == "noise-free":
        for k in range(1, ticks + 1):
            x[k] = model.f(x[k - 1])
        return x
    g = (
        stream(cfg.truth_seed, 0, "truth")
        if cfg.truth == "fixed"
        else stream(cfg.seed, run, "truth")
    )
    eps = g.standard_normal((ticks, model.Q_sqrt.shape[1]))
    for k in range(1, ticks + 1):
        x[k] = model.f(x[k - 1]) + model.Q_sqrt @ eps[k - 1]
    return x


def sampled(setup: Setup, x: Array, sensor_id: str) -> Array:
    """The rows of truth ``x`` at one operator's samples 1..K_i, (K_i, n_x)."""
    return x[setup.timeline.indices(sensor_id)]


def measurements(setup: Setup, run: int, x: Array, sensor_id: str = PRIMARY) -> Array:
    """z_1..z_K of one sensor along truth ``x`` at its own samples, shape (K, n_z), angles
    wrapped to (-pi, pi]."""
    s = setup.sensor(sensor_id)
    I_w = setup.intensity(sensor_id)
    g = stream(setup.cfg.seed, run, f"meas/{sensor_id}")
    seen = sampled(setup, observed_truth(setup, sensor_id, x), sensor_id)
    return s.draw(seen, I_w, g, miscalibration(setup.cfg, sensor_id, s, I_w))


def scans(setup: Setup, run: int, x: Array, z: Array, sensor_id: str = PRIMARY) -> Scans | None:
    """Each step's detections (M_k, n_z) of one sensor, and which are false alarms; None for
    the paper's sensor (every scan is z_k alone)."""
    own = setup.sensors[sensor_id]
    if own.detection.trivial:
        return None
    g = stream(setup.cfg.seed, run, f"detect/{sensor_id}")
    seen = own.detection.inside(
        own.model.h(sampled(setup, observed_truth(setup, sensor_id, x), sensor_id).T)
    )
    drawn = [own.detection.scan(z[k], bool(seen[k]), g) for k in range(len(z))]
    return Scans([d[0] for d in drawn], [d[1] for d in drawn])


def reports(setup: Setup, run: int, x: Array, sensor_id: str) -> list[Array]:
    """What one sensor reports at each step along truth ``x``, (M_k, n_z): its scans, or z_k
    alone for the paper's sensor. Its own streams only: an operator's sensor draws nothing of
    another's."""
    z = measurements(setup, run, x, sensor_id)
    drawn = scans(setup, run, x, z, sensor_id)
    return [zk[None, :] for zk in z] if drawn is None else drawn.detections


def initial_estimate(cfg: Config, run: int) -> Array:
    """x0_hat ~ N(x0, P0): every filter of the run starts here, not at the true x0."""
    eps = stream(cfg.seed, run, "init").standard_normal(cfg.n_x)
    return np.asarray(cfg.x0) + np.sqrt(cfg.P0_diag) * eps


@dataclass(frozen=True)
class Scans:
    """One sensor's scans over a run: per step, the detections (M_k, n_z) and which of them are
    false alarms (for scoring only: no filter sees it)."""

    detections: list[Array]
    is_clutter: list[NDArray[np.bool_]]


@dataclass(frozen=True)
class Run:
    """Everything the filters of one run are given, and the truth they are scored against."""

    run: int
    truth: Array  # (ticks + 1, n_x) on the truth grid: (K + 1, n_x) in the paper's case
    z: dict[str, Array]  # sensor id -> (K_i, n_z): the target's measurements at its samples
    x0_hat: Array  # (n_x,)
    scans: dict[str, Scans] = field(default_factory=dict)  # the sensors that miss or clutter

    def detections(self, sensor_id: str, k: int) -> Array:
        """What the sensor reports at step k, (M_k, n_z): its scan, or z_k alone for the paper's
        sensor (a live measurement message carries it so)."""
        if sensor_id in self.scans:
            return self.scans[sensor_id].detections[k - 1]
        return self.z[sensor_id][k - 1][None, :]


def simulate(setup: Setup, run: int) -> Run:
    """The truth, every sensor's measurements (and scans) and the initial estimate of one run."""
    x = truth(setup, run)
    z = {i: measurements(setup, run, x, i) for i in setup.sensor_ids}
    drawn = {i: scans(setup, run, x, z[i], i) for i in setup.sensor_ids}
    return Run(run, x, z, initial_estimate(setup.cfg, run), {i: s for i, s in drawn.items() if s})
