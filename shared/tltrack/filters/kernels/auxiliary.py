"""The auxiliary particle filter's kernels: the transition mean, the two weighting stages.

:class:`~tltrack.filters.auxiliary.AuxiliaryParticleFilter` picks ancestors by a look-ahead
(first stage), propagates them (the propagation kernels), and corrects the weights (second
stage); these kernels do the parts the bootstrap filter does not have.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tltrack.filters.kernels.fastmath import FMA, TRIG_MAX, exp, log, sincos
from tltrack.filters.kernels.moments import weighted_moments_run
from tltrack.filters.kernels.resample import ess_share, largest
from tltrack.filters.resampling import systematic_walk


@njit(**FMA)
def _ct_mean_row(
    px: np.ndarray,
    vx: np.ndarray,
    py: np.ndarray,
    vy: np.ndarray,
    w: np.ndarray,
    T: float,
    small: float,
    o0: np.ndarray,
    o1: np.ndarray,
    o2: np.ndarray,
    o3: np.ndarray,
    o4: np.ndarray,
) -> int:
    """f_CT of one run's particles (unit-stride rows, so the loop vectorises); returns how many
    turn arguments were beyond the fast sin/cos."""
    big = 0
    for i in range(px.shape[0]):
        om = w[i]
        wT = om * T
        s, c = sincos(wT)
        big += not (abs(wT) <= TRIG_MAX)
        tiny = abs(wT) < small
        inv = 1.0 / om
        a = T * (1.0 - wT * wT / 6.0) if tiny else s * inv  # sin(wT) / w
        bb = T * (wT / 2.0) if tiny else (1.0 - c) * inv  # (1 - cos(wT)) / w
        o0[i] = px[i] + a * vx[i] - bb * vy[i]
        o1[i] = c * vx[i] - s * vy[i]
        o2[i] = py[i] + bb * vx[i] + a * vy[i]
        o3[i] = s * vx[i] + c * vy[i]
        o4[i] = om
    return big


@njit(**FMA)
def _ct_mean_run(
    x: np.ndarray, b: int, w: np.ndarray, T: float, small: float, m: np.ndarray
) -> None:
    """m[:, b] = f_CT of run b's particles, turning at the rates w (N,)."""
    big = _ct_mean_row(
        x[0, b], x[1, b], x[2, b], x[3, b], w, T, small,
        m[0, b], m[1, b], m[2, b], m[3, b], m[4, b],
    )  # fmt: skip
    if big:  # turn arguments beyond the fast sin/cos (huge or not finite): libm
        for i in range(x.shape[2]):
            om = w[i]
            wT = om * T
            if not (abs(wT) <= TRIG_MAX):
                s, c = math.sin(wT), math.cos(wT)
                a, bb = s / om, (1.0 - c) / om
                px, vx, py, vy = x[0, b, i], x[1, b, i], x[2, b, i], x[3, b, i]
                m[0, b, i] = px + a * vx - bb * vy
                m[1, b, i] = c * vx - s * vy
                m[2, b, i] = py + bb * vx + a * vy
                m[3, b, i] = s * vx + c * vy


@njit(**FMA)
def ct_mean(x: np.ndarray, T: float, small: float, m: np.ndarray) -> None:
    """m = f_CT(x) for clouds (5, B, N): the transition's mean, for the look-ahead."""
    for b in range(x.shape[1]):
        _ct_mean_run(x, b, x[4, b], T, small, m)


@njit(**FMA)
def modes_ct_mean(
    x: np.ndarray, mode: np.ndarray, keep: np.ndarray, T: float, small: float, m: np.ndarray
) -> None:
    """m = f_m(x) for clouds (5, B, N) whose particle i of run b is in mode[b, i]: the coordinated
    turn at keep[mode] Omega (0: straight, Omega held at 0)."""
    w = np.empty(x.shape[2])
    for b in range(x.shape[1]):
        for i in range(x.shape[2]):
            w[i] = x[4, b, i] * keep[mode[b, i]]
        _ct_mean_run(x, b, w, T, small, m)


@njit(**FMA)
def first_stage(
    logw: np.ndarray,
    la: np.ndarray,
    beta: float,
    u: np.ndarray,
    anc: np.ndarray,
    row: np.ndarray,
    ok: np.ndarray,
    ess: np.ndarray,
) -> None:
    """Ancestors by the first-stage weights w_{k-1} l_k(f(x_{k-1}))^beta, systematically with
    the offset u[b]: anc (B, N + 1), ok[b] False where the weights are not finite, and ess[b]
    their effective sample size as a share of N."""
    N = logw.shape[1]
    for b in range(logw.shape[0]):
        for i in range(N):
            row[i] = logw[b, i] + beta * la[b, i]
        top = largest(row)
        for i in range(N):
            row[i] = exp(row[i] - top)
        ess[b] = ess_share(row)
        ok[b] = systematic_walk(row, u[b], anc[b])


@njit(**FMA)
def second_stage(
    ll: np.ndarray,
    la: np.ndarray,
    anc: np.ndarray,
    beta: float,
    x: np.ndarray,
    logw: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
    ok: np.ndarray,
    cnt: np.ndarray,
) -> None:
    """The exact weights log w_k = log l_k(x_k) - beta log l_k(f(x_{k-1}^anc)), normalised into
    logw (B, N), and the weighted cloud's mean and covariance; ok[b] False where not finite."""
    N = ll.shape[1]
    for b in range(ll.shape[0]):
        if not ok[b]:
            continue
        row = logw[b]
        for i in range(N):
            row[i] = ll[b, i] - beta * la[b, anc[b, i]]
        top = largest(row)
        total = 0.0
        for i in range(N):
            e = exp(row[i] - top)
            cnt[i] = e
            total += e
        if not (total > 0.0 and total < np.inf):
            ok[b] = False
            continue
        shift = top + log(total)
        scale = N / total  # weighted_moments_run divides by N
        for i in range(N):
            row[i] = row[i] - shift
            cnt[i] = cnt[i] * scale
        weighted_moments_run(x, b, cnt, mean, cov)
