import math

import numpy as np
import pytest
import sympy as sp

from nonholo.errors import ExpressionError
from nonholo.expressions import parse_expression
from nonholo.numerics import ROTATION_MAX, rotated_sincos, sinc_of, sincos, wrap_angle


def test_sincos_matches_libm_to_a_few_ulp():
    x = np.concatenate([np.linspace(-1e4, 1e4, 200_001), [0.0, -0.0, math.pi / 4]])
    s, c = np.array([sincos(v) for v in x[::50]]).T
    assert np.max(np.abs(s - np.sin(x[::50]))) < 4e-16
    assert np.max(np.abs(c - np.cos(x[::50]))) < 4e-16
    assert sincos.py_func(1.5e6)[0] == pytest.approx(math.sin(1.5e6), abs=1e-12)


def test_rotated_sincos_is_sin_and_cos_of_the_sum_to_a_few_ulp_within_its_range():
    """sin(a + d), cos(a + d) from sin a and cos a (correctly rounded here) and d, against
    40-digit values of the float a + d exactly; outside |d| ≤ ROTATION_MAX it is not accurate
    (which is why the kernels check |d|)."""
    import mpmath

    rng = np.random.default_rng(3)
    a = rng.uniform(-60.0, 60.0, 1500)
    d = rng.uniform(-ROTATION_MAX, ROTATION_MAX, a.size)
    d[:5] = [0.0, -0.0, ROTATION_MAX, -ROTATION_MAX, 1e-300]
    with mpmath.workdps(40):
        sums = [mpmath.mpf(x) + mpmath.mpf(y) for x, y in zip(a, d)]   # a + d exactly
        exact = np.array([(float(mpmath.sin(t)), float(mpmath.cos(t))) for t in sums])
        given = np.array([(float(mpmath.sin(x)), float(mpmath.cos(x))) for x in a])
    got = np.array([rotated_sincos(s, c, y) for (s, c), y in zip(given, d)])
    assert np.abs(got - exact).max() < 3.5e-16
    assert np.isnan(rotated_sincos(0.0, 1.0, np.nan)).all()
    far = rotated_sincos(0.0, 1.0, 1.0)
    assert abs(far[0] - math.sin(1.0)) > 1e-9   # beyond its range: a series cut at d⁹


@pytest.mark.parametrize("angle, wrapped", [(math.pi, math.pi), (-math.pi, math.pi), (3 * math.pi / 2, -math.pi / 2),
                                            (7.0, 7.0 - 2 * math.pi), (0.0, 0.0), (-1e-17, -1e-17)])
def test_wrap_angle_is_in_half_open_interval(angle, wrapped):
    assert wrap_angle(angle) == pytest.approx(wrapped, abs=1e-15)


def test_wrap_stays_in_the_half_open_interval_at_multiples_of_pi():
    """At k·π and the floats beside it (where a − 2πn rounds to just outside (−π, π]: π + 1
    ulp for a = 3π by the plain formula) the wrapped angle stays in (−π, π], is a + 2πn to
    rounding, and the compiled scalar and the numpy array version agree bit for bit; an angle
    already in (−π, π] comes back unchanged."""
    from nonholo.numerics import array_wrap
    multiples = np.array([k * math.pi for k in range(-200, 201)])
    a = np.concatenate([multiples, np.nextafter(multiples, np.inf), np.nextafter(multiples, -np.inf),
                        np.random.default_rng(3).uniform(-1e3, 1e3, 20_000)])
    plain = a - 2 * np.pi * np.ceil((a - np.pi) / (2 * np.pi))
    assert ((plain > math.pi) | (plain <= -math.pi)).any()   # what the correction is for
    w = array_wrap(a)
    assert np.all((w > -math.pi) & (w <= math.pi))
    turns = (a - w) / (2 * np.pi)
    assert np.max(np.abs(turns - np.round(turns))) < 1e-12
    assert np.array_equal(w, [wrap_angle(v) for v in a])
    extremes = np.array([1e20, -1e20, 1e300, np.inf, -np.inf, np.nan, -0.0])   # beyond int64, not finite, -0
    scalar = np.array([wrap_angle(v) for v in extremes])
    assert np.array_equal(array_wrap(extremes), scalar, equal_nan=True)
    assert np.array_equal(np.signbit(array_wrap(extremes)), np.signbit(scalar))
    inside = np.linspace(-math.pi, math.pi, 1001)[1:]
    assert np.array_equal(array_wrap(inside), inside)
    assert array_wrap(-math.pi) == math.pi and isinstance(array_wrap(1.0), float)


def test_heading_error_sine_and_cosine_are_those_of_the_heading_error():
    """The tracking laws' sin e3, cos e3 by the angle-difference identities are sin and cos of
    e3 = θ_d − θ (any branch: θ anywhere, θ_d in (−π, π]) to an absolute 3e-16 of the exact
    values (50 digits), at least as close as sin and cos of the wrapped float difference, and
    keep the sign of a tiny e3 (its sine is what the laws steer by near the reference)."""
    import mpmath

    from nonholo.control.tracking_errors import heading_error_sincos

    mpmath.mp.dps = 50
    rng = np.random.default_rng(7)
    theta = np.concatenate([rng.uniform(-50.0, 50.0, 2000), [0.0, math.pi, -math.pi, 1e-12]])
    theta_d = np.concatenate([rng.uniform(-math.pi, math.pi, 2000), [math.pi, -math.pi + 1e-15, math.pi, 0.0]])
    ours = direct = 0.0
    for a, b in zip(theta, theta_d):
        ref = (0.0,) * 7 + (b, 0.0, 0.0)   # REF_THETA = 7
        s, c = heading_error_sincos(math.cos(a), math.sin(a), ref)
        exact = mpmath.mpf(b) - mpmath.mpf(a)
        exact_s, exact_c = mpmath.sin(exact), mpmath.cos(exact)
        ours = max(ours, float(abs(s - exact_s)), float(abs(c - exact_c)))
        e3 = wrap_angle(b - a)
        direct = max(direct, float(abs(math.sin(e3) - exact_s)), float(abs(math.cos(e3) - exact_c)))
    assert ours < 3e-16 and ours <= direct
    s, _ = heading_error_sincos(1.0, 0.0, (0.0,) * 7 + (1e-9, 0.0, 0.0))
    assert s == pytest.approx(1e-9, rel=1e-9)


def test_sinc_is_continuous_at_zero():
    for x in (0.0, 1e-9, 1e-5, 1e-4, 1e-3, 0.5, -2.0):
        assert sinc_of(x, math.sin(x)) == pytest.approx(1.0 if x == 0 else math.sin(x) / x, rel=1e-15)


def test_expression_parser_builds_sympy_without_eval():
    t = sp.Symbol("t")
    assert parse_expression("6*sin(t/15 + 0.3) + 0.2*t", {"t": t}) == 6 * sp.sin(t / 15 + sp.Rational(3, 10)) + t / 5
    assert parse_expression("t^2 - 2*pi", {"t": t}) == t**2 - 2 * sp.pi


@pytest.mark.parametrize("text, fragment", [
    ("__import__('os').system('x')", "unknown function"), ("t.real", "not allowed"), ("q*t", "unknown symbol 'q'"),
    ("foo(t)", "unknown function 'foo'"), ("sin(t", "cannot parse"), ("", "empty"), ("atan2(t)", "takes 2 argument"), ("(" * 4000 + "t" + ")" * 4000, "cannot parse|nested"), ("t+" * 6000, "longer than"),
], ids=["import", "attribute", "unknown-name", "unknown-function", "syntax", "empty", "arity", "deep-nesting", "too-long"])
def test_expression_parser_rejects_unsafe_or_bad_input(text, fragment):
    with pytest.raises(ExpressionError, match=fragment):
        parse_expression(text, {"t": sp.Symbol("t")})
