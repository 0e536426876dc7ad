"""The detections near each particle of a dense scan, found through a grid, and their likelihood.

A scan of thousands of detections spread over a cloud's extent would cost N x M Gaussian terms;
but each particle's sum over detections (:mod:`tltrack.filters.association`) only needs those
within a box of ``half`` noise standard deviations of its predicted measurement, a handful. The
detections are bucketed once into a grid on their first two components (one for a one-component
sensor) with cells as wide as the box's half-width, so a particle reads the 3 x 3 cells around
its own and tests only what they hold.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tltrack.filters.kernels.fastmath import FMA, JIT, exp

#: the grid holds at most this many cells; a finer one is coarsened
MAX_CELLS = 1 << 20


@njit(**JIT)
def _wrap(d: float) -> float:
    return d - 2.0 * np.pi * np.floor((d + np.pi) / (2.0 * np.pi))


@njit(**JIT)
def _neighbour(i: int, t: int, cells: int, cyclic: bool) -> int:
    """The t-th (0, 1, 2) of the cells i - 1, i, i + 1, or -1 where there is none; round the
    circle if ``cyclic`` (an axis of fewer than 3 cells: each of its cells once)."""
    if cyclic:
        if cells < 3:
            return t if t < cells else -1
        return (i - 1 + t) % cells
    a = i - 1 + t
    return a if 0 <= a < cells else -1


@njit(**JIT)
def _cell(p: float, cells: int, cyclic: bool) -> int:
    """The cell of grid coordinate p; far outside the grid, clipped before the cast (its
    neighbourhood is then empty, unless the axis goes round)."""
    i = int(np.floor(min(max(p, -2.0), cells + 1.0)))
    return min(max(i, 0), cells - 1) if cyclic else i


@njit(**FMA)
def _cell_sum(
    Zs: np.ndarray,
    t0: int,
    t1: int,
    Zx: np.ndarray,
    n: int,
    angular: np.ndarray,
    Ri: np.ndarray,
    half: np.ndarray,
    r: np.ndarray,
) -> float:
    """sum of exp(-q/2) over detections t0..t1 of Zs within ``half`` of particle n, q the
    Mahalanobis distance of the residual r (scratch, n_z)."""
    n_z = Zs.shape[0]
    s = 0.0
    for t in range(t0, t1):
        inside = True
        for c in range(n_z):
            v = Zs[c, t] - Zx[c, n]
            r[c] = _wrap(v) if angular[c] else v
            inside &= abs(r[c]) <= half[c]
        if inside:
            q = 0.0
            for c in range(n_z):
                for e in range(n_z):
                    q += r[c] * Ri[c, e] * r[e]
            s += exp(-0.5 * q)  # q is bounded by the box: no underflow
    return s


@njit(**FMA)
def _cell_sum2(
    Zs: np.ndarray,
    t0: int,
    t1: int,
    x0: float,
    x1: float,
    a0: bool,
    a1: bool,
    Ri: np.ndarray,
    h0: float,
    h1: float,
) -> float:
    """:func:`_cell_sum` for two components, unrolled."""
    r00, r01, r11 = Ri[0, 0], 2.0 * Ri[0, 1], Ri[1, 1]
    s = 0.0
    for t in range(t0, t1):
        v0 = Zs[0, t] - x0
        v1 = Zs[1, t] - x1
        v0 = _wrap(v0) if a0 else v0
        v1 = _wrap(v1) if a1 else v1
        if abs(v0) <= h0 and abs(v1) <= h1:
            s += np.exp(-0.5 * (v0 * v0 * r00 + v0 * v1 * r01 + v1 * v1 * r11))
    return s


@njit(**JIT)
def near_loglik(
    Zx: np.ndarray,
    Z: np.ndarray,
    angular: np.ndarray,
    Ri: np.ndarray,
    half: np.ndarray,
    lognorm: float,
    out: np.ndarray,
) -> None:
    """out[n] = log sum_j N(z_j; h(x_n), R) over the detections j whose residual to particle n
    is within ``half`` in every component; -inf when none is.

    ``Zx`` (n_z, N) holds the particles' predicted measurements and ``Z`` (n_z, M) the
    detections, angles in [-pi, pi]; an angle's grid axis goes round the circle. ``Ri`` is
    R^-1, ``lognorm`` log N's constant.
    """
    n_z, N = Zx.shape
    M = Z.shape[1]
    d = 2 if n_z >= 2 else 1
    lo = np.zeros(2)
    width = np.ones(2)
    cells = np.ones(2, dtype=np.int64)
    for c in range(d):
        if angular[c]:
            lo[c] = -np.pi
            cells[c] = max(int(2.0 * np.pi / half[c]), 1)
            width[c] = 2.0 * np.pi / cells[c]
        elif M:
            lo[c] = Z[c].min()
            width[c] = half[c]
            cells[c] = int((Z[c].max() - lo[c]) / width[c]) + 1
    while cells[0] * cells[1] > MAX_CELLS:
        for c in range(d):
            cells[c] = (cells[c] + 1) // 2
            width[c] = 2.0 * np.pi / cells[c] if angular[c] else 2.0 * width[c]
    key = np.empty(M, dtype=np.int64)
    for j in range(M):
        k0 = min(int((Z[0, j] - lo[0]) / width[0]), cells[0] - 1)
        k1 = min(int((Z[1, j] - lo[1]) / width[1]), cells[1] - 1) if d == 2 else 0
        key[j] = k0 * cells[1] + k1
    order = np.argsort(key)
    Zs = np.empty((n_z, M))  # the detections in cell order: a cell's are contiguous
    for t in range(M):
        for c in range(n_z):
            Zs[c, t] = Z[c, order[t]]
    start = np.zeros(cells[0] * cells[1] + 1, dtype=np.int64)
    for j in range(M):
        start[key[j] + 1] += 1
    for i in range(1, start.shape[0]):
        start[i] += start[i - 1]
    cyclic1 = d == 2 and angular[1]
    r = np.empty(n_z)
    for n in range(N):
        s = 0.0
        p0 = (Zx[0, n] - lo[0]) / width[0]
        p1 = (Zx[1, n] - lo[1]) / width[1] if d == 2 else 0.0
        if not (np.isfinite(p0) and np.isfinite(p1)):
            out[n] = -np.inf
            continue
        i0 = _cell(p0, cells[0], angular[0])
        i1 = _cell(p1, cells[1], cyclic1)
        for ta in range(3):
            a = _neighbour(i0, ta, cells[0], angular[0])
            if a < 0:
                continue
            for tb in range(3):
                b = _neighbour(i1, tb, cells[1], cyclic1)
                if b < 0:
                    continue
                cell = a * cells[1] + b
                t0, t1 = start[cell], start[cell + 1]
                if n_z == 2:
                    x0, x1 = Zx[0, n], Zx[1, n]
                    a0, a1 = angular[0], angular[1]
                    s += _cell_sum2(Zs, t0, t1, x0, x1, a0, a1, Ri, half[0], half[1])
                else:
                    s += _cell_sum(Zs, t0, t1, Zx, n, angular, Ri, half, r)
        out[n] = lognorm + np.log(s) if s > 0.0 else -np.inf
