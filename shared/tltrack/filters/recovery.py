"""Recovery of a particle filter that lost track: an option, on in the services, off in experiments.

With the transition prior as proposal and little process noise, a cloud that has collapsed away
from the object never comes back: every particle explains the measurement equally badly. The test
is on the primary's own measurement, before the update, at the filter's anchors a^(i) (the
predicted cloud of the SIR; the transition means f(x_{k-1}^(i)) the auxiliary filter's first
stage weighs, so the test costs it no propagation of its own):

    lost  <=>  min_i (z_k - h(a^(i)))' Q_w^-1 (z_k - h(a^(i)))  >  chi2_{n_z}^{-1}(1 - 1e-9)

(also when the cloud holds a non-finite value), or when z_k alone would leave fewer than
``min_ess`` effective particles: the weights of all but one underflow, as after a long outage
whose predictions spread the cloud thin. A lost run's particles are redrawn with the spread of P0
around the anchors' mean, and, when the sensor's measurement fixes a position
(:class:`~tltrack.models.base.PositionFix`), with their position drawn around the one z_k implies
(its linearised covariance). The paper's experiments keep it off, so lost runs count.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from tltrack.filters import chi2
from tltrack.filters.kernels import resample
from tltrack.filters.likelihood import Likelihood
from tltrack.models.base import MotionModel, PositionFix
from tltrack.models.observation import Observation

Array = NDArray[np.float64]


class Reinitialisable(Protocol):
    """A particle filter whose runs a recovery can redraw."""

    model: MotionModel
    rngs: list[np.random.Generator]
    N: int

    @property
    def anchors(self) -> Array: ...

    def reinitialise(self, b: int, particles: Array) -> None: ...


@dataclass
class Recovery:
    """Detects and reinitialises lost runs of a particle filter; counts them per run."""

    P0: Array
    tail: float = 1e-9
    min_ess: float = 2.0
    count: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    _likelihood: Likelihood | None = field(default=None, init=False, repr=False)

    def lost(self, pf: Reinitialisable, z: Observation) -> NDArray[np.bool_]:
        x = pf.anchors
        if self._likelihood is None or self._likelihood.batch != x.shape[1]:
            self._likelihood = Likelihood(x.shape[1])
        B, N = x.shape[1:]
        rho = np.empty((B, N))
        self._likelihood.into(x, [z], rho)  # -NIS / 2, by the sensor's kernel where it has one
        peak, ess = np.empty(B), np.empty(B)
        resample.peak_and_ess(rho, peak, ess, np.empty(N))
        best = -2.0 * peak  # the smallest NIS; +inf when no particle's is finite
        return ~((best <= chi2.quantile(1.0 - self.tail, z.sensor.n_z)) & (ess * N >= self.min_ess))

    def __call__(self, pf: Reinitialisable, z: Observation) -> NDArray[np.bool_]:
        """Reinitialise the lost runs of ``pf`` around ``z``; returns which were."""
        lost = self.lost(pf, z)
        if self.count.shape[0] != lost.shape[0]:
            self.count = np.zeros(lost.shape[0], dtype=np.int64)
        self.count += lost
        for b in np.flatnonzero(lost):
            self._redraw(pf, z, int(b))
        return lost

    def _redraw(self, pf: Reinitialisable, z: Observation, b: int) -> None:
        g = pf.rngs[b]
        anchors = pf.anchors[:, b, :]
        finite = np.all(np.isfinite(anchors), axis=0)
        mean = anchors[:, finite].mean(axis=1) if finite.any() else np.zeros(anchors.shape[0])
        L = np.linalg.cholesky(self.P0)
        x = mean[:, None] + L @ g.standard_normal((len(mean), pf.N))
        if isinstance(z.sensor, PositionFix):
            pos, S = z.sensor.to_position(z.mean[:, b : b + 1], z.cov[b : b + 1])
            p = pos[:, 0, None] + np.linalg.cholesky(S[0]) @ g.standard_normal((2, pf.N))
            ix, iy = pf.model.layout.pos
            x[ix], x[iy] = p[0], p[1]
        pf.reinitialise(b, x)
