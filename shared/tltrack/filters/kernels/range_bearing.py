"""Range-bearing log-likelihoods (fused with resampling) and predicted-observation moments."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tltrack.filters.kernels.fastmath import FMA, SUM, TWO_PI, atan2, exp
from tltrack.filters.kernels.resample import resample_run

#: Per-observation constants of one run, see :func:`_rb_constants`.
_NC = 9


@njit(**FMA)
def _rb_constants(
    pos: np.ndarray, mean: np.ndarray, cov: np.ndarray, j: int, b: int, c: np.ndarray
) -> None:
    """c = [sx, sy, z_r, cos z_b, sin z_b, -P00/2, -P01, -P11/2, z_b in [-pi, pi]], P = cov^-1."""
    c00, c01, c10, c11 = cov[j, b, 0, 0], cov[j, b, 0, 1], cov[j, b, 1, 0], cov[j, b, 1, 1]
    det = c00 * c11 - c01 * c10
    c[0] = pos[j, 0]
    c[1] = pos[j, 1]
    c[2] = mean[j, 0, b]
    c[3] = math.cos(mean[j, 1, b])
    c[4] = math.sin(mean[j, 1, b])
    c[5] = -0.5 * c11 / det
    c[6] = c01 / det  # -(1/2) * 2 * P01, P01 = -c01 / det
    c[7] = -0.5 * c00 / det
    c[8] = math.atan2(c[4], c[3])


@njit(**FMA)
def _rb_pass(xr: np.ndarray, yr: np.ndarray, c: np.ndarray, row: np.ndarray, add: bool) -> None:
    """row (+)= -(1/2) d' P d, d = [z_r - r, wrap(z_b - bearing)], for particles at (xr, yr). The
    bearing residual is the angle of (dx, dy) rotated by -z_b, which needs no wrapping."""
    sx, sy, zr, cz, sz, pa, pb, pc = c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]
    for i in range(row.shape[0]):
        dx = xr[i] - sx
        dy = yr[i] - sy
        d0 = zr - math.sqrt(dx * dx + dy * dy)
        d1 = atan2(dx * sz - dy * cz, dx * cz + dy * sz)
        rho = pa * d0 * d0 + pb * d0 * d1 + pc * d1 * d1
        row[i] = rho + row[i] if add else rho


@njit(**FMA)
def _rb_pass2(
    xr: np.ndarray, yr: np.ndarray, c: np.ndarray, c2: np.ndarray, row: np.ndarray, add: bool
) -> None:
    """Two statements about sensors at the same place (the primary's z and a co-located source's
    transfer): one range and one bearing per particle serve both."""
    sx, sy, zr, zb, pa, pb, pc = c[0], c[1], c[2], c[8], c[5], c[6], c[7]
    zr2, zb2, pa2, pb2, pc2 = c2[2], c2[8], c2[5], c2[6], c2[7]
    for i in range(row.shape[0]):
        dx = xr[i] - sx
        dy = yr[i] - sy
        r = math.sqrt(dx * dx + dy * dy)
        th = atan2(dy, dx)
        d0 = zr - r
        d1 = zb - th  # in [-2 pi, 2 pi]: one turn at most to wrap into (-pi, pi]
        d1 = d1 - TWO_PI if d1 > np.pi else d1
        d1 = d1 + TWO_PI if d1 <= -np.pi else d1
        e0 = zr2 - r
        e1 = zb2 - th
        e1 = e1 - TWO_PI if e1 > np.pi else e1
        e1 = e1 + TWO_PI if e1 <= -np.pi else e1
        rho = (pa * d0 * d0 + pb * d0 * d1 + pc * d1 * d1) + (
            pa2 * e0 * e0 + pb2 * e0 * e1 + pc2 * e1 * e1
        )
        row[i] = rho + row[i] if add else rho


@njit(**FMA)
def _rb_loglik_run(
    x: np.ndarray,
    ix: int,
    iy: int,
    b: int,
    pos: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
    mask: np.ndarray,
    cs: np.ndarray,
    row: np.ndarray,
) -> None:
    """Run b of :func:`rb_loglik`, into row (N,); cs (M, _NC) is scratch."""
    na = 0
    for j in range(pos.shape[0]):
        if mask[j, b]:
            _rb_constants(pos, mean, cov, j, b, cs[na])
            na += 1
    if na == 0:
        row[:] = 0.0
        return
    xr = x[ix, b]
    yr = x[iy, b]
    t = 0
    while t < na:
        if na - t >= 2 and cs[t, 0] == cs[t + 1, 0] and cs[t, 1] == cs[t + 1, 1]:
            _rb_pass2(xr, yr, cs[t], cs[t + 1], row, t > 0)
            t += 2
        else:
            _rb_pass(xr, yr, cs[t], row, t > 0)
            t += 1


@njit(**FMA)
def rb_loglik(
    x: np.ndarray,
    ix: int,
    iy: int,
    pos: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
    mask: np.ndarray,
    logw: np.ndarray,
) -> None:
    """Write into logw (B, N) the sum of M range-bearing log-likelihoods (up to constants),
    log N(mean[j, :, b]; h_j(x), cov[j, b]) for a sensor at pos[j]; obs j counts for run b only
    where mask[j, b]. Particle positions are x[ix], x[iy]."""
    cs = np.empty((pos.shape[0], _NC))
    for b in range(x.shape[1]):
        _rb_loglik_run(x, ix, iy, b, pos, mean, cov, mask, cs, logw[b])


@njit(**FMA)
def rb_update(
    x: np.ndarray,
    ix: int,
    iy: int,
    pos: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
    mask: np.ndarray,
    u: np.ndarray,
    anc: np.ndarray,
    m_out: np.ndarray,
    c_out: np.ndarray,
    ok: np.ndarray,
    row: np.ndarray,
) -> int:
    """:func:`rb_loglik` then :func:`~tltrack.filters.kernels.resample.resample`, run by run,
    so that a run's log-weights (row, (N,) scratch) stay in cache between the two. Same
    arguments and results as those two."""
    cs = np.empty((pos.shape[0], _NC))
    cnt = np.empty(x.shape[2])
    good = 0
    for b in range(x.shape[1]):
        _rb_loglik_run(x, ix, iy, b, pos, mean, cov, mask, cs, row)
        ok[b] = resample_run(row, u[b], x, b, anc[b], cnt, m_out, c_out)
        good += ok[b]
    return good


@njit(**SUM)
def rb_predicted_obs(
    x: np.ndarray, ix: int, iy: int, sx: float, sy: float, eta: np.ndarray, cov: np.ndarray
) -> None:
    """Moments of h(x) for a range-bearing sensor: eta (2, B) with the circular bearing mean, and
    the sample covariance (B, 2, 2) of [r - eta_r, wrap(bearing - eta_b)], normalised by N."""
    N = x.shape[2]
    for b in range(x.shape[1]):
        sr = 0.0
        sc = 0.0
        ss = 0.0
        for i in range(N):
            dx = x[ix, b, i] - sx
            dy = x[iy, b, i] - sy
            r = math.sqrt(dx * dx + dy * dy)
            at_sensor = r == 0.0
            sr += r
            sc += 1.0 if at_sensor else dx / r  # cos(atan2(dy, dx))
            ss += 0.0 if at_sensor else dy / r  # sin(atan2(dy, dx))
        er = sr / N
        eb = math.atan2(ss / N, sc / N)
        ce = math.cos(eb)
        se = math.sin(eb)
        s00 = 0.0
        s01 = 0.0
        s11 = 0.0
        for i in range(N):
            dx = x[ix, b, i] - sx
            dy = x[iy, b, i] - sy
            d0 = math.sqrt(dx * dx + dy * dy) - er
            d1 = atan2(dy * ce - dx * se, dx * ce + dy * se)
            s00 += d0 * d0
            s01 += d0 * d1
            s11 += d1 * d1
        eta[0, b] = er
        eta[1, b] = eb
        cov[b, 0, 0] = s00 / N
        cov[b, 0, 1] = s01 / N
        cov[b, 1, 0] = s01 / N
        cov[b, 1, 1] = s11 / N


@njit(**SUM)
def rb_weighted_predicted_obs(
    x: np.ndarray,
    ix: int,
    iy: int,
    sx: float,
    sy: float,
    logw: np.ndarray,
    eta: np.ndarray,
    cov: np.ndarray,
    w: np.ndarray,
) -> None:
    """:func:`rb_predicted_obs` for a weighted cloud (normalised log-weights logw (B, N)): the
    weighted circular bearing mean, the weighted covariance; w (N,) is scratch."""
    N = x.shape[2]
    for b in range(x.shape[1]):
        total = 0.0
        for i in range(N):
            w[i] = exp(logw[b, i])
            total += w[i]
        sr = 0.0
        sc = 0.0
        ss = 0.0
        for i in range(N):
            dx = x[ix, b, i] - sx
            dy = x[iy, b, i] - sy
            r = math.sqrt(dx * dx + dy * dy)
            at_sensor = r == 0.0
            wi = w[i] / total
            sr += wi * r
            sc += wi * (1.0 if at_sensor else dx / r)
            ss += wi * (0.0 if at_sensor else dy / r)
        eb = math.atan2(ss, sc)
        ce = math.cos(eb)
        se = math.sin(eb)
        s00 = 0.0
        s01 = 0.0
        s11 = 0.0
        for i in range(N):
            dx = x[ix, b, i] - sx
            dy = x[iy, b, i] - sy
            d0 = math.sqrt(dx * dx + dy * dy) - sr
            d1 = atan2(dy * ce - dx * se, dx * ce + dy * se)
            wi = w[i] / total
            s00 += wi * d0 * d0
            s01 += wi * d0 * d1
            s11 += wi * d1 * d1
        eta[0, b] = sr
        eta[1, b] = eb
        cov[b, 0, 0] = s00
        cov[b, 0, 1] = s01
        cov[b, 1, 0] = s01
        cov[b, 1, 1] = s11
