"""Normalising log-weights, their effective sample size, and resampling systematically, run by
run, with the resampled cloud's moments taken from the offspring counts."""

from __future__ import annotations

import numpy as np
from numba import njit

from tltrack.filters.kernels.fastmath import FMA, SUM, exp
from tltrack.filters.kernels.moments import weighted_moments_run
from tltrack.filters.resampling import systematic_walk


@njit(**FMA)
def largest(v: np.ndarray) -> float:
    """Largest non-NaN entry, with four independent chains so the loop is not latency-bound."""
    m0 = m1 = m2 = m3 = -np.inf
    n = v.shape[0]
    n4 = n - n % 4
    for i in range(0, n4, 4):
        m0 = v[i] if v[i] > m0 else m0
        m1 = v[i + 1] if v[i + 1] > m1 else m1
        m2 = v[i + 2] if v[i + 2] > m2 else m2
        m3 = v[i + 3] if v[i + 3] > m3 else m3
    for i in range(n4, n):
        m0 = v[i] if v[i] > m0 else m0
    m0 = m1 if m1 > m0 else m0
    m2 = m3 if m3 > m2 else m2
    return m2 if m2 > m0 else m0


@njit(**SUM)
def ess_share(w: np.ndarray) -> float:
    """(sum w)^2 / (N sum w^2): the effective sample size of weights w >= 0, as a share of N."""
    s1 = 0.0
    s2 = 0.0
    for i in range(w.shape[0]):
        s1 += w[i]
        s2 += w[i] * w[i]
    return s1 * s1 / (s2 * w.shape[0]) if s2 > 0.0 else 0.0


@njit(**FMA)
def peak_and_ess(logw: np.ndarray, peak: np.ndarray, ess: np.ndarray, row: np.ndarray) -> None:
    """For each run b of log-weights logw (B, N): the largest, peak[b], and the effective sample
    size of exp(logw[b]), ess[b] (a share of N); entries that are not finite weigh nothing."""
    for b in range(logw.shape[0]):
        top = largest(logw[b])
        peak[b] = top
        if not (top > -np.inf and top < np.inf):
            ess[b] = 0.0
            continue
        for i in range(logw.shape[1]):
            e = exp(logw[b, i] - top)
            row[i] = e if e >= 0.0 else 0.0  # NaN weighs nothing
        ess[b] = ess_share(row)


@njit(**FMA)
def resample_run(
    w: np.ndarray,
    u: float,
    x: np.ndarray,
    b: int,
    anc: np.ndarray,
    cnt: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
) -> bool:
    """Run b of :func:`resample`, from its log-weights w (overwritten); cnt (N,) is scratch."""
    N = w.shape[0]
    m = largest(w)
    for i in range(N):
        w[i] = exp(w[i] - m)
    if not systematic_walk(w, u, anc):
        return False
    k = w.view(np.int64)  # the walk leaves k_j, the count of pointers below cdf[j]
    cnt[0] = k[0]
    for j in range(1, N):
        cnt[j] = k[j] - k[j - 1]  # offspring of particle j
    weighted_moments_run(x, b, cnt, mean, cov)
    return True


@njit(**FMA)
def resample(
    logw: np.ndarray,
    u: np.ndarray,
    x: np.ndarray,
    anc: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
    ok: np.ndarray,
) -> int:
    """Normalise exp(logw) per run and resample systematically with offset u[b]: the ancestors go
    to anc (B, N + 1; the last column is scratch), and the resampled cloud's mean (B, n) and
    covariance (B, n, n) to mean and cov. The cloud itself is not gathered here (the next predict
    reads through anc; :func:`~tltrack.filters.kernels.propagation.gather` makes it on request).
    ``logw`` is overwritten.

    ok[b] is False, and anc[b], mean[b], cov[b] meaningless, for a run whose weights are not finite
    (a NaN log-weight, or all -inf). Returns the count of runs that are ok.
    """
    cnt = np.empty(x.shape[2])
    good = 0
    for b in range(x.shape[1]):
        ok[b] = resample_run(logw[b], u[b], x, b, anc[b], cnt, mean, cov)
        good += ok[b]
    return good
