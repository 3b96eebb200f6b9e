"""Run every Chapter 3 analysis on one system and collect the results."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import sympy as sp

from .chained import ChainedFormCheck, FlatnessCheck, check_chained_form, check_flatness
from .distributions import (Filtration, accessibility_filtration, generic_rank, is_involutive,
                            nilpotency_step, rank_loss_conditions)
from .lie import BracketNode, bracket_tree
from .linear import (LinearModel, body_frame_model, controllability_matrix, equilibrium_point,
                     linearize_along_reference, linearize_at_point, suffixed,
                     time_varying_controllability_matrix)
from .observability import map_jacobian, observability_map, observability_matrix
from .system import ControlSystem, substitute


@dataclass(frozen=True)
class RankResult:
    """A matrix, its generic rank and where that rank is lost."""

    matrix: sp.Matrix
    rank: int
    rank_loss: list[list[sp.Expr]]


@dataclass(frozen=True)
class Summary:
    system: ControlSystem
    depth: int
    at: dict[sp.Symbol, sp.Expr]
    brackets: list[list[BracketNode]]
    involutive: bool
    filtration: Filtration
    filtration_at_point: Filtration | None
    nilpotency_step: int | None
    point: dict[sp.Symbol, sp.Expr]
    linear_at_point: LinearModel
    controllability_at_point: RankResult
    along_reference: LinearModel
    controllability_along_reference: RankResult
    body_frame: LinearModel | None
    controllability_body_frame: RankResult | None
    observability_map: sp.Matrix | None
    observability: RankResult | None
    observability_first_order: RankResult | None  # h and L_f h only (thesis Eq 3.28)
    observability_rank_at_point: int | None
    chained_forms: list[ChainedFormCheck]
    flatness: FlatnessCheck | None


def rank_result(matrix: sp.Matrix) -> RankResult:
    rank = generic_rank(matrix)
    return RankResult(matrix, rank, rank_loss_conditions(matrix, rank))


def is_time_invariant(model: LinearModel, system: ControlSystem) -> bool:
    """True when A and B involve no reference state (only the constant u_d), so that the
    constant-matrix controllability test of thesis Eq 3.18 applies."""
    reference_states = {suffixed(x, "d") for x in system.states}
    return not (model.A.free_symbols | model.B.free_symbols) & reference_states


def field_generators(system: ControlSystem) -> list[tuple[str, sp.Matrix]]:
    """(g1, …, gm): the control vector fields, labelled as in thesis Eq 2.19."""
    return [(f"g{i}", field) for i, field in enumerate(system.fields, start=1)]


def summarize(system: ControlSystem, depth: int = 3,
              at: Mapping[sp.Symbol, sp.Expr] | None = None) -> Summary:
    """All analyses of ``system``: brackets to ``depth``; ``at`` fixes some symbols
    (states, inputs, symbolic parameters) for the point-wise results."""
    at = dict(at or {})
    # Frobenius needs the pairs [g_i, g_j] even when the requested depth is 1.
    tree = bracket_tree(field_generators(system), system.states, max(depth, 2))
    levels, level_two = tree[:depth], tree[1]
    point = equilibrium_point(system, at)
    parameter_values = {s: v for s, v in at.items() if s not in system.states}
    at_point = linearize_at_point(system, {**point, **parameter_values})
    along = linearize_along_reference(system)
    body = body_frame_model(system) if system.body_frame else None
    phi = observability_map(system) if system.outputs else None
    observability = rank_result(map_jacobian(phi, system)) if phi is not None else None
    return Summary(
        system=system, depth=depth, at=at, brackets=levels,
        involutive=is_involutive(system.fields, [node.vector for node in level_two]),
        filtration=accessibility_filtration(levels, system.n),
        filtration_at_point=accessibility_filtration(levels, system.n, at) if at else None,
        nilpotency_step=nilpotency_step(levels),
        point=point,
        linear_at_point=at_point,
        controllability_at_point=rank_result(controllability_matrix(at_point.A, at_point.B)),
        along_reference=along,
        controllability_along_reference=rank_result(
            time_varying_controllability_matrix(system, along)),
        body_frame=body,
        controllability_body_frame=rank_result(controllability_matrix(body.A, body.B))
        if body and is_time_invariant(body, system) else None,
        observability_map=phi,
        observability_first_order=rank_result(observability_matrix(system, order=1))
        if system.outputs and system.n > 1 else None,
        observability=observability,
        observability_rank_at_point=generic_rank(substitute(observability.matrix, at))
        if observability and at else None,
        chained_forms=[check_chained_form(system, t) for t in system.chained_forms],
        flatness=check_flatness(system, system.flatness) if system.flatness else None,
    )
