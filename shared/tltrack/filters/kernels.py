"""Numba kernels of the particle filter's fast path: CT/CV propagation, range-bearing likelihoods,
systematic resampling, and the moments the filter reports.

Why hand-written elementary functions: numba turns ``math.sin`` and friends into scalar libm calls,
which LLVM cannot vectorise without Intel's SVML (and this numba's LLVM is not patched for SVML at
all). sin/cos, atan2, exp and log are therefore written here as branch-free polynomials (the
fdlibm/Cephes kernels, with Cody-Waite argument reduction), so every per-particle loop compiles to
SIMD code. Their accuracy is a few ulp at most (tested against NumPy), and NaN propagates through
each of them: no ``fastmath`` flag that could assume away NaN or infinity is used anywhere. Only
``contract`` (fused multiply-adds) and, in loops that accumulate sums, ``reassoc`` are allowed.

What keeps a loop vectorised here (each was measured: a loop that loses SIMD runs 5-10x slower):

- the loop calls only the small leaf functions below, never a helper that itself calls several
  of them (LLVM's inliner then gives up, and the loop stays scalar): see :func:`_box_muller`;
- every array in it is 1-D or C-ordered and indexed by the loop counter itself (not ``i0 + t``,
  not a strided 2-D view); a gather (``x[anc[i]]``) goes into a small scratch block first;
- no data-dependent branch: selects only (a pointer-by-pointer resampler mispredicts a branch
  per particle on real weights; see :func:`tltrack.filters.resampling.systematic_walk`).

Randomness stays NumPy's: the caller fills ``U`` with ``Generator.random(out=...)`` from each run's
own generator (53-bit uniforms, one per Gaussian, as NumPy's own ziggurat uses one 64-bit draw per
Gaussian), and the Gaussians are made here by Box-Muller from those uniforms. A run's numbers
depend only on its generator and N, never on the batch around it (no loop here mixes runs, and a
reduction's order depends only on N).

Array layouts: particles ``x`` are ``(n_x, B, N)`` as in
:class:`~tltrack.filters.particle.ParticleFilter`; per-run buffers are ``(B, ...)`` rows.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from tltrack.filters.resampling import systematic_walk

# error_model="numpy": a division by zero gives inf/NaN rather than raising, so loops vectorise.
_JIT: dict[str, Any] = {"cache": True, "nogil": True, "error_model": "numpy"}
#: Contraction allows fused multiply-adds; it never touches NaN or inf.
_FMA: dict[str, Any] = {**_JIT, "fastmath": {"contract"}}
#: Reassociation also lets LLVM vectorise sums (their order then depends on N alone).
_SUM: dict[str, Any] = {**_JIT, "fastmath": {"reassoc", "contract"}}

#: Beyond this |x| the 3-part Cody-Waite reduction of sin/cos is not trusted: libm is used instead.
TRIG_MAX = 1.0e5


# --------------------------------------------------------------------------------------------
# bit casts


def _bits_impl(typingctx: Any, x: Any) -> Any:
    """The IEEE-754 bits of a float64, as an int64."""
    if x != types.float64:
        return None

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return builder.bitcast(args[0], ir.IntType(64))

    return types.int64(types.float64), codegen


def _from_bits_impl(typingctx: Any, i: Any) -> Any:
    """The float64 whose IEEE-754 bits are the int64 ``i``."""
    if i != types.int64:
        return None

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return builder.bitcast(args[0], ir.DoubleType())

    return types.float64(types.int64), codegen


_bits: Any = intrinsic(_bits_impl)
_from_bits: Any = intrinsic(_from_bits_impl)

# --------------------------------------------------------------------------------------------
# elementary functions (fdlibm kernels)

_SHIFT = 6755399441055744.0  # 1.5 * 2**52: x + _SHIFT - _SHIFT rounds x to an integer
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_LOG2E = 1.44269504088896338700e00
_TWO_OVER_PI = 6.36619772367581382433e-01
_PIO2_1 = 1.57079632673412561417e00  # first 33 bits of pi/2
_PIO2_2 = 6.07710050630396597660e-11  # next 33 bits
_PIO2_3 = 2.02226624871116645580e-21  # the rest
_PI_HI = 3.14159265358979311600e00
_PI_LO = 1.22464679914735317720e-16
_PIO2_HI = 1.57079632679489655800e00
_PIO2_LO = 6.12323399573676603587e-17
_PIO2 = 1.57079632679489661923e00
# fdlibm's polynomial coefficients: __kernel_sin, __kernel_cos, __ieee754_log, atan
_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11
_LG1, _LG2, _LG3 = 6.666666666666735130e-01, 3.999999999940941908e-01, 2.857142874366239149e-01
_LG4, _LG5, _LG6 = 2.222219843214978396e-01, 1.818357216161805012e-01, 1.531383769920937332e-01
_LG7 = 1.479819860511658591e-01
_AT0, _AT1 = 3.33333333333329318027e-01, -1.99999999998764832476e-01
_AT2, _AT3 = 1.42857142725034663711e-01, -1.11111104054623557880e-01
_AT4, _AT5 = 9.09088713343650656196e-02, -7.69187620504482999495e-02
_AT6, _AT7 = 6.66107313738753120669e-02, -5.83357013379057348645e-02
_AT8, _AT9 = 4.97687799461593236017e-02, -3.65315727442169155270e-02
_AT10 = 1.62858201153657823623e-02


@njit(**_JIT)
def _ksin(x: float) -> float:
    """sin on [-pi/4, pi/4] (fdlibm __kernel_sin)."""
    z = x * x
    v = z * x
    r = _S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))
    return x + v * (_S1 + z * r)


@njit(**_JIT)
def _kcos(x: float) -> float:
    """cos on [-pi/4, pi/4] (fdlibm __kernel_cos)."""
    z = x * x
    r = z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + z * r)


@njit(**_JIT)
def _quadrant(r: float, q: int) -> tuple[float, float]:
    """sin and cos of r + q*pi/2 for |r| <= pi/4, branch-free."""
    s = _ksin(r)
    c = _kcos(r)
    odd = (q & 1) != 0
    sn = c if odd else s
    cs = s if odd else c
    if (q & 2) != 0:
        sn = -sn
    if ((q + 1) & 2) != 0:
        cs = -cs
    return sn, cs


@njit(**_JIT)
def sincos(x: float) -> tuple[float, float]:
    """sin(x), cos(x) for |x| <= TRIG_MAX (3-part Cody-Waite reduction); NaN in, NaN out."""
    t = x * _TWO_OVER_PI + _SHIFT
    n = t - _SHIFT
    r = ((x - n * _PIO2_1) - n * _PIO2_2) - n * _PIO2_3
    return _quadrant(r, _bits(t) & 3)


@njit(**_JIT)
def sincos_2pi(v: float) -> tuple[float, float]:
    """sin(2 pi v), cos(2 pi v) for v in [0, 1] (the angle of a Box-Muller pair)."""
    t = 4.0 * v + _SHIFT
    f = 4.0 * v - (t - _SHIFT)  # in [-1/2, 1/2], exact
    return _quadrant(f * _PIO2, _bits(t) & 3)


@njit(**_JIT)
def exp(x: float) -> float:
    """e^x; 0 below -708.3 (where libm would return subnormals), NaN in, NaN out."""
    t = x * _LOG2E + _SHIFT
    k = t - _SHIFT
    r = (x - k * _LN2_HI) - k * _LN2_LO  # |r| <= ln(2)/2
    p = 1.0 + r * (
        1.0
        + r
        * (
            1.0 / 2
            + r
            * (
                1.0 / 6
                + r
                * (
                    1.0 / 24
                    + r
                    * (
                        1.0 / 120
                        + r
                        * (
                            1.0 / 720
                            + r
                            * (
                                1.0 / 5040
                                + r
                                * (
                                    1.0 / 40320
                                    + r
                                    * (
                                        1.0 / 362880
                                        + r
                                        * (
                                            1.0 / 3628800
                                            + r
                                            * (
                                                1.0 / 39916800
                                                + r * (1.0 / 479001600 + r * (1.0 / 6227020800))
                                            )
                                        )
                                    )
                                )
                            )
                        )
                    )
                )
            )
        )
    )
    y = p * _from_bits((_bits(t) + 1023) << 52)
    if x < -708.3:
        y = 0.0
    if x > 709.78:
        y = np.inf
    return y


@njit(**_JIT)
def log(x: float) -> float:
    """ln(x) for positive normal x (fdlibm __ieee754_log without its special cases)."""
    hx = _bits(x)
    k = (hx >> 52) - 1023
    hm = hx & 0x000FFFFFFFFFFFFF
    i = (hm + 0x00095F6400000000) & 0x0010000000000000  # 1 when the mantissa exceeds sqrt(2)
    m = _from_bits(hm | (i ^ 0x3FF0000000000000))
    k += i >> 52
    f = m - 1.0
    s = f / (2.0 + f)
    dk = float(k)
    z = s * s
    w = z * z
    t1 = w * (_LG2 + w * (_LG4 + w * _LG6))
    t2 = z * (_LG1 + w * (_LG3 + w * (_LG5 + w * _LG7)))
    R = t2 + t1
    hfsq = 0.5 * f * f
    return dk * _LN2_HI - ((hfsq - (s * (hfsq + R) + dk * _LN2_LO)) - f)


@njit(**_JIT)
def atan2(y: float, x: float) -> float:
    """atan2(y, x) in [-pi, pi] (fdlibm's atan polynomial, one division); NaN in, NaN out."""
    ax = abs(x)
    ay = abs(y)
    swap = ay > ax
    mx = ay if swap else ax
    mn = ax if swap else ay
    # atan(mn/mx) = atan(c) + atan((mn - c*mx) / (mx + c*mn)), c in {0, 1/2, 1} by the ratio
    c = 0.0
    hi = 0.0
    lo = 0.0
    if mn >= 0.4375 * mx and mn > 0.0:
        c = 0.5
        hi = 4.63647609000806093515e-01
        lo = 2.26987774529616870924e-17
    if mn >= 0.6875 * mx and mn > 0.0:
        c = 1.0
        hi = 7.85398163397448278999e-01
        lo = 3.06161699786838301793e-17
    den = mx + c * mn
    if mx == 0.0:
        den = 1.0  # atan2(0, 0) = 0
    t = (mn - c * mx) / den
    z = t * t
    w = z * z
    s1 = z * (_AT0 + w * (_AT2 + w * (_AT4 + w * (_AT6 + w * (_AT8 + w * _AT10)))))
    s2 = w * (_AT1 + w * (_AT3 + w * (_AT5 + w * (_AT7 + w * _AT9))))
    a = hi - ((t * (s1 + s2) - lo) - t)
    if swap:
        a = (_PIO2_HI - a) + _PIO2_LO
    if x < 0.0:
        a = (_PI_HI - a) + _PI_LO
    if y < 0.0:
        a = -a
    return a


# --------------------------------------------------------------------------------------------
# Gaussians


def uniforms_per_run(r: int, N: int) -> int:
    """How many uniforms one run draws per predict for r Gaussians per particle.

    The layout (what :func:`gaussians` and the fused kernels read): Gaussians 2p and 2p + 1 of
    particle i are the Box-Muller pair of (u[2pN + i], u[(2p+1)N + i]); when r is odd, the last
    Gaussian row comes from ceil(N/2) pairs of the remaining uniforms (see :func:`_bm_row`).
    """
    return r * N + (r % 2) * (N % 2)


@njit(**_JIT)
def _box_muller(ur: np.ndarray, ua: np.ndarray, ea: np.ndarray, eb: np.ndarray) -> None:
    """Box-Muller: ea[i], eb[i] = R cos(theta), R sin(theta) with R = sqrt(-2 ln(1 - ur[i])) and
    theta = 2 pi ua[i], for the uniforms ur, ua in [0, 1); independent standard normals."""
    for i in range(ea.shape[0]):
        rad = math.sqrt(-2.0 * log(1.0 - ur[i]))  # 1 - ur is in (0, 1], exactly
        s, c = sincos_2pi(ua[i])
        ea[i] = rad * c
        eb[i] = rad * s


@njit(**_JIT)
def _bm_row(u: np.ndarray, e: np.ndarray) -> None:
    """e[:n] standard normals from u[:2M], M = ceil(n/2): pair j is (u[j], u[M + j]) and fills
    e[j] and e[M + j]."""
    n = e.shape[0]
    M = (n + 1) // 2
    _box_muller(u[: n - M], u[M:n], e[: n - M], e[M:n])
    if n - M < M:  # n odd: the last pair gives one Gaussian
        e[M - 1] = math.sqrt(-2.0 * log(1.0 - u[M - 1])) * sincos_2pi(u[2 * M - 1])[1]


@njit(**_JIT)
def _gaussian_rows(u: np.ndarray, e: np.ndarray) -> None:
    """e (r, N) standard normals from one run's uniforms u, in the documented layout."""
    r, N = e.shape
    for p in range(r // 2):
        o = 2 * p * N
        _box_muller(u[o : o + N], u[o + N : o + 2 * N], e[2 * p], e[2 * p + 1])
    if r % 2:
        _bm_row(u[(r - 1) * N :], e[r - 1])


@njit(**_JIT)
def gaussians(U: np.ndarray, E: np.ndarray) -> None:
    """E (B, r, N) standard normals from U (B, uniforms_per_run(r, N)), in the documented layout."""
    for b in range(E.shape[0]):
        _gaussian_rows(U[b], E[b])


# --------------------------------------------------------------------------------------------
# propagation


@njit(**_FMA)
def _ct_fixup(
    x: np.ndarray,
    anc: np.ndarray,
    e: np.ndarray,
    b: int,
    T: float,
    small: float,
    L: np.ndarray,
    out: np.ndarray,
) -> None:
    """Redo, with libm's sin/cos, the particles whose turn argument the fast reduction refused."""
    for i in range(out.shape[2]):
        j = anc[b, i]
        w = x[4, b, j]
        wT = w * T
        if not (abs(wT) <= TRIG_MAX):
            s = math.sin(wT)
            c = math.cos(wT)
            tiny = abs(wT) < small
            a = T * (1.0 - wT * wT / 6.0) if tiny else s * (1.0 / w)
            bb = T * (wT / 2.0) if tiny else (1.0 - c) * (1.0 / w)
            px, vx, py, vy = x[0, b, j], x[1, b, j], x[2, b, j], x[3, b, j]
            f = (px + a * vx - bb * vy, c * vx - s * vy, py + bb * vx + a * vy, s * vx + c * vy, w)
            for k in range(5):
                out[k, b, i] = f[k] + (L[k, 0] * e[0, i] + L[k, 1] * e[1, i] + L[k, 2] * e[2, i])


#: Particles per block of the propagation kernels: the gathered block stays in L1.
BLOCK = 256


@njit(**_FMA)
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


@njit(**_FMA)
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
        rad = math.sqrt(-2.0 * log(1.0 - ur[t]))  # Box-Muller, as in _box_muller
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


@njit(**_FMA)
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
        _bm_row(u[2 * N :], e2)
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
            _gaussian_rows(u, e)
            _ct_fixup(x, anc, e, b, T, small, L, out)


@njit(**_FMA)
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


@njit(**_FMA)
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
        _gaussian_rows(U[r], e)
        for i0 in range(0, N, BLOCK):
            m = min(BLOCK, N - i0)
            _gather_block(x, anc, b, i0, m, g)
            for k in range(4):
                _cv_row(A, L, k, g, e[0, i0 : i0 + m], e[1, i0 : i0 + m], out[k, b, i0 : i0 + m])


@njit(**_FMA)
def gather(x: np.ndarray, anc: np.ndarray, out: np.ndarray) -> None:
    """out[:, b, i] = x[:, b, anc[b, i]]: the resampled clouds, when someone asks for them."""
    n, B, N = out.shape
    for b in range(B):
        for k in range(n):
            for i in range(N):
                out[k, b, i] = x[k, b, anc[b, i]]


# --------------------------------------------------------------------------------------------
# range-bearing likelihood

#: Per-observation constants of one run, see :func:`_rb_constants`.
_NC = 9
_TWO_PI = 6.28318530717958647693e00


@njit(**_FMA)
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


@njit(**_FMA)
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


@njit(**_FMA)
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
        d1 = d1 - _TWO_PI if d1 > np.pi else d1
        d1 = d1 + _TWO_PI if d1 <= -np.pi else d1
        e0 = zr2 - r
        e1 = zb2 - th
        e1 = e1 - _TWO_PI if e1 > np.pi else e1
        e1 = e1 + _TWO_PI if e1 <= -np.pi else e1
        rho = (pa * d0 * d0 + pb * d0 * d1 + pc * d1 * d1) + (
            pa2 * e0 * e0 + pb2 * e0 * e1 + pc2 * e1 * e1
        )
        row[i] = rho + row[i] if add else rho


@njit(**_FMA)
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


@njit(**_FMA)
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


@njit(**_FMA)
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
    """:func:`rb_loglik` then :func:`resample`, run by run, so that a run's log-weights (row, (N,)
    scratch) stay in cache between the two. Same arguments and results as those two."""
    cs = np.empty((pos.shape[0], _NC))
    cnt = np.empty(x.shape[2])
    good = 0
    for b in range(x.shape[1]):
        _rb_loglik_run(x, ix, iy, b, pos, mean, cov, mask, cs, row)
        ok[b] = _resample_run(row, u[b], x, b, anc[b], cnt, m_out, c_out)
        good += ok[b]
    return good


# --------------------------------------------------------------------------------------------
# moments


@njit(**_SUM)
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


@njit(**_SUM)
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


@njit(**_FMA)
def moments(x: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> None:
    """Sample mean (B, n) and covariance (B, n, n), normalised by N, of the clouds x (n, B, N)."""
    for b in range(x.shape[1]):
        _moments_run(x, b, mean, cov)


@njit(**_SUM)
def _weighted_moments_run(
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


# --------------------------------------------------------------------------------------------
# resampling


@njit(**_FMA)
def _max(v: np.ndarray) -> float:
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


@njit(**_SUM)
def _weighted_moments5(
    x: np.ndarray, b: int, cnt: np.ndarray, mean: np.ndarray, cov: np.ndarray
) -> None:
    """:func:`_weighted_moments_run` for n = 5, each pass a single loop."""
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


@njit(**_FMA)
def _resample_run(
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
    m = _max(w)
    for i in range(N):
        w[i] = exp(w[i] - m)
    if not systematic_walk(w, u, anc):
        return False
    k = w.view(np.int64)  # the walk leaves k_j, the count of pointers below cdf[j]
    cnt[0] = k[0]
    for j in range(1, N):
        cnt[j] = k[j] - k[j - 1]  # offspring of particle j
    _weighted_moments_run(x, b, cnt, mean, cov)
    return True


@njit(**_FMA)
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
    reads through anc; :func:`gather` makes it on request). ``logw`` is overwritten.

    ok[b] is False, and anc[b], mean[b], cov[b] meaningless, for a run whose weights are not finite
    (a NaN log-weight, or all -inf). Returns the count of runs that are ok.
    """
    cnt = np.empty(x.shape[2])
    good = 0
    for b in range(x.shape[1]):
        ok[b] = _resample_run(logw[b], u[b], x, b, anc[b], cnt, mean, cov)
        good += ok[b]
    return good


# --------------------------------------------------------------------------------------------
# predicted observation


@njit(**_SUM)
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
