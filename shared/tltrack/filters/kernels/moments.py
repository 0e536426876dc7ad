"""The mean and covariance of a particle cloud, as the filter reports them.

Two passes (mean, then centred products), normalised by N; the 5-state case unrolled into single
loops. The weighted variant counts particle j ``cnt[j]`` times: the resampled cloud's moments
without gathering it. :func:`spread_coordinates` says which coordinates of such a covariance
have spread at all (a collapsed cloud's is singular).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tltrack.filters.kernels.fastmath import FMA, JIT, SUM


@njit(**SUM)
def _moments_run(x: np.ndarray, b: int, mean: np.ndarray, cov: np.ndarray) -> None:
    """Two-pass sample mean and covariance (normalised by N) of run b's cloud x[:, b, :]."""
    n, _, N = x.shape
    if n == 5:
        _moments5(x, b, mean, cov)
        return
    for k in range(n):
        s = 0.0
        for i in range(N):
            s += x[k, b, i]
        mean[b, k] = s / N
    for k in range(n):
        mk = mean[b, k]
        for j in range(k + 1):
            mj = mean[b, j]
            s = 0.0
            for i in range(N):
                s += (x[k, b, i] - mk) * (x[j, b, i] - mj)
            cov[b, k, j] = s / N
            cov[b, j, k] = s / N


@njit(**SUM)
def _moments5(x: np.ndarray, b: int, mean: np.ndarray, cov: np.ndarray) -> None:
    """:func:`_moments_run` for n = 5, each pass a single loop."""
    N = x.shape[2]
    s0 = s1 = s2 = s3 = s4 = 0.0
    for i in range(N):
        s0 += x[0, b, i]
        s1 += x[1, b, i]
        s2 += x[2, b, i]
        s3 += x[3, b, i]
        s4 += x[4, b, i]
    m0, m1, m2, m3, m4 = s0 / N, s1 / N, s2 / N, s3 / N, s4 / N
    c00 = c10 = c11 = c20 = c21 = c22 = c30 = c31 = c32 = c33 = 0.0
    c40 = c41 = c42 = c43 = c44 = 0.0
    for i in range(N):
        d0 = x[0, b, i] - m0
        d1 = x[1, b, i] - m1
        d2 = x[2, b, i] - m2
        d3 = x[3, b, i] - m3
        d4 = x[4, b, i] - m4
        c00 += d0 * d0
        c10 += d1 * d0
        c11 += d1 * d1
        c20 += d2 * d0
        c21 += d2 * d1
        c22 += d2 * d2
        c30 += d3 * d0
        c31 += d3 * d1
        c32 += d3 * d2
        c33 += d3 * d3
        c40 += d4 * d0
        c41 += d4 * d1
        c42 += d4 * d2
        c43 += d4 * d3
        c44 += d4 * d4
    mean[b, 0], mean[b, 1], mean[b, 2], mean[b, 3], mean[b, 4] = m0, m1, m2, m3, m4
    c = cov[b]
    c[0, 0] = c00 / N
    c[1, 1] = c11 / N
    c[2, 2] = c22 / N
    c[3, 3] = c33 / N
    c[4, 4] = c44 / N
    c[1, 0] = c[0, 1] = c10 / N
    c[2, 0] = c[0, 2] = c20 / N
    c[2, 1] = c[1, 2] = c21 / N
    c[3, 0] = c[0, 3] = c30 / N
    c[3, 1] = c[1, 3] = c31 / N
    c[3, 2] = c[2, 3] = c32 / N
    c[4, 0] = c[0, 4] = c40 / N
    c[4, 1] = c[1, 4] = c41 / N
    c[4, 2] = c[2, 4] = c42 / N
    c[4, 3] = c[3, 4] = c43 / N


@njit(**FMA)
def moments(x: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> None:
    """Sample mean (B, n) and covariance (B, n, n), normalised by N, of the clouds x (n, B, N)."""
    for b in range(x.shape[1]):
        _moments_run(x, b, mean, cov)


@njit(**SUM)
def weighted_moments_run(
    x: np.ndarray, b: int, cnt: np.ndarray, mean: np.ndarray, cov: np.ndarray
) -> None:
    """Mean and covariance (normalised by sum(cnt) = N) of the cloud where particle j of run b
    appears cnt[j] times: the resampled cloud's moments without gathering it."""
    n, _, N = x.shape
    if n == 5:
        _weighted_moments5(x, b, cnt, mean, cov)
        return
    for k in range(n):
        s = 0.0
        for j in range(N):
            s += cnt[j] * x[k, b, j]
        mean[b, k] = s / N
    for k in range(n):
        mk = mean[b, k]
        for q in range(k + 1):
            mq = mean[b, q]
            s = 0.0
            for j in range(N):
                s += cnt[j] * ((x[k, b, j] - mk) * (x[q, b, j] - mq))
            cov[b, k, q] = s / N
            cov[b, q, k] = s / N


@njit(**SUM)
def _weighted_moments5(
    x: np.ndarray, b: int, cnt: np.ndarray, mean: np.ndarray, cov: np.ndarray
) -> None:
    """:func:`weighted_moments_run` for n = 5, each pass a single loop."""
    N = x.shape[2]
    s0 = s1 = s2 = s3 = s4 = 0.0
    for j in range(N):
        c = cnt[j]
        s0 += c * x[0, b, j]
        s1 += c * x[1, b, j]
        s2 += c * x[2, b, j]
        s3 += c * x[3, b, j]
        s4 += c * x[4, b, j]
    m0, m1, m2, m3, m4 = s0 / N, s1 / N, s2 / N, s3 / N, s4 / N
    c00 = c10 = c11 = c20 = c21 = c22 = c30 = c31 = c32 = c33 = 0.0
    c40 = c41 = c42 = c43 = c44 = 0.0
    for j in range(N):
        c = cnt[j]
        d0 = x[0, b, j] - m0
        d1 = x[1, b, j] - m1
        d2 = x[2, b, j] - m2
        d3 = x[3, b, j] - m3
        d4 = x[4, b, j] - m4
        e0 = c * d0
        e1 = c * d1
        e2 = c * d2
        e3 = c * d3
        e4 = c * d4
        c00 += e0 * d0
        c10 += e1 * d0
        c11 += e1 * d1
        c20 += e2 * d0
        c21 += e2 * d1
        c22 += e2 * d2
        c30 += e3 * d0
        c31 += e3 * d1
        c32 += e3 * d2
        c33 += e3 * d3
        c40 += e4 * d0
        c41 += e4 * d1
        c42 += e4 * d2
        c43 += e4 * d3
        c44 += e4 * d4
    mean[b, 0], mean[b, 1], mean[b, 2], mean[b, 3], mean[b, 4] = m0, m1, m2, m3, m4
    C = cov[b]
    C[0, 0] = c00 / N
    C[1, 1] = c11 / N
    C[2, 2] = c22 / N
    C[3, 3] = c33 / N
    C[4, 4] = c44 / N
    C[1, 0] = C[0, 1] = c10 / N
    C[2, 0] = C[0, 2] = c20 / N
    C[2, 1] = C[1, 2] = c21 / N
    C[3, 0] = C[0, 3] = c30 / N
    C[3, 1] = C[1, 3] = c31 / N
    C[3, 2] = C[2, 3] = c32 / N
    C[4, 0] = C[0, 4] = c40 / N
    C[4, 1] = C[1, 4] = c41 / N
    C[4, 2] = C[2, 4] = c42 / N
    C[4, 3] = C[3, 4] = c43 / N


@njit(**JIT)
def spread_coordinates(P: np.ndarray, rcond: float) -> np.ndarray:
    """The coordinates (B, n) a diagonally pivoted LDL' of each P[b] keeps: in turn, the one with
    the most variance left given those kept so far, while that is over ``rcond`` times P[b]'s
    largest variance.

    Plain arithmetic, no contraction and no eigensolver (whose last bits follow the LAPACK
    kernels picked at run time), so every machine with the same CPU keeps the same coordinates.
    """
    B, n, _ = P.shape
    keep = np.zeros((B, n), dtype=np.bool_)
    S = np.empty((n, n))
    col = np.empty(n)
    for b in range(B):
        S[:, :] = P[b]
        tol = P[b, 0, 0]
        for i in range(1, n):
            tol = max(tol, P[b, i, i])
        tol *= rcond
        for _ in range(n):
            j, pivot = -1, -np.inf
            for i in range(n):
                if not keep[b, i] and S[i, i] > pivot:
                    j, pivot = i, S[i, i]
            if not pivot > tol:
                break
            col[:] = S[:, j]
            for r in range(n):
                for c in range(n):
                    S[r, c] -= col[r] * col[c] / pivot
            keep[b, j] = True
    return keep
