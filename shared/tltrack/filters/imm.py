"""The interacting multiple-model filter (Blom & Bar-Shalom 1988) over B runs.

One Gaussian filter per motion mode (:class:`~tltrack.models.modes.MotionModes`), each matched to
its mode, and the probability mu_j of each mode. One step (Bar-Shalom, Li & Kirubarajan 2001,
sec. 11.6.6):

1. mixing: c_j = sum_i Pi_ij mu_i, mu_i|j = Pi_ij mu_i / c_j; filter j starts from the mixture
   m0_j = sum_i mu_i|j m_i, P0_j = sum_i mu_i|j (P_i + (m_i - m0_j)(m_i - m0_j)');
2. each filter predicts with its own model and updates on every statement of the step (its own
   z_k and the transfers: the transfer term is the single-model filter's);
3. mode probabilities: mu_j proportional to c_j Lambda_j, Lambda_j the likelihood of filter j's
   stacked innovation;
4. the estimate is the mixture's mean and covariance.

A source's transfer is the moment-matched predicted observation of the mixture (weights c_j,
the predicted mode probabilities): the primary's transfer term is unchanged, and no mode
probability ever crosses. With one mode every step above is the mode's own filter, exactly.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from tltrack.filters.base import Estimate
from tltrack.models.base import MeasurementModel
from tltrack.models.observation import Observation
from tltrack.models.scan import Statement

Array = NDArray[np.float64]


@runtime_checkable
class GaussianFilter(Protocol):
    """A mode-matched filter: its Gaussian (m (n, B), P (B, n, n)) and the log-likelihood of its
    last update per run (``loglik``), beside the Filter interface."""

    m: Array
    P: Array
    loglik: Array

    def predict(self) -> None: ...

    def update(self, observations: Sequence[Statement]) -> None: ...

    def predicted_observation(self, sensor: MeasurementModel, R: Array) -> Observation: ...


class InteractingMultipleModel:
    """The IMM filter, with the :class:`~tltrack.filters.base.Filter` interface."""

    def __init__(
        self, filters: Sequence[GaussianFilter], transition: Array, initial: Array
    ) -> None:
        self.filters = list(filters)
        self.Pi = np.asarray(transition, dtype=float)
        B = self.filters[0].m.shape[1]
        #: (M, B): the mode probabilities, posterior after an update, predicted after a predict
        self.mu = np.repeat(np.asarray(initial, dtype=float)[:, None], B, axis=1)
        #: per run, log p(statements | the past) of the last update: log sum_j c_j Lambda_j
        self.loglik = np.zeros(B)

    @property
    def mode_probabilities(self) -> Array:
        """(M, B): each mode's probability, per run."""
        return self.mu

    def predict(self) -> None:
        """Mix (step 1), then let each mode-matched filter predict."""
        c = self.Pi.T @ self.mu  # (M, B): c_j
        safe = np.where(c > 0, c, 1.0)
        mix = self.Pi[:, :, None] * self.mu[:, None, :] / safe[None]  # (i, j, B): mu_i|j
        means = np.stack([f.m for f in self.filters])  # (M, n, B)
        covs = np.stack([f.P for f in self.filters])  # (M, B, n, n)
        for j, f in enumerate(self.filters):
            m0 = np.einsum("ib,inb->nb", mix[:, j], means)
            d = means - m0[None]  # (M, n, B)
            spread = np.einsum("inb,imb->ibnm", d, d)
            f.m = m0
            f.P = np.einsum("ib,ibnm->bnm", mix[:, j], covs + spread)
            f.predict()
        self.mu = c

    def update(self, observations: Sequence[Statement]) -> None:
        """Each filter updates; the modes are weighed by their likelihoods (step 3)."""
        for f in self.filters:
            f.update(observations)
        if not observations:
            self.loglik = np.zeros(self.mu.shape[1])
            return
        logw = np.log(np.maximum(self.mu, 1e-300)) + np.stack([f.loglik for f in self.filters])
        top = logw.max(axis=0, keepdims=True)
        w = np.exp(logw - top)
        total = w.sum(axis=0, keepdims=True)
        self.loglik = (top + np.log(total))[0]
        self.mu = w / total

    def estimate(self) -> Estimate:
        """The mixture's mean and covariance."""
        means = np.stack([f.m for f in self.filters])  # (M, n, B)
        m = np.einsum("ib,inb->nb", self.mu, means)
        d = means - m[None]
        P = np.einsum(
            "ib,ibnm->bnm",
            self.mu,
            np.stack([f.P for f in self.filters]) + np.einsum("inb,imb->ibnm", d, d),
        )
        return Estimate(m.T.copy(), P)

    def predicted_observation(self, sensor: MeasurementModel, R: Array) -> Observation:
        """The mixture's predicted observation, moment-matched (angles through the sensor's
        wrapped residuals about the first mode's)."""
        parts = [f.predicted_observation(sensor, R) for f in self.filters]
        ref = parts[0].mean
        eta = ref + sum(self.mu[j] * sensor.residual(p.mean, ref) for j, p in enumerate(parts))
        cov = np.zeros_like(parts[0].cov)
        for j, p in enumerate(parts):
            d = sensor.residual(p.mean, eta)  # (n_z, B)
            cov += self.mu[j][:, None, None] * (p.cov + np.einsum("ib,jb->bij", d, d))
        return Observation(sensor, np.asarray(eta), cov)

    def adopt(self, other: InteractingMultipleModel, runs: NDArray[np.bool_]) -> None:
        """``other``'s modes and their filters for ``runs`` (the robust TL's rollback)."""
        for mine, theirs in zip(self.filters, other.filters, strict=True):
            mine.m[:, runs] = theirs.m[:, runs]
            mine.P[runs] = theirs.P[runs]
        self.mu[:, runs] = other.mu[:, runs]
