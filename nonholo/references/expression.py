"""References given by formulas x_d(t), y_d(t), differentiated exactly with sympy."""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import sympy as sp

from nonholo.expressions import parse_expression
from nonholo.numerics import array_cos, array_sin
from nonholo.references.base import FORWARD, Reference

T = sp.Symbol("t", real=True)


class ExpressionReference(Reference):
    """p_d(t) = (x(t), y(t)) from sympy expressions in the symbol ``t``.

    Derivatives are exact (sympy), then compiled once to vectorized numpy code.
    """

    kind = "expression"

    def __init__(self, x: sp.Expr, y: sp.Expr, direction: int = FORWARD,
                 default_duration: float | None = None, parameters: Mapping[str, float] | None = None):
        super().__init__(direction, default_duration)
        self.x_expr = sp.sympify(x)
        self.y_expr = sp.sympify(y)
        self.parameters = dict(parameters or {})
        derivatives = []
        for expr in (self.x_expr, self.y_expr):
            d1 = sp.diff(expr, T)
            derivatives.append((expr, d1, sp.diff(d1, T)))
        (x0, x1, x2), (y0, y1, y2) = derivatives
        self._exprs = (x0, y0, x1, y1, x2, y2)
        # sin and cos dominate the cost of evaluating a reference table: use the SIMD ones.
        self._evaluate = sp.lambdify(T, list(self._exprs), modules=[{"sin": array_sin, "cos": array_cos}, "numpy"],
                                     cse=True)

    @classmethod
    def from_strings(cls, x: str, y: str, direction: int = FORWARD, default_duration: float | None = None,
                     parameters: Mapping[str, float] | None = None) -> "ExpressionReference":
        """Parse ``x`` and ``y`` safely (no eval); ``parameters`` are named constants."""
        names = {"t": T, **{k: sp.Float(v) for k, v in (parameters or {}).items()}}
        return cls(parse_expression(x, names), parse_expression(y, names), direction, default_duration, parameters)

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
