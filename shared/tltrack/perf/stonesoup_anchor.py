"""Stone Soup as its users run it, for the benchmarks' anchors (``tltrack bench`` and
``tltrack bench --clutter``).

The primary's radar is Stone Soup's ``CartesianToBearingRange`` and the paper's coordinated turn
its ``ConstantTurn``: its own models, not tltrack's in Stone Soup's clothes
(:mod:`tltrack.interop.stonesoup`), so that the anchor is the library's own speed. The prior cloud
is drawn as tltrack's filters draw theirs, x0_hat + sqrt(P0) * standard normals, from NumPy's
global generator (which Stone Soup draws from).

This module imports Stone Soup: import it where its absence is handled.
"""

from __future__ import annotations

import datetime
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
from stonesoup.models.transition.nonlinear import ConstantTurn
from stonesoup.predictor.particle import ParticlePredictor
from stonesoup.types.array import StateVector, StateVectors
from stonesoup.types.detection import Detection
from stonesoup.types.state import ParticleState
from tltrack.engine.setup import PRIMARY, Setup

#: the time of step 0 (Stone Soup's states carry datetimes)
T0 = datetime.datetime(2025, 1, 1)


@dataclass(frozen=True)
class Anchor:
    """The radar, the predictor and the prior at :data:`T0` of one setup."""

    radar: CartesianToBearingRange
    predictor: ParticlePredictor
    prior: ParticleState
    Ts: float

    def at(self, k: int) -> datetime.datetime:
        """The time of step k."""
        return T0 + datetime.timedelta(seconds=k * self.Ts)

    def detection(self, range_m: float, bearing_rad: float, k: int) -> Detection:
        """A detection at step k, in Stone Soup's order [bearing, range]."""
        z = StateVector([bearing_rad, range_m])
        return Detection(z, timestamp=self.at(k), measurement_model=self.radar)


def anchor(setup: Setup, x0_hat: NDArray[np.float64], N: int, seed: int) -> Anchor:
    """Stone Soup's models of ``setup``'s primary radar and motion, and N prior particles about
    ``x0_hat`` (NumPy's global generator seeded with ``seed``)."""
    np.random.seed(seed)  # Stone Soup draws from NumPy's global generator
    cfg, own = setup.cfg, setup.sensors[PRIMARY]
    radar = CartesianToBearingRange(
        ndim_state=5,
        mapping=(0, 2),
        noise_covar=np.diag([own.R[1, 1], own.R[0, 0]]),  # [bearing, range]
        translation_offset=StateVector(list(own.model.position)),
    )
    predictor = ParticlePredictor(
        ConstantTurn(linear_noise_coeffs=np.array([cfg.q1, cfg.q1]), turn_noise_coeff=cfg.q2)
    )
    sd0 = np.sqrt(np.asarray(cfg.P0_diag))[:, None]
    particles = x0_hat[:, None] + sd0 * np.random.standard_normal((len(x0_hat), N))
    prior = ParticleState(StateVectors(particles), log_weight=np.full(N, -np.log(N)), timestamp=T0)
    return Anchor(radar, predictor, prior, cfg.Ts)
