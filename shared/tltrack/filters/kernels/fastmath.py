"""Compile options, and the elementary functions of the kernels as vectorisable polynomials.

sin/cos, exp, log and atan2 are the fdlibm kernels, branch-free, with Cody-Waite argument
reduction: numba's ``math.sin`` is a scalar libm call that keeps a loop from vectorising (see the
package's docstring).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

# error_model="numpy": a division by zero gives inf/NaN rather than raising, so loops vectorise.
JIT: dict[str, Any] = {"cache": True, "nogil": True, "error_model": "numpy"}
#: Contraction allows fused multiply-adds; it never touches NaN or inf.
FMA: dict[str, Any] = {**JIT, "fastmath": {"contract"}}
#: Reassociation also lets LLVM vectorise sums (their order then depends on N alone).
SUM: dict[str, Any] = {**JIT, "fastmath": {"reassoc", "contract"}}

#: Beyond this |x| the 3-part Cody-Waite reduction of sin/cos is not trusted: libm is used instead.
TRIG_MAX = 1.0e5
#: 2 pi to the last bit
TWO_PI = 6.28318530717958647693e00


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


@njit(**JIT)
def _ksin(x: float) -> float:
    """sin on [-pi/4, pi/4] (fdlibm __kernel_sin)."""
    z = x * x
    v = z * x
    r = _S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))
    return x + v * (_S1 + z * r)


@njit(**JIT)
def _kcos(x: float) -> float:
    """cos on [-pi/4, pi/4] (fdlibm __kernel_cos)."""
    z = x * x
    r = z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + z * r)


@njit(**JIT)
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


@njit(**JIT)
def sincos(x: float) -> tuple[float, float]:
    """sin(x), cos(x) for |x| <= TRIG_MAX (3-part Cody-Waite reduction); NaN in, NaN out."""
    t = x * _TWO_OVER_PI + _SHIFT
    n = t - _SHIFT
    r = ((x - n * _PIO2_1) - n * _PIO2_2) - n * _PIO2_3
    return _quadrant(r, _bits(t) & 3)


@njit(**JIT)
def sincos_2pi(v: float) -> tuple[float, float]:
    """sin(2 pi v), cos(2 pi v) for v in [0, 1] (the angle of a Box-Muller pair)."""
    t = 4.0 * v + _SHIFT
    f = 4.0 * v - (t - _SHIFT)  # in [-1/2, 1/2], exact
    return _quadrant(f * _PIO2, _bits(t) & 3)


@njit(**JIT)
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


@njit(**JIT)
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


@njit(**JIT)
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
