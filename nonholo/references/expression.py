"""References given by formulas x_d(t), y_d(t), differentiated exactly with sympy.

The feedforward needs p_d and its first two derivatives, so a formula is accepted only if
sympy can differentiate it twice into something finite and smooth: ``Abs(t - 3)`` (a
corner, whose derivatives are ``sign`` and ``DiracDelta``) is refused, naming the
function and the first time where it fails.

Symbolic work is bounded by sizes, not by a clock: the parser's limits bound the formula
(``nonholo.expressions``), the first derivative of each coordinate may have at most
``MAX_DERIVATIVE_NODES`` nodes and the six expressions compiled together at most
``MAX_COMPILED_NODES``. Differentiating twice costs at most about the square of the first
bound, so no accepted formula takes more than about a second here (measured on the worst
families: products of many factors, towers of powers, nested functions). Sizes rather than a
timeout: a file is accepted or refused alike on every machine and under any load, and no
signal, thread or worker process is needed.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from operator import itemgetter

import numpy as np
import sympy as sp

from nonholo.errors import ExpressionError, InfeasibleReferenceError, ScenarioError
from nonholo.expressions import (MAX_NAME_LENGTH, RESERVED_NAMES, check_constants, check_name, exact_number, formula_of,
                                 expression_size, parse_expression, quote, symbolic_budget, sympy_failures)
from nonholo.numerics import array_sincos
from nonholo.references.base import FORWARD, Reference

T = sp.Symbol("t", real=True)

RESERVED_PARAMETERS = frozenset({"t", "kind", "x", "y", "direction", "parameters"}) | RESERVED_NAMES
"""Names a formula parameter may not take: time, the keys of ``describe()`` (parameters
are reported beside them) and the function and constant names."""
MAX_DERIVATIVE_NODES = 1_000
"""Nodes of dx/dt (and of dy/dt): the largest formulas the parser accepts need 700 (a
90-term Fourier series) to 830 (a degree-166 polynomial); products of many factors reach it
first (13 sines), as their second derivatives grow with the cube of the factor count."""
MAX_COMPILED_NODES = 100_000
"""Nodes of x, y and their two derivatives together, compiled to numpy at once."""
SEARCH_HORIZON = 1_000.0
"""Seconds searched for the time where a non-smooth function fails, when the reference
has no natural duration (the thesis' longest run)."""
NON_SMOOTH = (sp.Abs, sp.sign, sp.Heaviside, sp.DiracDelta, sp.floor, sp.ceiling, sp.Piecewise, sp.Min, sp.Max,
              sp.re, sp.im, sp.arg, sp.Derivative, sp.Subs)
_ORDER = ("", "the first derivative of ", "the second derivative of ")
_WHOSE = ("", "its first derivative has ", "its second derivative has ")


class ExpressionReference(Reference):
    """p_d(t) = (x(t), y(t)) from sympy expressions in the symbol ``t``.

    Derivatives are exact (sympy), then compiled once to vectorized numpy code.
    """

    kind = "expression"

    def __init__(self, x: sp.Expr, y: sp.Expr, direction: int = FORWARD,
                 default_duration: float | None = None, parameters: Mapping[str, float] | None = None):
        super().__init__(direction, default_duration)
        with formula_of("x"):
            self.x_expr = _formula(x, "x")
        with formula_of("y"):
            self.y_expr = _formula(y, "y")
        self.parameters = dict(parameters or {})
        with sympy_failures(f"x = {quote(str(self.x_expr))}, y = {quote(str(self.y_expr))}"):
            derivatives = []
            for expr, label in ((self.x_expr, "x"), (self.y_expr, "y")):
                with formula_of(label):
                    derivatives.append(_derivatives(expr, label))
            (x0, x1, x2), (y0, y1, y2) = derivatives
            self._exprs = (x0, y0, x1, y1, x2, y2)
            self._check_smooth()
            if sum(expression_size(e, MAX_COMPILED_NODES) for e in self._exprs) > MAX_COMPILED_NODES:
                raise ExpressionError(f"the formulas and their derivatives have more than {MAX_COMPILED_NODES:,} "
                                      "nodes together: write a smaller formula")
            numeric = [_paired_sin_cos(_for_numpy(e, label)) for e, label in zip(self._exprs, ("x", "y") * 3)]
            self._evaluate = sp.lambdify(T, numeric, modules=[_PAIRED_SIN_COS, "numpy"], cse=True)

    @classmethod
    def from_strings(cls, x: str, y: str, direction: int = FORWARD, default_duration: float | None = None,
                     parameters: Mapping[str, float] | None = None) -> "ExpressionReference":
        """Parse ``x`` and ``y`` safely (no eval); ``parameters`` are named constants."""
        values = _parameters(parameters)
        names = {"t": T, **values}
        with symbolic_budget(f"x = {quote(str(x))}, y = {quote(str(y))}"):
            return cls(parse_expression(x, names, "x"), parse_expression(y, names, "y"), direction,
                       default_duration, {name: float(value) for name, value in values.items()})

    def flat_outputs(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        out = np.empty((6,) + t.shape)
        with np.errstate(all="ignore"):  # non-finite values are reported by the simulator's check
            values = self._evaluate(t)
        for row, value in zip(out, values):
            row[...] = value  # constant derivatives come back as scalars
        return out

    def describe(self) -> dict:
        return {"kind": self.kind, "x": str(self.x_expr), "y": str(self.y_expr),
                "direction": "forward" if self.direction == FORWARD else "backward", **self.parameters}

    def _check_smooth(self) -> None:
        """``InfeasibleReferenceError`` naming the first non-smooth function in x, y or
        their derivatives (lowest order first) and the first time t >= 0 where it fails."""
        for order in range(3):
            for label, expr in zip("xy", self._exprs[2 * order:2 * order + 2]):
                found = sorted(expr.atoms(*NON_SMOOTH), key=sp.default_sort_key)
                if not found:
                    continue
                formula = self.x_expr if label == "x" else self.y_expr
                raise InfeasibleReferenceError(
                    f"{label} = {quote(str(formula))} is not twice differentiable, as the feedforward needs: "
                    f"{_WHOSE[order]}{self._where_not_smooth(found[0])}")

    def _where_not_smooth(self, function: sp.Expr) -> str:
        """``function`` (Abs, sign, ...) and the first t in [0, horizon] where its argument
        vanishes, searched numerically."""
        shown = quote(str(function))
        if not function.args or function.args[0].free_symbols != {T}:
            return f"{shown} is not smooth"
        argument = function.args[0]
        horizon = self.default_duration if _positive(self.default_duration) else SEARCH_HORIZON
        compiled = sp.lambdify(T, _for_numpy(argument, "the argument"), "numpy")

        def evaluate(times: np.ndarray) -> np.ndarray:  # real values, NaN where complex or undefined
            with np.errstate(all="ignore"):
                values = np.broadcast_to(np.asarray(compiled(times), dtype=complex), times.shape)
            return np.where(np.abs(values.imag) < 1e-12, values.real, np.nan)

        from scipy.optimize import brentq   # here: scipy.optimize costs every command 0.2 s to import

        grid = np.linspace(0.0, horizon, 10_001)
        values = evaluate(grid)
        zero = np.flatnonzero(values == 0)
        change = np.flatnonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0)
        candidates = [grid[zero[0]]] if zero.size else []
        if change.size:
            i = change[0]
            try:
                candidates.append(brentq(lambda s: float(evaluate(np.array([s]))[0]), grid[i], grid[i + 1],
                                         xtol=1e-12))
            except (ValueError, RuntimeError):  # a pole, or not converging: keep the grid point
                candidates.append(grid[i])
        where = f"{shown} is not smooth where {quote(str(argument))} = 0"
        if not candidates:
            return (f"{where} (no such t in [0, {horizon:g}] s; if it never vanishes, write the formula "
                    f"without {function.func.__name__})")
        return f"{where}, first at t = {min(candidates):.6g} s"


def _formula(value, label: str) -> sp.Expr:
    """A formula given as sympy (or parsed safely from a string) in the symbol ``t`` only."""
    if isinstance(value, str):
        return parse_expression(value, {"t": T}, label)
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return exact_number(value)
    if not isinstance(value, sp.Expr):
        raise ExpressionError(f"{label}: expected a formula in t, got {type(value).__name__}")
    others = sorted(str(s) for s in value.free_symbols - {T})
    if others:
        raise ExpressionError(f"{label} = {quote(str(value))} has symbols other than t: {', '.join(others)}")
    check_constants(value, label)
    return value


def _derivatives(expr: sp.Expr, label: str) -> tuple[sp.Expr, sp.Expr, sp.Expr]:
    first = sp.diff(expr, T)
    if expression_size(first, MAX_DERIVATIVE_NODES) > MAX_DERIVATIVE_NODES:
        raise ExpressionError(f"the derivative of {label} = {quote(str(expr))} has more than "
                              f"{MAX_DERIVATIVE_NODES:,} nodes: write a smaller formula")
    second = sp.diff(first, T)
    for order, derivative in ((1, first), (2, second)):
        if derivative.has(sp.zoo, sp.nan, sp.oo, -sp.oo):
            raise ExpressionError(f"{_ORDER[order]}{label} = {quote(str(expr))} is not finite")
    return expr, first, second


def _for_numpy(expr: sp.Expr, label: str) -> sp.Expr:
    """``expr`` with each constant part as one float, evaluated by sympy to full precision:
    numpy's functions refuse Python integers beyond int64 (``arctan(10**300)``), and a
    constant that cancels in floating point would divide by zero as Python floats.
    ``ExpressionError`` for a constant that is not a finite real number (in a derivative of
    ``label``: ``(-2)**t`` brings ``log(-2)``)."""
    if expr.is_Rational:
        return sp.Float(expr, 17) if max(abs(expr.p), expr.q) >= 2**53 else expr
    if expr.is_number and not expr.is_Number and not expr.is_NumberSymbol:
        value = expr.evalf(17)
        if not (value.is_Number and value.is_finite):
            raise ExpressionError(f"{label} or its derivatives have the constant {quote(str(expr))}, which is not "
                                  "a finite real number")
        return value
    if not expr.args:
        return expr
    args = [_for_numpy(a, label) for a in expr.args]
    return expr if all(a is b for a, b in zip(args, expr.args)) else expr.func(*args)


# sin and cos dominate the cost of evaluating a reference table, and a formula's derivatives
# take both of each argument: every sin(a) and cos(a) is rewritten as one element of a pair
# computed once per argument (common subexpression elimination finds the shared pair) by the
# SIMD ``array_sincos``.
_SIN_COS_PAIR, _SIN_OF, _COS_OF = sp.Function("sin_cos_pair"), sp.Function("sin_of"), sp.Function("cos_of")
_PAIRED_SIN_COS = {"sin_cos_pair": array_sincos, "sin_of": itemgetter(0), "cos_of": itemgetter(1)}


def _paired_sin_cos(expr: sp.Expr) -> sp.Expr:
    """``expr`` with sin(a) and cos(a) as the two elements of the pair ``sin_cos_pair(a)``."""
    return expr.replace(sp.sin, lambda a: _SIN_OF(_SIN_COS_PAIR(a))).replace(
        sp.cos, lambda a: _COS_OF(_SIN_COS_PAIR(a)))


def _parameters(parameters) -> dict[str, sp.Rational]:
    """Formula parameters as exact numbers; names reserved or unusable in a formula, and
    values that are not finite numbers, are refused."""
    if parameters is None:
        return {}
    if not isinstance(parameters, Mapping):
        raise ScenarioError("expression reference", "parameters", "expected a table of name = number")
    values = {}
    for name, value in parameters.items():
        problem = check_name(name)
        if problem:  # a long or odd name is quoted, shortened, in the problem only
            plain = isinstance(name, str) and name.isidentifier() and len(name) <= MAX_NAME_LENGTH
            raise ScenarioError("expression reference", f"parameters.{name}" if plain else "parameters", problem)
        if name in RESERVED_PARAMETERS:
            raise ScenarioError("expression reference", f"parameters.{name}",
                                "reserved name (t is time; kind, x, y and direction are reported beside the "
                                "parameters; function and constant names are taken)")
        try:
            values[name] = exact_number(value)
        except ExpressionError as exc:
            raise ScenarioError("expression reference", f"parameters.{name}", str(exc)) from None
    return values


def _positive(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0
