"""Lie brackets, bracket trees and Lie derivatives (thesis §2.2, Eq 2.5, Appendix A).

Convention (thesis Eq 2.5, and the MATLAB LieBracket.m of Appendix A):

    [f, g] = (∂g/∂x) f − (∂f/∂x) g.

Some textbooks use the opposite sign; only this one gives [g1, g2] = (sin θ, −cos θ, 0)
for the unicycle (thesis Eq 2.21).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import sympy as sp

from .symbolic import is_identically_zero


def simplify_vector(vector: sp.Matrix) -> sp.Matrix:
    """Component-wise simplification, so that zero brackets print and compare as 0."""
    return vector.applyfunc(sp.simplify)


def lie_bracket(f: sp.Matrix, g: sp.Matrix, states: Sequence[sp.Symbol]) -> sp.Matrix:
    """[f, g] = (∂g/∂x) f − (∂f/∂x) g, simplified."""
    x = sp.Matrix(states)
    return simplify_vector(g.jacobian(x) * f - f.jacobian(x) * g)


def lie_derivative(function: sp.Expr, field: sp.Matrix, states: Sequence[sp.Symbol]) -> sp.Expr:
    """L_f h = ∇h · f, the rate of change of h along the flow of f."""
    gradient = sp.Matrix([function]).jacobian(sp.Matrix(states))
    # expand, not simplify: simplify costs seconds on the follower models' second
    # derivatives, and ranks are decided by exact zero tests anyway.
    return sp.expand((gradient * field)[0, 0])


def repeated_lie_derivatives(function: sp.Expr, field: sp.Matrix, states: Sequence[sp.Symbol],
                             order: int) -> list[sp.Expr]:
    """[h, L_f h, L_f² h, …, L_f^order h]."""
    derivatives = [sp.expand(function)]
    for _ in range(order):
        derivatives.append(lie_derivative(derivatives[-1], field, states))
    return derivatives


@dataclass(frozen=True)
class BracketNode:
    """One node of the Lie-bracket tree: a generator or a left-nested bracket [X, child]."""

    label: str
    depth: int  # number of generators in the bracket: 1 for g_i, 2 for [g_i, g_j], …
    vector: sp.Matrix

    @property
    def is_zero(self) -> bool:
        return all(is_identically_zero(component) for component in self.vector)


def bracket_tree(generators: Sequence[tuple[str, sp.Matrix]], states: Sequence[sp.Symbol],
                 depth: int) -> list[list[BracketNode]]:
    """Levels 1…depth of left-nested brackets [X_{i1}, [X_{i2}, … [X_{ik-1}, X_{ik}]]].

    Left-nested brackets of the generators span every bracket of the same length (a
    consequence of the Jacobi identity), so this tree suffices for the accessibility
    filtration and for nilpotency. Level 2 keeps only i < j (skew symmetry, Eq 2.6) and
    zero brackets are listed but not expanded (all their children vanish).
    """
    levels = [[BracketNode(label, 1, simplify_vector(vector)) for label, vector in generators]]
    for level_depth in range(2, depth + 1):
        level = []
        for child_index, child in enumerate(levels[-1]):
            if child.is_zero:
                continue
            for generator_index, (label, vector) in enumerate(generators):
                if level_depth == 2 and generator_index >= child_index:
                    continue
                level.append(BracketNode(f"[{label}, {child.label}]", level_depth,
                                         lie_bracket(vector, child.vector, states)))
        levels.append(level)
    return levels
