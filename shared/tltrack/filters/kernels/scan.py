"""A dense scan's likelihood for each particle of one run, through a grid of the detections.

A scan of thousands of detections spread over a cloud's extent would cost N x M Gaussian terms;
but each particle's sum over detections (:mod:`tltrack.filters.association`) only needs those
within a box of ``half`` noise standard deviations of its predicted measurement, a handful. The
scan is first cut to the detections within reach of the cloud at all. They are bucketed once
into a grid on their first two components (one for a one-component sensor), in cells ``1 / SUB``
of the box's half-width, in row-major order: the cells a particle's box touches in one row hold
a contiguous run of detections, so a particle reads a few runs, about as many detections as its
box holds, and the box test leaves exactly those.

Each block of particles is done in two passes: the first gathers the Mahalanobis distance q of
every (particle, detection) pair in a box into a buffer, storing each pair it reads and moving
on only past those inside (no branch to mispredict: about a third of the pairs read are outside);
the second turns the buffer into exp(-q/2), a branch-free loop that vectorises (see the package's
docstring), and sums each particle's share in gathering order.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tltrack.filters.kernels.fastmath import FMA, JIT, exp

#: the grid holds at most this many cells; a finer one is coarsened
MAX_CELLS = 1 << 20
#: cells per half-width of a particle's box, on each grid axis
SUB = 2
#: particles per block of the two passes (its buffer stays in cache)
BLOCK = 512
_TWO_PI = 6.28318530717958647693e00
_INV_TWO_PI = 1.0 / _TWO_PI


@njit(**JIT)
def _wrap(d: float) -> float:
    """An angle's difference d, into [-pi, pi)."""
    return d - _TWO_PI * np.floor((d + np.pi) * _INV_TWO_PI)


@njit(**JIT)
def _span(p: float, reach: float, cells: int, cyclic: bool, out: np.ndarray) -> int:
    """The cells within ``reach`` of grid coordinate p, as at most two ranges [out[0], out[1]]
    and [out[2], out[3]] (two when a cyclic axis wraps round); the number of ranges."""
    p = min(max(p, -reach - 2.0), cells + reach + 2.0)  # far outside: no overflow in the cast
    a = int(np.floor(p - reach))
    b = int(np.floor(p + reach))
    if cyclic:
        if b - a + 1 >= cells:
            out[0], out[1] = 0, cells - 1
            return 1
        if a < 0 or b >= cells:
            a %= cells
            b %= cells
        if a <= b:
            out[0], out[1] = a, b
            return 1
        out[0], out[1], out[2], out[3] = a, cells - 1, 0, b
        return 2
    a = max(a, 0)
    b = min(b, cells - 1)
    if a > b:
        return 0
    out[0], out[1] = a, b
    return 1


@njit(**FMA)
def _exp_half(q: np.ndarray, m: int) -> None:
    """q[:m] = exp(-q[:m] / 2), vectorised."""
    for i in range(m):
        q[i] = exp(-0.5 * q[i])


@njit(**JIT)
def _near_cloud(Zx: np.ndarray, Z: np.ndarray, angular: np.ndarray, half: np.ndarray) -> np.ndarray:
    """The detections (n_z, M') within ``half`` of some particle's box: those whose residual to a
    reference particle is within the cloud's extent about it plus ``half``, in every component
    (on the circle too: the circular distance obeys the triangle inequality). None of them when
    no particle's predicted measurement is finite."""
    n_z, N = Zx.shape
    ref = -1
    for n in range(N):
        finite = True
        for c in range(n_z):
            finite &= np.isfinite(Zx[c, n])
        if finite:
            ref = n
            break
    if ref < 0:
        return Z[:, :0]
    reach = np.zeros(n_z)
    for n in range(N):
        for c in range(n_z):
            v = Zx[c, n] - Zx[c, ref]
            v = abs(_wrap(v) if angular[c] else v)
            if v > reach[c]:  # False for NaN: a particle with no measurement widens nothing
                reach[c] = v
    keep = np.empty(Z.shape[1], dtype=np.int64)
    m = 0
    for j in range(Z.shape[1]):
        inside = True
        for c in range(n_z):
            v = Z[c, j] - Zx[c, ref]
            inside &= abs(_wrap(v) if angular[c] else v) <= reach[c] + half[c]
        keep[m] = j
        m += inside
    out = np.empty((n_z, m))
    for t in range(m):
        for c in range(n_z):
            out[c, t] = Z[c, keep[t]]
    return out


@njit(**JIT)
def _grid(
    Z: np.ndarray, angular: np.ndarray, half: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The detections (n_z, M) in cell order, each cell's first index (``start``, one past the
    last cell too), and the grid's origin, cell widths, cell counts and the box's reach in cells.
    An angle's axis covers [-pi, pi] and goes round."""
    n_z, M = Z.shape
    d = 2 if n_z >= 2 else 1
    lo = np.zeros(2)
    width = np.ones(2)
    cells = np.ones(2, dtype=np.int64)
    for c in range(d):
        if angular[c]:
            lo[c] = -np.pi
            cells[c] = max(int(_TWO_PI / (half[c] / SUB)), 1)
            width[c] = _TWO_PI / cells[c]
        elif M:
            lo[c] = Z[c].min()
            width[c] = half[c] / SUB
            cells[c] = int((Z[c].max() - lo[c]) / width[c]) + 1
    while cells[0] * cells[1] > MAX_CELLS:
        for c in range(d):
            cells[c] = (cells[c] + 1) // 2
            width[c] = _TWO_PI / cells[c] if angular[c] else 2.0 * width[c]
    reach = np.zeros(2)
    for c in range(d):
        reach[c] = half[c] / width[c]
    key = np.empty(M, dtype=np.int64)
    for j in range(M):
        k0 = min(int((Z[0, j] - lo[0]) / width[0]), cells[0] - 1)
        k1 = min(int((Z[1, j] - lo[1]) / width[1]), cells[1] - 1) if d == 2 else 0
        key[j] = k0 * cells[1] + k1
    order = np.argsort(key)
    Zs = np.empty((n_z, M))
    for t in range(M):
        for c in range(n_z):
            Zs[c, t] = Z[c, order[t]]
    start = np.zeros(cells[0] * cells[1] + 1, dtype=np.int64)
    for j in range(M):
        start[key[j] + 1] += 1
    for i in range(1, start.shape[0]):
        start[i] += start[i - 1]
    return Zs, start, lo, width, cells, reach


@njit(**JIT)
def scan_loglik(
    Zx: np.ndarray,
    Z: np.ndarray,
    angular: np.ndarray,
    Ri: np.ndarray,
    half: np.ndarray,
    floor: np.ndarray,
    weight: np.ndarray,
    out: np.ndarray,
) -> None:
    """out[n] = log(floor[n] + weight[n] sum_j exp(-q_nj / 2)) over the detections j whose
    residual to particle n is within ``half`` in every component, q_nj its Mahalanobis
    distance; -inf where that is 0. With floor = lambda_c (1 - pd(x)) and weight = pd(x) times
    N's constant, it is the scan's log-likelihood (:mod:`tltrack.filters.association`).

    ``Zx`` (n_z, N) holds the particles' predicted measurements and ``Z`` (n_z, M) the
    detections, angles in [-pi, pi]. ``Ri`` is R^-1.
    """
    n_z, N = Zx.shape
    Z = _near_cloud(Zx, Z, angular, half)
    M = Z.shape[1]
    two = n_z == 2  # the common layout, unrolled
    d = 2 if n_z >= 2 else 1
    Zs, start, lo, width, cells, reach = _grid(Z, angular, half)
    c0, c1 = cells[0], cells[1]
    cyclic0, cyclic1 = bool(angular[0]), d == 2 and bool(angular[1])
    a0 = bool(angular[0])
    a1 = bool(angular[1]) if two else False
    h0 = half[0]
    h1 = half[1] if two else 0.0
    r00 = Ri[0, 0]
    r01 = 2.0 * Ri[0, 1] if two else 0.0
    r11 = Ri[1, 1] if two else 0.0
    rows = np.zeros(4, dtype=np.int64)
    cols = np.zeros(4, dtype=np.int64)
    r = np.empty(n_z)
    q = np.empty(64 * BLOCK)  # grown when a block's pairs need more
    ends = np.zeros(BLOCK + 1, dtype=np.int64)
    for n0 in range(0, N, BLOCK):
        n1 = min(n0 + BLOCK, N)
        m = 0
        for n in range(n0, n1):
            if m + M > q.shape[0]:  # a particle reads each detection at most once
                grown = np.empty(2 * (m + M))
                grown[:m] = q[:m]
                q = grown
            x0 = Zx[0, n]
            x1 = Zx[1, n] if d == 2 else 0.0
            p0 = (x0 - lo[0]) / width[0]
            p1 = (x1 - lo[1]) / width[1]
            if np.isfinite(p0) and np.isfinite(p1):
                nr = _span(p0, reach[0], c0, cyclic0, rows)
                nc = _span(p1, reach[1], c1, cyclic1, cols) if d == 2 else 1
                for ra in range(nr):
                    for a in range(rows[2 * ra], rows[2 * ra + 1] + 1):
                        for cb in range(nc):
                            t0 = start[a * c1 + cols[2 * cb]]
                            t1 = start[a * c1 + cols[2 * cb + 1] + 1]
                            if two:
                                for t in range(t0, t1):
                                    v0 = Zs[0, t] - x0
                                    v1 = Zs[1, t] - x1
                                    v0 = _wrap(v0) if a0 else v0
                                    v1 = _wrap(v1) if a1 else v1
                                    # kept (m moves on) only inside the box: no branch
                                    q[m] = v0 * v0 * r00 + v0 * v1 * r01 + v1 * v1 * r11
                                    m += (abs(v0) <= h0) & (abs(v1) <= h1)
                                continue
                            for t in range(t0, t1):
                                inside = True
                                for c in range(n_z):
                                    v = Zs[c, t] - Zx[c, n]
                                    r[c] = _wrap(v) if angular[c] else v
                                    inside &= abs(r[c]) <= half[c]
                                if inside:
                                    s = 0.0
                                    for c in range(n_z):
                                        for e in range(n_z):
                                            s += r[c] * Ri[c, e] * r[e]
                                    q[m] = s
                                    m += 1
            ends[n - n0 + 1] = m
        _exp_half(q, m)
        for n in range(n0, n1):
            s = 0.0
            for i in range(ends[n - n0], ends[n - n0 + 1]):
                s += q[i]
            v = floor[n] + weight[n] * s
            out[n] = np.log(v) if v > 0.0 else -np.inf
