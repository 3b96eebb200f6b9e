"""The control-affine system ẋ = f(x) + Σ g_i(x) u_i that every analysis works on."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import sympy as sp


@dataclass(frozen=True)
class ChainedFormTransform:
    """A change of coordinates z = z(x) and of inputs u = u(x, w) to be checked against the
    (2, n) chained form (thesis §3.4); ``reference`` names the equation it comes from."""

    reference: str
    coordinates: tuple[sp.Expr, ...]
    new_inputs: tuple[sp.Symbol, ...]
    input_map: tuple[sp.Expr, ...]


@dataclass(frozen=True)
class FlatParametrization:
    """States and inputs as functions of flat outputs y_k(t) and their derivatives."""

    time: sp.Symbol
    flat_outputs: tuple[sp.Expr, ...]  # y_k(t) as applied undefined functions
    output_map: tuple[sp.Expr, ...]  # y_k = output_map[k](x): which functions of x are flat
    states: tuple[sp.Expr, ...]
    inputs: tuple[sp.Expr, ...]
    validity: str  # where the parametrization is defined (e.g. "ẋ² + ẏ² ≠ 0")


@dataclass(frozen=True)
class ControlSystem:
    """ẋ = drift(x) + Σ fields[i](x) · inputs[i].

    ``parameters`` maps a parameter name to its value: a number for user files, the
    symbol itself when the parameter stays symbolic (built-in systems). ``outputs`` are the
    measured functions h(x) used for observability. ``body_frame`` names the (x, y, heading)
    states when the system has a planar pose, which enables the body-frame similarity
    transform of thesis Eq 3.15–3.18.
    """

    name: str
    description: str
    states: tuple[sp.Symbol, ...]
    inputs: tuple[sp.Symbol, ...]
    fields: tuple[sp.Matrix, ...]
    drift: sp.Matrix | None = None
    outputs: tuple[sp.Expr, ...] = ()
    parameters: dict[str, sp.Expr] = field(default_factory=dict)
    body_frame: tuple[sp.Symbol, sp.Symbol, sp.Symbol] | None = None
    chained_forms: tuple[ChainedFormTransform, ...] = ()
    flatness: FlatParametrization | None = None

    @property
    def n(self) -> int:
        return len(self.states)

    @property
    def m(self) -> int:
        return len(self.inputs)

    @property
    def has_drift(self) -> bool:
        return self.drift is not None and not self.drift.is_zero_matrix

    def input_matrix(self) -> sp.Matrix:
        """G(x) = [g_1 … g_m]."""
        return sp.Matrix.hstack(*self.fields)

    def rhs(self) -> sp.Matrix:
        """f(x, u) = drift + G(x) u with the input symbols kept as symbols."""
        controlled = self.input_matrix() * sp.Matrix(self.inputs)
        return controlled + self.drift if self.has_drift else controlled

    def names(self) -> dict[str, sp.Symbol]:
        """Every name that may be assigned a value at an analysis point."""
        symbols = {str(s): s for s in (*self.states, *self.inputs)}
        symbols.update({name: value for name, value in self.parameters.items()
                        if isinstance(value, sp.Symbol)})
        return symbols


def control_affine_from_rates(rates: Sequence[sp.Expr], inputs: Sequence[sp.Symbol]
                              ) -> tuple[sp.Matrix | None, tuple[sp.Matrix, ...]]:
    """Split model rates f(x, u) into (drift, fields) with g_i = ∂f/∂u_i.

    Raises ValueError when f is not affine in the inputs, since every Chapter 3 analysis
    assumes the control-affine form of thesis Eq 2.3.
    """
    rates = sp.Matrix(rates)
    fields = tuple(rates.diff(u) for u in inputs)
    for g in fields:
        if any(not g.diff(u).is_zero_matrix for u in inputs):
            raise ValueError("the model is not affine in its inputs")
    drift = rates.subs({u: 0 for u in inputs})
    return (None if drift.is_zero_matrix else drift), fields


def substitute(expression: sp.Basic, values: dict) -> sp.Basic:
    """``expression`` with ``values`` substituted simultaneously (safe for swaps x→y, y→x)."""
    return expression.subs(values, simultaneous=True) if values else expression

