"""Ranks of distributions, involutivity (Frobenius), the accessibility filtration
(Chow–Rashevskii / LARC, thesis Eq 3.7–3.9), nilpotency, and where a rank is lost.

Ranks are *generic* ranks over the field of functions of the symbols: a set of columns is
independent when one of its maximal minors is not identically zero (``symbolic``).
"""
from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import sympy as sp

from .lie import BracketNode
from .symbolic import is_identically_zero

_SIMPLIFY_LIMIT = 60  # operations; larger minors are left as they are (simplify is slow)

def independent_columns(columns: Sequence[sp.Matrix]) -> list[int]:
    """Indices of a maximal independent subset, chosen greedily in the given order.

    Greedy selection yields a basis of any matroid, here linear independence over the
    function field, so ``len`` of the result is the generic rank.
    """
    basis: list[int] = []
    for index, column in enumerate(columns):
        candidate = sp.Matrix.hstack(*(columns[i] for i in basis), column)
        if _has_full_column_rank(candidate):
            basis.append(index)
    return basis


def _has_full_column_rank(matrix: sp.Matrix) -> bool:
    size = matrix.cols
    if size > matrix.rows:
        return False
    return any(not is_identically_zero(matrix.extract(list(rows), list(range(size))).det())
               for rows in itertools.combinations(range(matrix.rows), size))


def generic_rank(matrix: sp.Matrix) -> int:
    """Rank of ``matrix`` for generic values of its symbols."""
    return len(independent_columns([matrix[:, j] for j in range(matrix.cols)]))


def maximal_minors(matrix: sp.Matrix, size: int) -> list[sp.Expr]:
    """All non-zero size×size minors."""
    minors = []
    for rows in itertools.combinations(range(matrix.rows), size):
        for cols in itertools.combinations(range(matrix.cols), size):
            minor = matrix.extract(list(rows), list(cols)).det(method="berkowitz")
            if not is_identically_zero(minor):
                minors.append(sp.factor(sp.cancel(minor)))
    return minors


def rank_loss_conditions(matrix: sp.Matrix, rank: int) -> list[list[sp.Expr]]:
    """Where the generic rank ``rank`` drops: a list of alternatives, each a list of
    expressions that vanish together there.

    First the factors common to every rank×rank minor (each one's vanishing is a
    hypersurface on which the rank drops, e.g. v = 0 for the unicycle's observability).
    If there is none and the minors are polynomial, the common zeros are solved for
    (e.g. v_d = ω_d = 0 for thesis Eq 3.18). Lower-dimensional rank drops of
    non-polynomial minors are not searched for.
    """
    if rank == 0:
        return []
    minors = maximal_minors(matrix, rank)
    common = _common_factors(minors)
    if common:
        return [[factor] for factor in common]
    if all(sp.count_ops(m) <= _SIMPLIFY_LIMIT for m in minors):
        # trig identities can turn minors polynomial, e.g. −ω_d (sin²θ_d + cos²θ_d) → −ω_d
        minors = [sp.simplify(m) for m in minors]
    symbols = sorted(set().union(*(m.free_symbols for m in minors)), key=str)
    if symbols and all(m.is_polynomial(*symbols) for m in minors):
        return [[s - value for s, value in sorted(solution.items(), key=lambda kv: str(kv[0]))]
                for solution in sp.solve(minors, symbols, dict=True)]
    return []


def _common_factors(minors: Sequence[sp.Expr]) -> list[sp.Expr]:
    factor_sets = []
    for minor in minors:
        numerator = sp.together(minor).as_numer_denom()[0]
        _, factors = sp.factor_list(numerator)
        factor_sets.append({f for f, _ in factors if f.free_symbols})
    common = set.intersection(*factor_sets) if factor_sets else set()
    return sorted((f for f in common if _can_vanish(f)), key=str)


def _can_vanish(factor: sp.Expr) -> bool:
    """False for factors such as a positive parameter l or tan²φ + 1 = 1/cos²φ that are
    never zero, so that they are not reported as rank-loss conditions."""
    numerator = sp.together(sp.simplify(factor)).as_numer_denom()[0]
    return bool(numerator.free_symbols) and not (numerator.is_positive or numerator.is_negative)


@dataclass(frozen=True)
class Filtration:
    """Ranks of Δ1 ⊂ Δ2 ⊂ … (thesis Eq 3.8) and the first degree reaching rank n."""

    ranks: tuple[int, ...]  # ranks[k-1] = rank Δ_k
    degree: int | None  # smallest k with rank Δ_k = n, None if not reached up to the depth
    basis: tuple[str, ...]  # labels of the brackets forming a basis

    @property
    def rank(self) -> int:
        return self.ranks[-1]


def accessibility_filtration(levels: Sequence[Sequence[BracketNode]], n: int,
                             at: dict | None = None) -> Filtration:
    """Ranks of the accessibility filtration Δ_k = span of brackets of length ≤ k.

    With ``at`` the vector fields are evaluated at that point first.
    """
    ranks, basis_labels, basis_vectors = [], [], []
    for level in levels:
        for node in level:
            if len(basis_vectors) == n:
                break
            vector = node.vector.subs(at, simultaneous=True) if at else node.vector
            if _has_full_column_rank(sp.Matrix.hstack(*basis_vectors, vector)):
                basis_vectors.append(vector)
                basis_labels.append(node.label)
        ranks.append(len(basis_vectors))
    degree = next((k + 1 for k, rank in enumerate(ranks) if rank == n), None)
    return Filtration(tuple(ranks), degree, tuple(basis_labels))


def is_involutive(fields: Sequence[sp.Matrix], brackets: Sequence[sp.Matrix]) -> bool:
    """Frobenius: span{g_i} is involutive iff every [g_i, g_j] lies in it (thesis Eq 2.8)."""
    base_rank = generic_rank(sp.Matrix.hstack(*fields))
    return all(generic_rank(sp.Matrix.hstack(*fields, b)) == base_rank for b in brackets)


def nilpotency_step(levels: Sequence[Sequence[BracketNode]]) -> int | None:
    """Smallest s such that every bracket of length s + 1 vanishes identically, i.e. the
    Lie algebra is nilpotent of step s; None if no level up to the depth vanishes."""
    for depth_index, level in enumerate(levels[1:], start=2):
        if all(node.is_zero for node in level):
            return depth_index - 1
    return None
