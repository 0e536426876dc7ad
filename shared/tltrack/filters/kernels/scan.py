"""A dense scan's likelihood for each particle of one run, through a grid of the particles.

A scan of thousands of detections spread over a cloud's extent would cost N x M Gaussian terms;
but each particle's sum over detections (:mod:`tltrack.filters.association`) only needs those
within a box of ``half`` noise standard deviations of its predicted measurement, a handful. The
scan is first cut to the detections within reach of the cloud at all. The particles are then
sorted (a counting sort) into a grid on their predicted measurements' first two components (one
for a one-component sensor), in cells ``1 / SUB`` of the box's half-width, row-major: the cells
that a detection's box touches in one row hold a contiguous run of particles. Each detection adds
exp(-q/2) to every particle of those runs that has it inside its box (q the Mahalanobis
distance), in a branch-free loop over the run that vectorises (see the package's docstring);
the runs hold about 1.5 times the particles in the box. A cloud that keeps its track is dense,
its runs long; a lost one is spread thin, and its runs short.

Going detection by detection rather than particle by particle is what lets the loop vectorise:
a particle has a handful of detections near it, a detection has the cloud's particles near it.
Each particle's sum is in the detections' order, whatever the grid.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tltrack.filters.kernels.fastmath import FMA, JIT, TWO_PI, exp

#: the grid holds at most this many cells; a finer one is coarsened
MAX_CELLS = 1 << 20
#: cells per half-width of a particle's box, on each grid axis
SUB = 2
_INV_TWO_PI = 1.0 / TWO_PI


@njit(**JIT)
def _wrap(d: float) -> float:
    """An angle's difference d, into [-pi, pi)."""
    return d - TWO_PI * np.floor((d + np.pi) * _INV_TWO_PI)


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


@njit(**JIT)
def _near_cloud(P: np.ndarray, Z: np.ndarray, angular: np.ndarray, half: np.ndarray) -> np.ndarray:
    """The detections (n_z, M') within ``half`` of some particle's box: those whose residual to a
    reference particle (the first) is within the cloud's extent about it plus ``half``, in every
    component (on the circle too: the circular distance obeys the triangle inequality). ``P``
    (n_z, N') holds the predicted measurements of the particles that have one (finite); none of
    the detections when no particle has."""
    n_z, N = Z.shape[0], P.shape[1]
    if N == 0:
        return Z[:, :0]
    reach = np.zeros(n_z)
    for n in range(N):
        for c in range(n_z):
            v = P[c, n] - P[c, 0]
            reach[c] = max(reach[c], abs(_wrap(v) if angular[c] else v))
    keep = np.empty(Z.shape[1], dtype=np.int64)
    m = 0
    for j in range(Z.shape[1]):
        inside = True
        for c in range(n_z):
            v = Z[c, j] - P[c, 0]
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
    Zx: np.ndarray, angular: np.ndarray, half: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The particles with a finite predicted measurement, in cell order: their measurements
    ``P`` (at least 2 rows, a one-component sensor's second 0) and indices ``order``; each
    cell's first position (``start``, one past the last cell too); the grid's origin, cell
    widths, cell counts and a box's reach in cells. An angle's axis covers [-pi, pi] and goes
    round."""
    n_z, N = Zx.shape
    d = 2 if n_z >= 2 else 1
    finite = np.empty(N, dtype=np.int64)
    n_f = 0
    for n in range(N):
        ok = True
        for c in range(n_z):
            ok &= np.isfinite(Zx[c, n])
        finite[n_f] = n
        n_f += ok
    lo = np.zeros(2)
    width = np.ones(2)
    cells = np.ones(2, dtype=np.int64)
    for c in range(d):
        if angular[c]:
            lo[c] = -np.pi
            cells[c] = max(int(TWO_PI / (half[c] / SUB)), 1)
            width[c] = TWO_PI / cells[c]
        elif n_f:
            lo[c], hi = np.inf, -np.inf
            for t in range(n_f):
                lo[c] = min(lo[c], Zx[c, finite[t]])
                hi = max(hi, Zx[c, finite[t]])
            width[c] = half[c] / SUB
            cells[c] = int((hi - lo[c]) / width[c]) + 1
    while cells[0] * cells[1] > MAX_CELLS:
        for c in range(d):
            cells[c] = (cells[c] + 1) // 2
            width[c] = TWO_PI / cells[c] if angular[c] else 2.0 * width[c]
    reach = np.zeros(2)
    for c in range(d):
        reach[c] = half[c] / width[c]
    key = np.empty(n_f, dtype=np.int64)
    start = np.zeros(cells[0] * cells[1] + 1, dtype=np.int64)
    for t in range(n_f):
        n = finite[t]
        k0 = min(int((Zx[0, n] - lo[0]) / width[0]), cells[0] - 1)
        k1 = min(int((Zx[1, n] - lo[1]) / width[1]), cells[1] - 1) if d == 2 else 0
        key[t] = k0 * cells[1] + k1
        start[key[t] + 1] += 1
    for i in range(1, start.shape[0]):
        start[i] += start[i - 1]
    fill = start[:-1].copy()
    order = np.empty(n_f, dtype=np.int64)
    for t in range(n_f):
        order[fill[key[t]]] = finite[t]
        fill[key[t]] += 1
    P = np.zeros((max(n_z, 2), n_f))
    for t in range(n_f):
        for c in range(n_z):
            P[c, t] = Zx[c, order[t]]
    return P, order, start, lo, width, cells, reach


@njit(**FMA)
def _add2(
    p0: np.ndarray,
    p1: np.ndarray,
    acc: np.ndarray,
    z: np.ndarray,
    angular: np.ndarray,
    half: np.ndarray,
    Ri: np.ndarray,
) -> None:
    """acc += exp(-q/2) for the particles (p0, p1) that have the two-component detection z in
    their box, q its Mahalanobis distance; the others get 0."""
    z0, z1, a0, a1, h0, h1 = z[0], z[1], angular[0], angular[1], half[0], half[1]
    r00, r01, r11 = Ri[0, 0], 2.0 * Ri[0, 1], Ri[1, 1]
    for i in range(acc.shape[0]):
        v0 = z0 - p0[i]
        v1 = z1 - p1[i]
        v0 = _wrap(v0) if a0 else v0
        v1 = _wrap(v1) if a1 else v1
        e = exp(-0.5 * (v0 * v0 * r00 + v0 * v1 * r01 + v1 * v1 * r11))
        acc[i] += e if (abs(v0) <= h0) & (abs(v1) <= h1) else 0.0


@njit(**FMA)
def _add3(
    p0: np.ndarray,
    p1: np.ndarray,
    p2: np.ndarray,
    acc: np.ndarray,
    z: np.ndarray,
    angular: np.ndarray,
    half: np.ndarray,
    Ri: np.ndarray,
) -> None:
    """:func:`_add2` for three components."""
    z0, z1, z2, a0, a1, a2 = z[0], z[1], z[2], angular[0], angular[1], angular[2]
    h0, h1, h2 = half[0], half[1], half[2]
    r00, r11, r22 = Ri[0, 0], Ri[1, 1], Ri[2, 2]
    r01, r02, r12 = 2.0 * Ri[0, 1], 2.0 * Ri[0, 2], 2.0 * Ri[1, 2]
    for i in range(acc.shape[0]):
        v0 = z0 - p0[i]
        v1 = z1 - p1[i]
        v2 = z2 - p2[i]
        v0 = _wrap(v0) if a0 else v0
        v1 = _wrap(v1) if a1 else v1
        v2 = _wrap(v2) if a2 else v2
        q = v0 * (v0 * r00 + v1 * r01 + v2 * r02) + v1 * (v1 * r11 + v2 * r12) + v2 * v2 * r22
        acc[i] += exp(-0.5 * q) if (abs(v0) <= h0) & (abs(v1) <= h1) & (abs(v2) <= h2) else 0.0


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

    ``Zx`` (n_z, N), n_z <= 3, holds the particles' predicted measurements and ``Z`` (n_z, M) the
    detections, angles in [-pi, pi]. ``Ri`` is R^-1.
    """
    n_z, N = Zx.shape
    P, order, start, lo, width, cells, reach = _grid(Zx, angular, half)
    Z = _near_cloud(P[:n_z], Z, angular, half)
    # a one-component sensor's second component: 0 for particles and detections, never outside
    z = np.zeros(max(n_z, 2))
    ang = np.zeros(max(n_z, 2), dtype=np.bool_)
    ang[:n_z] = angular
    box = np.full(max(n_z, 2), np.inf)
    box[:n_z] = half
    Rq = np.zeros((max(n_z, 2), max(n_z, 2)))
    Rq[:n_z, :n_z] = Ri
    acc = np.zeros(order.shape[0])
    rows = np.zeros(4, dtype=np.int64)
    cols = np.zeros(4, dtype=np.int64)
    c1 = cells[1]
    for j in range(Z.shape[1]):
        z[:n_z] = Z[:, j]
        nr = _span((z[0] - lo[0]) / width[0], reach[0], cells[0], ang[0], rows)
        nc = _span((z[1] - lo[1]) / width[1], reach[1], c1, ang[1], cols) if n_z >= 2 else 1
        for ra in range(nr):
            for a in range(rows[2 * ra], rows[2 * ra + 1] + 1):
                for cb in range(nc):
                    i0 = start[a * c1 + cols[2 * cb]]
                    i1 = start[a * c1 + cols[2 * cb + 1] + 1]
                    if i1 == i0:
                        continue
                    if n_z == 3:
                        _add3(P[0, i0:i1], P[1, i0:i1], P[2, i0:i1], acc[i0:i1], z, ang, box, Rq)
                    else:
                        _add2(P[0, i0:i1], P[1, i0:i1], acc[i0:i1], z, ang, box, Rq)
    hits = np.zeros(N)  # a particle with no finite measurement: the clutter term alone
    for t in range(order.shape[0]):
        hits[order[t]] = acc[t]
    for n in range(N):
        v = floor[n] + weight[n] * hits[n]
        out[n] = np.log(v) if v > 0.0 else -np.inf
