"""Zero tests for symbolic expressions (the basis of every rank in this package).

An expression is declared non-zero as soon as its value at a random rational point,
evaluated by sympy to 30 significant digits, is clearly non-zero (that proves it). Otherwise
``sympy.simplify`` must reduce it to 0. Both steps are exact; the sampling only saves time.
"""
from __future__ import annotations

import random

import sympy as sp

_SAMPLE_POINTS = 3
_SAMPLE_DIGITS = 30


def is_identically_zero(expression: sp.Expr) -> bool:
    """True when ``expression`` vanishes for all values of its symbols."""
    expression = sp.sympify(expression)
    if expression.is_zero is not None:
        return bool(expression.is_zero)
    if _nonzero_at_a_sample_point(expression):
        return False
    return sp.simplify(expression) == 0


def _nonzero_at_a_sample_point(expression: sp.Expr) -> bool:
    # A value evaluated to 30 significant digits that is clearly non-zero proves the
    # expression is not identically zero; the converse needs the symbolic check.
    generator = random.Random(20240605)  # fixed seed: analyses are reproducible
    symbols = sorted(expression.free_symbols, key=str)
    for _ in range(_SAMPLE_POINTS):
        point = {s: sp.Rational(generator.randint(11, 97), generator.randint(11, 97))
                 for s in symbols}
        value = expression.evalf(_SAMPLE_DIGITS, subs=point)
        if value.is_number and value.is_finite and value.is_real and abs(value) > 1e-20:
            return True
    return False
