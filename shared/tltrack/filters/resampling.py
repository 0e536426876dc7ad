"""Systematic resampling (Kitagawa 1996), batched over runs.

One uniform u ~ U[0, 1) per run places N evenly spaced pointers (u + i) / N on that run's weight
CDF. Each run is searched on its own, so a run's ancestors never depend on the batch around it.

The search is O(N) and branch-free (numba), instead of ``cumsum`` + ``searchsorted``'s
O(N log N): the ancestor of pointer p is the first j whose cumulative weight exceeds p (as
``searchsorted(..., side="right")`` finds it), so a zero-weight particle is never chosen.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit
from numpy.typing import NDArray


@njit(cache=True, nogil=True, error_model="numpy")
def systematic_walk(w: np.ndarray, u: float, idx: np.ndarray) -> bool:
    """Ancestors idx[:N] of unnormalised weights w[:N] for the offset u in [0, 1).

    Pointer i sits at p_i = (u + i) * total / N and descends from the first j with cdf[j] > p_i
    (or, should rounding put p_i at or past the total, from the first j whose cdf[j] is the total:
    never from a particle of zero weight).
    ``idx`` needs N + 1 entries. ``w``'s memory is left holding, as int64 (``w.view(np.int64)``),
    k_j = #{i : p_i < cdf[j]}: particle j has k_j - k_{j-1} offspring. Returns False, leaving
    ``idx`` and ``w`` meaningless, when the total is not a positive finite number (a NaN weight).

    Branch-free, so its speed does not depend on the weights (a pointer-by-pointer walk
    mispredicts a branch per particle on real, ever-changing weights): particle j owns the
    pointers [k_{j-1}, k_j), k_j = #{i : p_i < cdf[j]}; writing j at slot k_{j-1} for every j in
    order and taking the running maximum gives every pointer its ancestor.
    """
    N = w.shape[0]
    for i in range(1, N):
        w[i] += w[i - 1]
    total = w[N - 1]
    if not (total > 0.0 and total < np.inf):
        return False
    step = total / N
    fN = float(N)
    k = w.view(np.int64)  # k_j replaces cdf[j] in place
    for j in range(N):
        c = w[j]
        kj = min(max(np.ceil(c / step - u), 0.0), fN)
        # ceil can miss by one where c / step - u is within rounding of an integer: check p_i
        below = (u + (kj - 1.0)) * step >= c
        above = (u + kj) * step < c
        kj = kj - 1.0 if below and kj > 0.0 else kj  # (rare: predictable branches)
        kj = kj + 1.0 if above and kj < fN else kj
        kj = fN if c >= total else kj  # a pointer rounded past the total: the last live particle
        k[j] = np.int64(kj)
    idx[: N + 1] = 0
    prev = 0
    for j in range(N):
        idx[prev] = j  # a later j at the same slot (j had no offspring) overwrites it
        prev = k[j]
    _running_max(idx, N)
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def _running_max(a: np.ndarray, N: int) -> None:
    """a[:N] = its running maximum, for non-negative int64 entries.

    Four interleaved chains (max by bit arithmetic, so no branch mispredicts), then a vectorised
    pass carries each quarter's maximum into the next.
    """
    Q = N // 4
    m0 = m1 = m2 = m3 = 0
    for t in range(Q):
        d = a[t] - m0
        m0 += d & ~(d >> 63)
        a[t] = m0
        d = a[Q + t] - m1
        m1 += d & ~(d >> 63)
        a[Q + t] = m1
        d = a[2 * Q + t] - m2
        m2 += d & ~(d >> 63)
        a[2 * Q + t] = m2
        d = a[3 * Q + t] - m3
        m3 += d & ~(d >> 63)
        a[3 * Q + t] = m3
    for t in range(4 * Q, N):
        d = a[t] - m3
        m3 += d & ~(d >> 63)
        a[t] = m3
    carry = 0
    for q in range(1, 4):
        carry = max(carry, a[q * Q - 1]) if Q > 0 else carry
        hi = N if q == 3 else (q + 1) * Q
        for t in range(q * Q, hi):
            v = a[t]
            a[t] = v if v > carry else carry


@njit(cache=True, nogil=True, error_model="numpy")
def _systematic_batch(w: np.ndarray, u: np.ndarray, idx: np.ndarray) -> bool:
    N = w.shape[1]
    scratch = np.empty(N)
    anc = np.empty(N + 1, dtype=np.int64)
    for b in range(w.shape[0]):
        scratch[:] = w[b]
        if not systematic_walk(scratch, u[b], anc):
            return False
        idx[b] = anc[:N]
    return True


def systematic_indices(
    w: NDArray[np.float64], rngs: Sequence[np.random.Generator]
) -> NDArray[np.intp]:
    """Ancestor indices (B, N) for weights ``w`` (B, N), one draw from each run's stream.

    The weights need not be normalised; each row must have a positive, finite sum.
    """
    B, N = w.shape
    u = np.array([g.random() for g in rngs])
    idx = np.empty((B, N), dtype=np.intp)
    if not _systematic_batch(np.ascontiguousarray(w, dtype=np.float64), u, idx):
        raise ValueError("every run's weights must have a positive, finite sum")
    return idx
