"""Observability from repeated Lie derivatives of the outputs (thesis §3.3, Eq 3.19–3.28).

As in the thesis, the inputs are treated as constant symbols while differentiating: the
observability map stacks h, L_f h, …, L_f^{n−1} h with f = f(x, u) (Eq 3.21, listing each
order once — erratum 2 of spec leader.md), ordered by derivative order, outputs inside each
order (o1, o2, ȯ1, ȯ2, … as in Eq 3.27). Its Jacobian is the observability matrix; full
rank n means the state can be reconstructed locally from outputs and inputs.
"""
from __future__ import annotations

from collections.abc import Sequence

import sympy as sp

from .lie import repeated_lie_derivatives
from .system import ControlSystem


def observability_map(system: ControlSystem, outputs: Sequence[sp.Expr] | None = None,
                      order: int | None = None) -> sp.Matrix:
    """Φ(x) = [h; L_f h; …; L_f^order h] (order n−1 by default)."""
    outputs = tuple(outputs if outputs is not None else system.outputs)
    if not outputs:
        raise ValueError(f"system {system.name!r} declares no outputs")
    order = system.n - 1 if order is None else order
    by_output = [repeated_lie_derivatives(h, system.rhs(), system.states, order)
                 for h in outputs]
    return sp.Matrix([derivatives[k] for k in range(order + 1) for derivatives in by_output])


def observability_matrix(system: ControlSystem, outputs: Sequence[sp.Expr] | None = None,
                         order: int | None = None) -> sp.Matrix:
    """∂Φ/∂x (thesis Eq 3.25, 3.27)."""
    return map_jacobian(observability_map(system, outputs, order), system)


def map_jacobian(phi: sp.Matrix, system: ControlSystem) -> sp.Matrix:
    """∂Φ/∂x of an already computed observability map."""
    return phi.jacobian(sp.Matrix(system.states)).applyfunc(sp.expand)
