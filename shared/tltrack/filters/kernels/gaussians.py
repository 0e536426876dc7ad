"""Standard normals by Box-Muller from each run's own uniforms (see :func:`uniforms_per_run`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tltrack.filters.kernels.fastmath import JIT, log, sincos_2pi


def uniforms_per_run(r: int, N: int) -> int:
    """How many uniforms one run draws per predict for r Gaussians per particle.

    The layout (what :func:`gaussians` and the fused kernels read): Gaussians 2p and 2p + 1 of
    particle i are the Box-Muller pair of (u[2pN + i], u[(2p+1)N + i]); when r is odd, the last
    Gaussian row comes from ceil(N/2) pairs of the remaining uniforms (see :func:`bm_row`).
    """
    return r * N + (r % 2) * (N % 2)


@njit(**JIT)
def box_muller(ur: np.ndarray, ua: np.ndarray, ea: np.ndarray, eb: np.ndarray) -> None:
    """Box-Muller: ea[i], eb[i] = R cos(theta), R sin(theta) with R = sqrt(-2 ln(1 - ur[i])) and
    theta = 2 pi ua[i], for the uniforms ur, ua in [0, 1); independent standard normals."""
    for i in range(ea.shape[0]):
        rad = math.sqrt(-2.0 * log(1.0 - ur[i]))  # 1 - ur is in (0, 1], exactly
        s, c = sincos_2pi(ua[i])
        ea[i] = rad * c
        eb[i] = rad * s


@njit(**JIT)
def bm_row(u: np.ndarray, e: np.ndarray) -> None:
    """e[:n] standard normals from u[:2M], M = ceil(n/2): pair j is (u[j], u[M + j]) and fills
    e[j] and e[M + j]."""
    n = e.shape[0]
    M = (n + 1) // 2
    box_muller(u[: n - M], u[M:n], e[: n - M], e[M:n])
    if n - M < M:  # n odd: the last pair gives one Gaussian
        e[M - 1] = math.sqrt(-2.0 * log(1.0 - u[M - 1])) * sincos_2pi(u[2 * M - 1])[1]


@njit(**JIT)
def gaussian_rows(u: np.ndarray, e: np.ndarray) -> None:
    """e (r, N) standard normals from one run's uniforms u, in the documented layout."""
    r, N = e.shape
    for p in range(r // 2):
        o = 2 * p * N
        box_muller(u[o : o + N], u[o + N : o + 2 * N], e[2 * p], e[2 * p + 1])
    if r % 2:
        bm_row(u[(r - 1) * N :], e[r - 1])


@njit(**JIT)
def gaussians(U: np.ndarray, E: np.ndarray) -> None:
    """E (B, r, N) standard normals from U (B, uniforms_per_run(r, N)), in the documented layout."""
    for b in range(E.shape[0]):
        gaussian_rows(U[b], E[b])
