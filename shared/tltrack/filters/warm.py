"""Compiling the particle filters' kernels ahead of use."""

from __future__ import annotations

import numpy as np

from tltrack.filters import fastpath
from tltrack.filters.auxiliary import AuxiliaryParticleFilter
from tltrack.filters.kernels import propagation, scan
from tltrack.filters.kernels.gaussians import uniforms_per_run
from tltrack.filters.kernels.moments import spread_coordinates
from tltrack.filters.particle import ParticleFilter
from tltrack.filters.recovery import Recovery
from tltrack.filters.resampling import systematic_indices
from tltrack.models.coordinated_turn import CoordinatedTurn
from tltrack.models.modes import Straight
from tltrack.models.observation import Observation


def warm_up() -> None:
    """Load (or, on a cold cache, compile) every fast-path kernel, on a tiny problem.

    Call it in a parent process before starting workers, so they find numba's cache on disk
    instead of compiling the same kernels side by side.
    """
    rngs = [np.random.default_rng(0)]
    for model, sensor in fastpath.examples():
        z = Observation.broadcast(sensor, sensor.h(np.full(model.n, 1000.0)), sensor.R(1.0))
        n = model.n
        x0 = np.full((n, 1), 1000.0)
        for kind in (ParticleFilter, AuxiliaryParticleFilter):
            pf = kind(model, x0, np.eye(n), 8, rngs)
            pf.predict()
            Recovery(np.eye(n)).lost(pf, z)  # the services' lost-track test
            pf.estimate()
            pf.predicted_observation(sensor, sensor.R(1.0))
            pf.update([z, z])
            pf.estimate()
            _ = pf.x
            pf.gaussians()
    _warm_modes()
    for n_z in (1, 2, 3):  # the dense scans' grid, for each layout of its loop
        x, two = np.zeros((n_z, 2)), np.ones(2)
        scan.scan_loglik(x, x, np.zeros(n_z, bool), np.eye(n_z), np.ones(n_z), two, two, two.copy())
    systematic_indices(np.full((1, 4), 0.25), rngs)
    spread_coordinates(np.eye(5)[None], 1e-10)  # the Monte-Carlo engine's NEES


def _warm_modes() -> None:
    """The jump-Markov coordinated turn's kernels (particles of mixed modes)."""
    N = 8
    mixed = fastpath.modes_propagator([Straight(1.0, 1.0), CoordinatedTurn(1.0, 1.0, 1e-4)], N)
    assert mixed is not None
    x = np.full((5, 1, N), 1000.0)
    modes = (np.arange(N) % 2)[None].astype(np.int64)
    anc = np.zeros((1, N + 1), dtype=np.int64)
    out = np.empty_like(x)
    mixed(x, anc, modes, np.full((1, uniforms_per_run(3, N)), 0.5), out, 0)
    mixed.mean(x, modes, out)
    propagation.switch_modes(np.full((1, N), 0.5), modes, np.ones((2, 2)), modes.copy())
