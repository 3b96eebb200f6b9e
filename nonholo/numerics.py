"""Scalar numerics shared by every compiled law: sin/cos that vectorize, angle wrapping,
sin(x)/x.

Why our own sincos: numba compiles ``math.sin`` to a call into libm, which stops LLVM from
vectorizing the loop over robots (and the PyPI llvmlite has no SVML). The kernels below
are branch-free (selects only), so a loop calling them compiles to SIMD code. Accuracy:
Cody–Waite reduction by π/2 with a three-part constant, then the fdlibm minimax
polynomials on [−π/4, π/4]; the error is within a few ulp of libm for |x| < 2²⁰·π/2
(≈ 1.6e6 rad, where the split constant stops being exact; headings never get near).
"""
from __future__ import annotations

import math
import numbers

import numpy as np
from numba import njit


def is_real(value) -> bool:
    """A finite real number (numpy scalars included, booleans not); Python floats and ints
    are checked without the slower abstract-base-class test (sweeps check 10⁴ gain sets)."""
    try:   # (an int past the float range raises OverflowError in isfinite: not a finite real for us)
        kind = type(value)
        if kind is float or kind is int:
            return math.isfinite(value)
        return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)
    except OverflowError:
        return False


_TWO_OVER_PI = 0.63661977236758134308
# π/2 split into three parts (fdlibm pio2_1, pio2_2, pio2_3): k·part is exact for |k| < 2^20.
_PIO2_1 = 1.57079632673412561417e00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_3 = 2.02226624871116645580e-21

# fdlibm __kernel_sin / __kernel_cos coefficients.
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11

TWO_PI = 2.0 * math.pi


@njit(inline="always", error_model="numpy")
def sincos(x):
    """(sin x, cos x), branch-free so that loops calling it vectorize."""
    k = np.floor(x * _TWO_OVER_PI + 0.5)   # (a float: math.floor's int would be converted back)
    r = ((x - k * _PIO2_1) - k * _PIO2_2) - k * _PIO2_3
    z = r * r
    sin_r = r + r * z * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    cos_r = 1.0 - 0.5 * z + z * z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    quadrant = int(k) & 3
    odd = (quadrant & 1) == 1
    s = cos_r if odd else sin_r
    c = sin_r if odd else cos_r
    s = -s if (quadrant & 2) == 2 else s
    c = -c if ((quadrant + 1) & 2) == 2 else c
    return s, c


# ``rotated_sincos``'s range, and its Taylor coefficients of sin d (d³ … d⁹) and cos d (d² … d¹⁰)
ROTATION_MAX = 0.125
_RS = (-1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0)
_RC = (-0.5, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0, -1.0 / 3628800.0)


@njit(inline="always", error_model="numpy")
def rotated_sincos(sin_a, cos_a, d):
    """(sin(a + d), cos(a + d)) from sin a and cos a, for |d| ≤ ``ROTATION_MAX``: the
    angle-sum identities, with sin d and cos d by their Taylor series to d⁹ and d¹⁰
    (truncated there below 3·10⁻¹⁷ relative). No reduction of the angle: 16 multiplies
    instead of ``sincos``'s 21 and its selects. Within a few ulp of sin and cos of a + d;
    NaN stays NaN. Outside its range it is not accurate: callers check |d| first."""
    z = d * d
    sin_d = d + d * (z * (_RS[0] + z * (_RS[1] + z * (_RS[2] + z * _RS[3]))))
    cos_d = 1.0 + z * (_RC[0] + z * (_RC[1] + z * (_RC[2] + z * (_RC[3] + z * _RC[4]))))
    return sin_a * cos_d + cos_a * sin_d, cos_a * cos_d - sin_a * sin_d


_INV_TWO_PI = 1.0 / TWO_PI


@njit(inline="always", error_model="numpy")
def wrap_angle(a):
    """Angle wrapped to (−π, π] (spec convention), branch-free: a − 2π⌈(a − π)/2π⌉, the
    quotient by a multiplication (a division is a long operation that the SIMD loops
    calling this wait on), then a 2π correction where rounding left the result outside
    (−π, π]: near odd multiples of π, as the division also did (π + 1 ulp for a = 3π).
    Floats in (−π, π] are returned unchanged (−0.0 as +0.0); −π itself (to the float)
    becomes π. ``np.ceil``, a float, not ``math.ceil``, which numba makes an int64: a
    conversion in the SIMD loops, and an overflow beyond 9.2e18."""
    w = a - TWO_PI * np.ceil((a - math.pi) * _INV_TWO_PI)
    w = w - TWO_PI if w > math.pi else w
    return w + TWO_PI if w <= -math.pi else w


def array_wrap(angle):
    """``wrap_angle`` of an array or scalar (numpy, same operations, same results)."""
    angle = np.asarray(angle, dtype=float)
    with np.errstate(invalid="ignore"):   # ±inf: NaN, as the compiled one gives, without a warning
        w = angle - TWO_PI * np.ceil((angle - math.pi) * _INV_TWO_PI)
    w = np.where(w > math.pi, w - TWO_PI, w)
    return np.where(w <= -math.pi, w + TWO_PI, w)[()]   # (a scalar for a scalar)


@njit(inline="always", error_model="numpy")
def sinc_of(x, sin_x):
    """sin(x)/x given sin(x), equal to its continuous extension 1 − x²/6 near 0."""
    small = abs(x) < 1e-4
    safe_x = 1.0 if small else x
    return 1.0 - x * x / 6.0 if small else sin_x / safe_x


# Beyond this |x| the three-part reduction loses accuracy; array functions defer to numpy.
SINCOS_EXACT_RANGE = 1.0e6


@njit(cache=True, error_model="numpy")
def _sin_cos_arrays(x, sin_out, cos_out):
    for i in range(x.size):
        sin_out[i], cos_out[i] = sincos(x[i])


def array_sincos(x):
    """(sin x, cos x) of an array with the SIMD ``sincos`` (numpy beyond ``SINCOS_EXACT_RANGE``)."""
    x = np.asarray(x, dtype=float)
    flat = np.ascontiguousarray(x).ravel()
    sin_out, cos_out = np.empty_like(flat), np.empty_like(flat)
    _sin_cos_arrays(flat, sin_out, cos_out)
    far = np.abs(flat) > SINCOS_EXACT_RANGE
    if far.any():
        sin_out[far], cos_out[far] = np.sin(flat[far]), np.cos(flat[far])
    return sin_out.reshape(x.shape), cos_out.reshape(x.shape)


def array_sin(x):
    """sin of an array with the SIMD ``sincos`` (numpy beyond ``SINCOS_EXACT_RANGE``)."""
    return array_sincos(x)[0]


def array_cos(x):
    """cos of an array with the SIMD ``sincos`` (numpy beyond ``SINCOS_EXACT_RANGE``)."""
    return array_sincos(x)[1]
