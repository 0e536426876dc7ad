"""Propagation x_k = f(x_{k-1}^(anc)) + L eps of the coordinated-turn and constant-velocity
models, and of the coordinated turn's jump-Markov modes, fused with the gather of the resampled
ancestors, block by block."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tltrack.filters.kernels.fastmath import FMA, TRIG_MAX, log, sincos, sincos_2pi
from tltrack.filters.kernels.gaussians import bm_row, gaussian_rows


@njit(**FMA)
def _ct_fixup(
    x: np.ndarray,
    anc: np.ndarray,
    e: np.ndarray,
    b: int,
    T: float,
    small: float,
    Ls: np.ndarray,
    mode: np.ndarray,
    keep: np.ndarray,
    out: np.ndarray,
) -> None:
    """Redo, with libm's sin/cos, the particles whose turn argument the fast reduction refused;
    particle i moves in mode mode[i] (noise factor Ls[m], turn rate scaled by keep[m])."""
    for i in range(out.shape[2]):
        j = anc[b, i]
        m = mode[i]
        w = x[4, b, j] * keep[m]
        wT = w * T
        if not (abs(wT) <= TRIG_MAX):
            s = math.sin(wT)
            c = math.cos(wT)
            tiny = abs(wT) < small
            a = T * (1.0 - wT * wT / 6.0) if tiny else s * (1.0 / w)
            bb = T * (wT / 2.0) if tiny else (1.0 - c) * (1.0 / w)
            px, vx, py, vy = x[0, b, j], x[1, b, j], x[2, b, j], x[3, b, j]
            f = (px + a * vx - bb * vy, c * vx - s * vy, py + bb * vx + a * vy, s * vx + c * vy, w)
            L = Ls[m]
            for k in range(5):
                out[k, b, i] = f[k] + (L[k, 0] * e[0, i] + L[k, 1] * e[1, i] + L[k, 2] * e[2, i])


#: Particles per block of the propagation kernels: the gathered block stays in L1.
BLOCK = 256


@njit(**FMA)
def _gather_block(x: np.ndarray, anc: np.ndarray, b: int, i0: int, m: int, g: np.ndarray) -> None:
    """g[k, t] = x[k, b, anc[b, i0 + t]] for t < m (a scalar loop: LLVM does not vectorise the
    gather here, and the propagation that then reads g does vectorise)."""
    if g.shape[0] == 5:  # one pass, one index load per particle
        for t in range(m):
            j = anc[b, i0 + t]
            g[0, t] = x[0, b, j]
            g[1, t] = x[1, b, j]
            g[2, t] = x[2, b, j]
            g[3, t] = x[3, b, j]
            g[4, t] = x[4, b, j]
        return
    for k in range(g.shape[0]):
        for t in range(m):
            g[k, t] = x[k, b, anc[b, i0 + t]]


@njit(**FMA)
def _ct_block(
    ur: np.ndarray,
    ua: np.ndarray,
    e2: np.ndarray,
    g: np.ndarray,
    T: float,
    small: float,
    L: np.ndarray,
    o0: np.ndarray,
    o1: np.ndarray,
    o2: np.ndarray,
    o3: np.ndarray,
    o4: np.ndarray,
) -> int:
    """Propagate the gathered particles g[:, :m] into the rows o0..o4 (m,), m = len(ur), with the
    Box-Muller uniforms ur, ua and third Gaussians e2 of those particles; returns how many turn
    arguments were beyond the fast sin/cos. Every array is 1-D or C-ordered and indexed by the loop
    counter alone: LLVM then sees unit-stride accesses and vectorises the loop (it does not with a
    strided 2-D view, or an offset index)."""
    l00, l01, l02 = L[0, 0], L[0, 1], L[0, 2]
    l10, l11, l12 = L[1, 0], L[1, 1], L[1, 2]
    l20, l21, l22 = L[2, 0], L[2, 1], L[2, 2]
    l30, l31, l32 = L[3, 0], L[3, 1], L[3, 2]
    l40, l41, l42 = L[4, 0], L[4, 1], L[4, 2]
    big = 0
    for t in range(ur.shape[0]):
        rad = math.sqrt(-2.0 * log(1.0 - ur[t]))  # Box-Muller, as in box_muller
        sa, ca = sincos_2pi(ua[t])
        z0 = rad * ca
        z1 = rad * sa
        z2 = e2[t]
        px = g[0, t]
        vx = g[1, t]
        py = g[2, t]
        vy = g[3, t]
        w = g[4, t]
        wT = w * T
        s, c = sincos(wT)
        big += not (abs(wT) <= TRIG_MAX)
        tiny = abs(wT) < small
        inv = 1.0 / w
        a = T * (1.0 - wT * wT / 6.0) if tiny else s * inv  # sin(wT) / w
        bb = T * (wT / 2.0) if tiny else (1.0 - c) * inv  # (1 - cos(wT)) / w
        o0[t] = px + a * vx - bb * vy + (l00 * z0 + l01 * z1 + l02 * z2)
        o1[t] = c * vx - s * vy + (l10 * z0 + l11 * z1 + l12 * z2)
        o2[t] = py + bb * vx + a * vy + (l20 * z0 + l21 * z1 + l22 * z2)
        o3[t] = s * vx + c * vy + (l30 * z0 + l31 * z1 + l32 * z2)
        o4[t] = w + (l40 * z0 + l41 * z1 + l42 * z2)
    return big


@njit(**FMA)
def ct_predict(
    x: np.ndarray,
    anc: np.ndarray,
    U: np.ndarray,
    e: np.ndarray,
    g: np.ndarray,
    T: float,
    small: float,
    L: np.ndarray,
    out: np.ndarray,
    b0: int,
) -> None:
    """out[:, b, i] = f_CT(x[:, b, anc[b, i]]) + L @ eps: the resampling's gather fused into the
    propagation, block by block through the scratch g (5, BLOCK), for the runs b0 ..
    b0 + len(U) - 1. eps (3 per particle) by Box-Muller from U (runs, 3N [+1]); L is Q_sqrt (5, 3);
    e (3, N) is scratch (only its last row is used: the pair Gaussians are made in the loop)."""
    N = out.shape[2]
    e2 = e[2]
    for r in range(U.shape[0]):
        b = b0 + r
        u = U[r]
        bm_row(u[2 * N :], e2)
        big = 0
        for i0 in range(0, N, BLOCK):
            m = min(BLOCK, N - i0)
            _gather_block(x, anc, b, i0, m, g)
            j = i0 + m
            big += _ct_block(
                u[i0:j],
                u[N + i0 : N + j],
                e2[i0:j],
                g,
                T,
                small,
                L,
                out[0, b, i0:j],
                out[1, b, i0:j],
                out[2, b, i0:j],
                out[3, b, i0:j],
                out[4, b, i0:j],
            )
        if big:  # turn arguments beyond the fast sin/cos (huge or not finite): redo with libm
            gaussian_rows(u, e)
            _ct_fixup(x, anc, e, b, T, small, L.reshape((1, 5, 3)), np.zeros(N, np.int64),
                      np.ones(1), out)  # fmt: skip


#: the noise factor's entries that a coordinated turn's (and a straight mode's) Q_sqrt (5, 3) may
#: have non-zero: x and vx from the first Gaussian, y and vy from the second, Omega from the third
MODE_NOISE = ((0, 0), (1, 0), (2, 1), (3, 1), (4, 2))


@njit(**FMA)
def _mode_rows(
    mode: np.ndarray, keep: np.ndarray, C: np.ndarray, g: np.ndarray, c: np.ndarray
) -> None:
    """Per particle t of the block: its turn rate g[4, t] scaled by keep[m] and its noise
    coefficients c[:, t] = C[m] (m = mode[t]), so that the propagation's loop reads unit-stride
    rows and vectorises (a per-particle lookup inside it would not)."""
    for t in range(mode.shape[0]):
        m = mode[t]
        g[4, t] *= keep[m]
        c[0, t] = C[m, 0]
        c[1, t] = C[m, 1]
        c[2, t] = C[m, 2]
        c[3, t] = C[m, 3]
        c[4, t] = C[m, 4]


@njit(**FMA)
def _modes_block(
    ur: np.ndarray,
    ua: np.ndarray,
    e2: np.ndarray,
    g: np.ndarray,
    c: np.ndarray,
    T: float,
    small: float,
    o0: np.ndarray,
    o1: np.ndarray,
    o2: np.ndarray,
    o3: np.ndarray,
    o4: np.ndarray,
) -> int:
    """:func:`_ct_block` with each particle's own noise coefficients c (5, m) (the entries
    :data:`MODE_NOISE` of its mode's Q_sqrt) and its turn rate already scaled by its mode."""
    big = 0
    for t in range(ur.shape[0]):
        rad = math.sqrt(-2.0 * log(1.0 - ur[t]))
        sa, ca = sincos_2pi(ua[t])
        z0 = rad * ca
        z1 = rad * sa
        px = g[0, t]
        vx = g[1, t]
        py = g[2, t]
        vy = g[3, t]
        w = g[4, t]
        wT = w * T
        s, co = sincos(wT)
        big += not (abs(wT) <= TRIG_MAX)
        tiny = abs(wT) < small
        inv = 1.0 / w
        a = T * (1.0 - wT * wT / 6.0) if tiny else s * inv
        bb = T * (wT / 2.0) if tiny else (1.0 - co) * inv
        o0[t] = px + a * vx - bb * vy + c[0, t] * z0
        o1[t] = co * vx - s * vy + c[1, t] * z0
        o2[t] = py + bb * vx + a * vy + c[2, t] * z1
        o3[t] = s * vx + co * vy + c[3, t] * z1
        o4[t] = w + c[4, t] * e2[t]
    return big


@njit(**FMA)
def modes_ct_predict(
    x: np.ndarray,
    anc: np.ndarray,
    U: np.ndarray,
    e: np.ndarray,
    g: np.ndarray,
    c: np.ndarray,
    mode: np.ndarray,
    keep: np.ndarray,
    C: np.ndarray,
    Ls: np.ndarray,
    T: float,
    small: float,
    out: np.ndarray,
    b0: int,
) -> None:
    """:func:`ct_predict` for the jump-Markov coordinated turn: new particle i of run b moves in
    mode mode[b, i] of M (turn-rate factors keep (M,); noise factors Ls (M, 5, 3), whose only
    non-zero entries, :data:`MODE_NOISE`, are C (M, 5)), with the single-model kernel's
    Gaussians from U; c (5, BLOCK) is scratch."""
    N = out.shape[2]
    e2 = e[2]
    for r in range(U.shape[0]):
        b = b0 + r
        u = U[r]
        bm_row(u[2 * N :], e2)
        big = 0
        for i0 in range(0, N, BLOCK):
            m = min(BLOCK, N - i0)
            j = i0 + m
            _gather_block(x, anc, b, i0, m, g)
            _mode_rows(mode[b, i0:j], keep, C, g, c)
            big += _modes_block(
                u[i0:j],
                u[N + i0 : N + j],
                e2[i0:j],
                g,
                c,
                T,
                small,
                out[0, b, i0:j],
                out[1, b, i0:j],
                out[2, b, i0:j],
                out[3, b, i0:j],
                out[4, b, i0:j],
            )
        if big:
            gaussian_rows(u, e)
            _ct_fixup(x, anc, e, b, T, small, Ls, mode[b], keep, out)


@njit(**FMA)
def switch_modes(u: np.ndarray, previous: np.ndarray, cdf: np.ndarray, out: np.ndarray) -> None:
    """out[b, i]: the mode after previous[b, i], by the inverse CDF (cdf (M, M), rows' cumulative
    sums, the last 1) of the chain's row at the uniform u[b, i]."""
    M = cdf.shape[1]
    for b in range(u.shape[0]):
        for i in range(u.shape[1]):
            row = previous[b, i]
            m = 0
            for j in range(M - 1):  # branch-free: the count of the row's sums at or below u
                m += u[b, i] >= cdf[row, j]
            out[b, i] = m


@njit(**FMA)
def _cv_row(
    A: np.ndarray,
    L: np.ndarray,
    k: int,
    g: np.ndarray,
    e0: np.ndarray,
    e1: np.ndarray,
    o: np.ndarray,
) -> None:
    """o = row k of A g + L eps for a block (1-D, unit-stride indexing, as in :func:`_ct_block`)."""
    a0, a1, a2, a3 = A[k, 0], A[k, 1], A[k, 2], A[k, 3]
    l0, l1 = L[k, 0], L[k, 1]
    for t in range(o.shape[0]):
        o[t] = (a0 * g[0, t] + a1 * g[1, t] + a2 * g[2, t] + a3 * g[3, t]) + (
            l0 * e0[t] + l1 * e1[t]
        )


@njit(**FMA)
def cv_predict(
    x: np.ndarray,
    anc: np.ndarray,
    U: np.ndarray,
    e: np.ndarray,
    g: np.ndarray,
    A: np.ndarray,
    L: np.ndarray,
    out: np.ndarray,
    b0: int,
) -> None:
    """out[:, b, i] = A x[:, b, anc[b, i]] + L @ eps for the 4-state constant-velocity model, for
    the runs b0 .. b0 + len(U) - 1; L is Q_sqrt (4, 2); e (2, N) and g (4, BLOCK) scratch."""
    N = out.shape[2]
    for r in range(U.shape[0]):
        b = b0 + r
        gaussian_rows(U[r], e)
        for i0 in range(0, N, BLOCK):
            m = min(BLOCK, N - i0)
            _gather_block(x, anc, b, i0, m, g)
            for k in range(4):
                _cv_row(A, L, k, g, e[0, i0 : i0 + m], e[1, i0 : i0 + m], out[k, b, i0 : i0 + m])


@njit(**FMA)
def gather(x: np.ndarray, anc: np.ndarray, out: np.ndarray) -> None:
    """out[:, b, i] = x[:, b, anc[b, i]]: the resampled clouds, when someone asks for them."""
    n, B, N = out.shape
    for b in range(B):
        for k in range(n):
            for i in range(N):
                out[k, b, i] = x[k, b, anc[b, i]]
