"""Chained forms and differential flatness (thesis §3.4–3.5).

The (2, n) chained form is

    ż1 = w1,   ż2 = w2,   ż3 = z2 w1,   …,   żn = z_{n−1} w1.

A transformation (z = z(x), u = u(x, w)) is verified by computing ż = (∂z/∂x) f(x, u(x, w))
and checking that it equals the chained form evaluated at z(x) identically; it must also be
a local change of coordinates and of inputs (non-vanishing Jacobian determinants).
A flat parametrization is verified by substituting it into ẋ = f(x, u).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import sympy as sp

from .symbolic import is_identically_zero
from .system import ChainedFormTransform, ControlSystem, FlatParametrization, substitute


def chained_form_rates(z: Sequence[sp.Expr], w: Sequence[sp.Expr]) -> sp.Matrix:
    """Right-hand side of the (2, n) chained form at coordinates z and inputs w."""
    w1, w2 = w
    return sp.Matrix([w1, w2, *(z[k - 1] * w1 for k in range(2, len(z)))])


@dataclass(frozen=True)
class ChainedFormCheck:
    """Outcome of checking one transformation against the chained form."""

    reference: str
    residual: sp.Matrix  # ż − chained form; identically 0 for a valid transformation
    coordinate_determinant: sp.Expr  # det ∂z/∂x
    input_determinant: sp.Expr  # det ∂u/∂w

    @property
    def is_chained_form(self) -> bool:
        return (self.residual.is_zero_matrix
                and not is_identically_zero(self.coordinate_determinant)
                and not is_identically_zero(self.input_determinant))


def check_chained_form(system: ControlSystem, transform: ChainedFormTransform) -> ChainedFormCheck:
    """Whether ``transform`` brings ``system`` into the (2, n) chained form."""
    z = sp.Matrix(transform.coordinates)
    inputs = dict(zip(system.inputs, transform.input_map))
    z_rates = z.jacobian(sp.Matrix(system.states)) * substitute(system.rhs(), inputs)
    residual = (z_rates - chained_form_rates(list(z), transform.new_inputs)).applyfunc(
        sp.simplify)
    input_jacobian = sp.Matrix(transform.input_map).jacobian(sp.Matrix(transform.new_inputs))
    return ChainedFormCheck(
        transform.reference,
        residual,
        sp.simplify(z.jacobian(sp.Matrix(system.states)).det()),
        sp.simplify(input_jacobian.det()),
    )


@dataclass(frozen=True)
class FlatnessCheck:
    """Residuals of ẋ = f(x, u) and of y = h(x) along the flat parametrization."""

    dynamics_residual: sp.Matrix
    output_residual: sp.Matrix

    @property
    def is_flat_parametrization(self) -> bool:
        return self.dynamics_residual.is_zero_matrix and self.output_residual.is_zero_matrix


def check_flatness(system: ControlSystem, flat: FlatParametrization) -> FlatnessCheck:
    """Substitute x(t), u(t) built from the flat outputs into the model and into y = h(x)."""
    along_flat = dict(zip(system.states, flat.states)) | dict(zip(system.inputs, flat.inputs))
    state_rates = sp.Matrix(flat.states).diff(flat.time)
    dynamics = (state_rates - substitute(system.rhs(), along_flat)).applyfunc(sp.simplify)
    outputs = (substitute(sp.Matrix(flat.output_map), along_flat)
               - sp.Matrix(flat.flat_outputs)).applyfunc(sp.simplify)
    return FlatnessCheck(dynamics, outputs)
