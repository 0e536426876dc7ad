"""One target among false alarms: the measurement-set likelihood and probabilistic data association.

A scan Z = {z_1, ..., z_M} holds the target's measurement with probability pd(x) (pd inside the
field of view, 0 outside) and Poisson false alarms of density lambda_c. Given the state x, the
scan's likelihood, up to a factor that does not depend on x, is

    l(Z | x)  ∝  lambda_c (1 - pd(x) P_G)  +  pd(x) sum_j g(z_j | x),        g = N(z; h(x), R)

(the expected-likelihood particle filter of Marrs, Maskell & Bar-Shalom 2002, eq. 12, multiplied
through by lambda_c). Written so, it needs no division and holds at lambda_c = 0: one detection
and pd = 1 give g(z | x), the paper's likelihood.

- Particle filters (:func:`scan_loglik`) weigh every particle by it. A detection farther than
  ``CLOUD_GATE_SIGMAS`` noise standard deviations, in any component, from a particle's predicted
  measurement adds less than exp(-CLOUD_GATE_SIGMAS^2 / 2) of a hit to that particle's sum and is
  left out of it, so P_G = 1. The scan is gated once per cloud, by the cloud's extent; then each
  detection adds to the particles near it, found through a grid of the particles
  (:mod:`tltrack.filters.kernels.scan`), so a scan of thousands of detections costs little more
  than the few near each particle.
- Gaussian filters (:func:`associate`) use probabilistic data association (Bar-Shalom & Tse
  1975; Bar-Shalom, Daum & Huang 2009, eqs. 37-44): the detections inside the gate
  nu' S^-1 nu <= chi2_{n_z}(P_G) of the predicted measurement N(z_hat, S) each get a probability
  beta_j of being the target's, beta_0 that none is, from the same likelihood with x integrated
  out; the update uses the combined innovation sum_j beta_j nu_j.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tltrack.filters import chi2
from tltrack.filters.kernels import scan as kernel
from tltrack.models.observation import Observation
from tltrack.models.scan import Scan

Array = NDArray[np.float64]

#: the cloud's gate, in noise standard deviations beyond the cloud's extent (a detection outside
#: it adds at most exp(-18) ~ 1.5e-8 of a hit to any particle's likelihood)
CLOUD_GATE_SIGMAS = 6.0


def gate_volume(R: Array, probability: float = 0.99) -> float:
    """The volume of {nu : nu' R^-1 nu <= chi2_{n_z}(probability)}: an ellipsoid of radius
    sqrt(gamma) in R's metric (pi gamma sqrt(det R) for n_z = 2)."""
    n = R.shape[0]
    gamma = chi2.quantile(probability, n)
    unit_ball = math.pi ** (n / 2) / math.gamma(n / 2 + 1)
    return float(unit_ball * gamma ** (n / 2) * math.sqrt(np.linalg.det(R)))


def logsumexp(a: Array, axis: int) -> Array:
    """log sum exp(a) along ``axis``, -inf where every term is -inf."""
    top = np.max(a, axis=axis, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore"):
        return np.asarray(np.log(np.sum(np.exp(a - top), axis=axis)) + np.squeeze(top, axis))


def _log_clutter(scan: Scan, pd_x: Array, P_G: float) -> Array:
    """log(lambda_c (1 - pd(x) P_G)), -inf where it is 0."""
    with np.errstate(divide="ignore"):
        return np.log(scan.detection.density * (1.0 - pd_x * P_G))


def _log_pd(pd_x: Array) -> Array:
    with np.errstate(divide="ignore"):
        return np.log(pd_x)


def _gaussian_logpdf(nu: Array, cov: Array) -> Array:
    """log N(nu; 0, cov) for innovations nu (n_z, B, ...) and covariances cov (B, n_z, n_z)."""
    n_z, B = nu.shape[:2]
    shape = (B,) + (1,) * (nu.ndim - 2)
    Ri = np.linalg.inv(cov)
    q = sum(Ri[:, i, j].reshape(shape) * nu[i] * nu[j] for i in range(n_z) for j in range(n_z))
    logdet = np.linalg.slogdet(cov)[1]
    return np.asarray(-0.5 * (q + (logdet + n_z * np.log(2.0 * np.pi)).reshape(shape)))


def _compact(scan: Scan, keep: NDArray[np.bool_]) -> tuple[Array, NDArray[np.bool_]]:
    """The kept detections of each run first, padded to the largest count: (n_z, B, M'), (B, M')."""
    M = int(keep.sum(axis=1).max(initial=0))
    order = np.argsort(~keep, axis=1, kind="stable")[:, :M]
    return np.take_along_axis(scan.z, order[None], axis=2), np.take_along_axis(keep, order, axis=1)


def scan_loglik(scan: Scan, x: Array) -> Array:
    """log l(Z | x) (B, N) of the clouds ``x`` (n_x, B, N), up to a per-run constant.

    A run where every particle's likelihood is 0 (no detection near its cloud, and no false
    alarms possible) learns nothing: its log-likelihoods are 0, as for a run outside the scan's
    ``mask``. (Without clutter, a cloud that every detection misses by more than the gate has
    lost the target; the recovery, not the weights, is what can bring it back.)
    """
    Zx = scan.sensor.h(x)  # (n_z, B, N)
    half = CLOUD_GATE_SIGMAS * np.sqrt(np.diagonal(scan.cov, axis1=1, axis2=2)).T  # (n_z, B)
    pd_x = scan.detection.pd_at(Zx)  # (B, N)
    angular = getattr(scan.sensor, "angular", None)
    if angular is None or scan.sensor.n_z > 3:
        out = _loglik_by_pairs(scan, Zx, half, pd_x)
    else:
        out = _loglik_by_grid(scan, Zx, half, pd_x, np.asarray(angular, dtype=np.bool_))
    dead = ~np.isfinite(out).any(axis=1) | (False if scan.mask is None else ~scan.mask)
    out[dead] = 0.0
    return np.asarray(out)


def _loglik_by_grid(
    scan: Scan, Zx: Array, half: Array, pd_x: Array, angular: NDArray[np.bool_]
) -> Array:
    """:func:`scan_loglik` through the grid kernel (:mod:`tltrack.filters.kernels.scan`), run by
    run, for a sensor of at most three components that declares which are angles."""
    B, N = pd_x.shape
    out = np.empty((B, N))
    Ri = np.linalg.inv(scan.cov)
    norm = 1.0 / np.sqrt(np.linalg.det(2.0 * np.pi * scan.cov))  # (B,)
    floor = scan.detection.density * (1.0 - pd_x)
    for b in range(B):
        kernel.scan_loglik(
            np.ascontiguousarray(Zx[:, b, :]),
            np.ascontiguousarray(scan.z[:, b, scan.valid[b]]),
            angular,
            np.ascontiguousarray(Ri[b]),
            np.ascontiguousarray(half[:, b]),
            np.ascontiguousarray(floor[b]),
            np.ascontiguousarray(pd_x[b] * norm[b]),
            out[b],
        )
    return out


def _loglik_by_pairs(scan: Scan, Zx: Array, half: Array, pd_x: Array) -> Array:
    """:func:`scan_loglik` with every particle against every detection near its cloud, for a
    sensor that does not declare its angles (``angular``; its own ``residual`` knows them) or
    has more than three components."""
    s = scan.sensor
    ref = s.mean(Zx, axis=2)  # (n_z, B)
    Ux = s.residual(Zx, ref[:, :, None])  # measurements relative to the cloud's centre
    Uz = s.residual(scan.z, ref[:, :, None])
    with np.errstate(invalid="ignore"):
        extent = np.nanmax(np.abs(Ux), axis=2, initial=0.0)  # (n_z, B)
    near = scan.valid & (np.abs(Uz) <= (extent + half)[:, :, None]).all(axis=0)
    out = _log_clutter(scan, pd_x, 1.0)
    if near.any():
        Zg, vg = _compact(scan, near)
        nu = s.residual(Zg[:, :, None, :], Zx[:, :, :, None])  # (n_z, B, N, M')
        lg = np.where(vg[:, None, :], _gaussian_logpdf(nu, scan.cov), -np.inf)
        out = np.logaddexp(out, _log_pd(pd_x) + logsumexp(lg, axis=2))
    return np.asarray(out)


@dataclass(frozen=True)
class Association:
    """PDA of one scan against a predicted measurement N(z_hat, S), per run."""

    nu: Array  #: (n_z, B, M) each detection's innovation z_j - z_hat
    beta: Array  #: (B, M) P(detection j is the target's); 0 outside the gate
    beta0: Array  #: (B,) P(none is)
    loglik: Array  #: (B,) log of the scan's likelihood with x integrated out (0: no information)
    gated: NDArray[np.bool_]  #: (B, M)

    @property
    def innovation(self) -> Array:
        """The combined innovation sum_j beta_j nu_j (n_z, B)."""
        return np.asarray(np.einsum("ibm,bm->ib", self.nu, self.beta))

    @property
    def spread(self) -> Array:
        """sum_j beta_j nu_j nu_j' - nu nu' (B, n_z, n_z): what the association's doubt adds."""
        nu = self.innovation
        return np.asarray(
            np.einsum("bm,ibm,jbm->bij", self.beta, self.nu, self.nu)
            - np.einsum("ib,jb->bij", nu, nu)
        )

    @property
    def any(self) -> NDArray[np.bool_]:
        """Runs with at least one detection in the gate."""
        return np.asarray(self.gated.any(axis=1))


def associate(scan: Scan, predicted: Observation) -> Association:
    """The PDA of ``scan`` given the predicted measurement ``predicted`` = N(z_hat, S)."""
    s, zhat, S = scan.sensor, predicted.mean, predicted.cov
    B, M = scan.valid.shape
    P_G = scan.gate_probability
    if M == 0:
        z = np.zeros((s.n_z, B, 0))
        return Association(z, np.zeros((B, 0)), np.ones(B), np.zeros(B), np.zeros((B, 0), bool))
    nu = s.residual(scan.z, zhat[:, :, None])  # (n_z, B, M)
    lg = _gaussian_logpdf(nu, S)  # (B, M)
    d2 = -2.0 * lg - (np.linalg.slogdet(S)[1] + s.n_z * np.log(2.0 * np.pi))[:, None]
    gated = scan.valid & (d2 <= chi2.quantile(P_G, s.n_z))
    pd_b = scan.detection.pd_at(zhat)  # (B,)
    hits = np.where(gated, _log_pd(pd_b)[:, None] + lg, -np.inf)
    terms = np.concatenate([_log_clutter(scan, pd_b, P_G)[:, None], hits], axis=1)
    total = logsumexp(terms, axis=1)
    none = ~np.isfinite(total) | (False if scan.mask is None else ~scan.mask)
    total = np.where(none, 0.0, total)
    beta = np.where(none[:, None], 0.0, np.exp(terms - total[:, None]))
    beta[none, 0] = 1.0
    return Association(nu, beta[:, 1:], beta[:, 0], total, gated & ~none[:, None])


def combined(scan: Scan, predicted: Observation, a: Association) -> Observation:
    """The scan as one statement: z_hat plus the combined innovation, with the noise R plus the
    association's spread; where no detection is in the gate, the prediction N(z_hat, S) itself
    (what the robust policy judges a transfer against)."""
    s = scan.sensor
    mean = s.residual(predicted.mean + a.innovation, np.zeros_like(predicted.mean))
    cov = np.where(a.any[:, None, None], scan.cov + a.spread, predicted.cov)
    return Observation(s, mean, cov, None, scan.origin)


def likeliest(scan: Scan, a: Association) -> Observation:
    """Each run's gated detection of the largest beta_j, with R (a lost-track recovery's anchor),
    for the runs with a detection in the gate."""
    B = scan.batch
    j = np.argmax(a.beta, axis=1) if a.beta.shape[1] else np.zeros(B, dtype=np.int64)
    mean = scan.z[:, np.arange(B), j] if scan.z.shape[2] else np.zeros((scan.sensor.n_z, B))
    return Observation(scan.sensor, mean, np.asarray(scan.cov), a.any, scan.origin)
