"""Linear analysis: Jacobian linearization at an equilibrium (thesis Eq 3.3–3.6), along a
reference trajectory (Eq 3.10–3.14), the similarity transform to the body frame (Eq 3.15–3.18,
Appendices D–E) and the controllability matrices (Appendix B).

Reference trajectories are written with one symbol per state and input, suffixed ``_d``
(θ_d, v_d, ω_d), and the reference inputs are taken constant, as in thesis Eq 3.18.
Points of linearization use the suffix ``_e`` (θ_e) for coordinates left unspecified.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import sympy as sp

from .system import ControlSystem, substitute


@dataclass(frozen=True)
class LinearModel:
    """δẋ = A δx + B δu."""

    A: sp.Matrix
    B: sp.Matrix


def suffixed(symbol: sp.Symbol, suffix: str) -> sp.Symbol:
    """θ → θ_d: the same symbol (same assumptions) on a reference or at a point."""
    return sp.Symbol(f"{symbol.name}_{suffix}", **symbol.assumptions0)


def reference_symbols(system: ControlSystem) -> dict[sp.Symbol, sp.Symbol]:
    """{x: x_d, …, v: v_d, …} for every state and input."""
    return {s: suffixed(s, "d") for s in (*system.states, *system.inputs)}


def linearize(system: ControlSystem, state_values: Mapping, input_values: Mapping) -> LinearModel:
    """A = ∂f/∂x, B = ∂f/∂u evaluated at the given states and inputs (thesis Eq 3.11)."""
    rhs = system.rhs()
    values = {**state_values, **input_values}
    A = substitute(rhs.jacobian(sp.Matrix(system.states)), values).applyfunc(sp.expand)
    B = substitute(rhs.jacobian(sp.Matrix(system.inputs)), values).applyfunc(sp.expand)
    return LinearModel(A, B)


def equilibrium_point(system: ControlSystem, given: Mapping[sp.Symbol, sp.Expr]
                      ) -> dict[sp.Symbol, sp.Expr]:
    """A point p_e: given coordinates keep their values, the others become symbols x_e."""
    return {s: given.get(s, suffixed(s, "e")) for s in system.states}


def linearize_at_point(system: ControlSystem, point: Mapping[sp.Symbol, sp.Expr]) -> LinearModel:
    """Linearization at p_e with zero inputs, which is an equilibrium of any driftless system
    (thesis Eq 3.3–3.5). ``point`` gives state values and may also fix parameters."""
    return linearize(system, point, {u: sp.Integer(0) for u in system.inputs})


def linearize_along_reference(system: ControlSystem) -> LinearModel:
    """A(t) = Σ ∂g_i/∂x|_{x_d} u_di (+ ∂f/∂x for the drift), B(t) = G(x_d) (thesis Eq 3.12–3.13)."""
    reference = reference_symbols(system)
    return linearize(system, {s: reference[s] for s in system.states},
                     {u: reference[u] for u in system.inputs})


def controllability_matrix(A: sp.Matrix, B: sp.Matrix) -> sp.Matrix:
    """C_M = [B, AB, …, A^{n−1}B] (thesis Eq 3.1, Appendix B)."""
    blocks, block = [B], B
    for _ in range(A.rows - 1):
        block = (A * block).applyfunc(sp.simplify)
        blocks.append(block)
    return sp.Matrix.hstack(*blocks)


def time_derivative_on_reference(matrix: sp.Matrix, system: ControlSystem) -> sp.Matrix:
    """d/dt of a matrix of reference coordinates along ẋ_d = f(x_d, u_d), u_d constant."""
    reference = reference_symbols(system)
    reference_rates = substitute(system.rhs(), reference)
    derivative = sp.zeros(matrix.rows, matrix.cols)
    for state, rate in zip(system.states, reference_rates):
        derivative += matrix.diff(reference[state]) * rate
    # expand rather than simplify: simplify takes seconds on the follower models
    return derivative.applyfunc(sp.expand)


def time_varying_controllability_matrix(system: ControlSystem, model: LinearModel) -> sp.Matrix:
    """Silverman–Meadows matrix [K_0, …, K_{n−1}], K_0 = B, K_{i+1} = −A K_i + K̇_i.

    Full rank at some time means the time-varying linearization (Eq 3.14) is controllable;
    this needs no change of frame, unlike the thesis' route through Eq 3.17.
    """
    blocks, block = [model.B], model.B
    for _ in range(system.n - 1):
        block = (-model.A * block + time_derivative_on_reference(block, system)).applyfunc(
            sp.expand)
        blocks.append(block)
    return sp.Matrix.hstack(*blocks)


def similarity_transform(model: LinearModel, T: sp.Matrix, T_dot: sp.Matrix) -> LinearModel:
    """z = T x turns ẋ = A x + B u into ż = (Ṫ T⁻¹ + T A T⁻¹) z + T B u (Appendix D)."""
    T_inverse = sp.simplify(T.inv())
    return LinearModel((T_dot * T_inverse + T * model.A * T_inverse).applyfunc(sp.simplify),
                       (T * model.B).applyfunc(sp.simplify))


def body_frame_rotation(system: ControlSystem) -> sp.Matrix:
    """T of thesis Eq 3.15: rotate the (x, y) error by the reference heading θ_d; other
    states are left unchanged."""
    if system.body_frame is None:
        raise ValueError(f"system {system.name!r} has no planar pose (x, y, heading)")
    x, y = (system.states.index(s) for s in system.body_frame[:2])
    theta_d = reference_symbols(system)[system.body_frame[2]]
    T = sp.eye(system.n)
    T[x, x], T[x, y] = sp.cos(theta_d), sp.sin(theta_d)
    T[y, x], T[y, y] = -sp.sin(theta_d), sp.cos(theta_d)
    return T


def body_frame_model(system: ControlSystem) -> LinearModel:
    """The reference linearization in body-frame error coordinates (thesis Eq 3.17)."""
    T = body_frame_rotation(system)
    return similarity_transform(linearize_along_reference(system), T,
                                time_derivative_on_reference(T, system))
