"""The SIR particle filter of the seed's Sec. IV, batched over B runs.

With the transition prior as proposal and resampling at every step, the weight of particle i is
the product of the Gaussian likelihoods of every observation (seed eqs. TL_tr_weights_1/2):

    w_k^(i)  ∝  p(z_k | x_k^(i)) · p(eta_hat_k | x_k^(i))

An isolated PF passes only z_k; TL-PF adds the source's transfer; centralized fusion adds the
source's raw measurement instead. Weights stay in the log domain, so two sharp likelihoods whose
product underflows in linear space still normalise (no 0/0).

Particles are stored ``(n_x, B, N)``: each state component of each run is one contiguous row.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from tltrack.filters.base import Estimate
from tltrack.filters.resampling import systematic_indices
from tltrack.models.measurement import RangeBearing
from tltrack.models.motion import MotionModel
from tltrack.models.observation import Observation

Array = NDArray[np.float64]


def gaussian_loglik(obs: Observation, x: Array) -> Array:
    """log N(obs.mean; h(x), obs.cov) up to a per-run constant, (B, N) (seed eq. TL_tr_likelihood_2)."""
    d = obs.sensor.residual(obs.mean[:, :, None], obs.sensor.h(x))  # (2, B, N)
    Pinv = np.linalg.inv(obs.cov)  # (B, 2, 2)
    a = Pinv[:, 0, 0, None]
    b = Pinv[:, 0, 1, None]
    c = Pinv[:, 1, 1, None]
    rho = -0.5 * (a * d[0] * d[0] + 2.0 * b * d[0] * d[1] + c * d[1] * d[1])
    if obs.mask is not None:
        rho = np.where(obs.mask[:, None], rho, 0.0)
    return rho


class ParticleFilter:
    """SIR-PF with systematic resampling at every step; one random stream per run."""

    def __init__(
        self,
        model: MotionModel,
        x0_hat: Array,
        P0: Array,
        n_particles: int,
        rngs: Sequence[np.random.Generator],
    ) -> None:
        """Draw N particles per run from N(x0_hat[:, b], P0); ``x0_hat`` is (n_x, B)."""
        self.model = model
        self.rngs = list(rngs)
        self.N = n_particles
        n, B = x0_hat.shape
        if len(self.rngs) != B:
            raise ValueError(f"{len(self.rngs)} random streams for a batch of {B} runs")
        L0 = np.linalg.cholesky(P0)
        eps = self._normals(n)
        self.x: Array = x0_hat[:, :, None] + np.tensordot(L0, eps, axes=1)

    @property
    def batch(self) -> int:
        return len(self.rngs)

    def _normals(self, r: int) -> Array:
        eps = np.empty((r, self.batch, self.N))
        for b, g in enumerate(self.rngs):
            eps[:, b, :] = g.standard_normal((r, self.N))
        return eps

    def predict(self) -> None:
        """x_k^(i) ~ p(x_k | x_{k-1}^(i)) (seed eq. BTL_tr_particle_2), noise through Q_sqrt."""
        L = self.model.Q_sqrt
        self.x = self.model.f(self.x) + np.tensordot(L, self._normals(L.shape[1]), axes=1)

    def log_weights(self, observations: Sequence[Observation]) -> Array:
        """Unnormalised log-weights (B, N): the sum of every observation's log-likelihood."""
        logw = np.zeros((self.batch, self.N))
        for obs in observations:
            logw += gaussian_loglik(obs, self.x)
        return logw

    def update(self, observations: Sequence[Observation]) -> None:
        """Weight, normalise and resample (Algorithm 2, lines 3-9)."""
        logw = self.log_weights(observations)
        logw -= logw.max(axis=1, keepdims=True)
        w = np.exp(logw)
        w /= w.sum(axis=1, keepdims=True)
        idx = systematic_indices(w, self.rngs)
        self.x = np.take_along_axis(self.x, idx[None, :, :], axis=2)

    def estimate(self) -> Estimate:
        """Mean and covariance of the resampled cloud, plus Q_v (seed eqs. BTL_tr_state_mean/cov)."""
        mean = self.x.mean(axis=2)  # (n, B)
        d = self.x - mean[:, :, None]
        cov = np.einsum("ibn,jbn->bij", d, d) / self.N + self.model.Q
        return Estimate(mean.T.copy(), cov)

    def predicted_observation(self, sensor: RangeBearing, R: Array) -> Observation:
        """eta_hat and P_eta_eta from the propagated cloud (seed eqs. BTL_sr_pred_obser_mean/cov).

        The bearing's mean is circular, and deviations are wrapped, as tracks cross the +-pi cut.
        """
        Z = sensor.h(self.x)  # (2, B, N)
        eta = sensor.mean(Z, axis=2)  # (2, B)
        d = sensor.residual(Z, eta[:, :, None])
        cov = np.einsum("ibn,jbn->bij", d, d) / self.N + R
        return Observation(sensor, eta, cov)
