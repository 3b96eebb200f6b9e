"""Observability (thesis §3.3, Eq 3.22–3.28)."""
import sympy as sp

from nonholo.analysis import (BUILTIN_SYSTEMS, generic_rank, observability_map,
                              observability_matrix, rank_loss_conditions)


def test_unicycle_observability_map_and_matrix_eq_3_24_3_25():
    unicycle = BUILTIN_SYSTEMS["unicycle"]()
    x, y, theta = unicycle.states
    v, omega = unicycle.inputs
    c, s = sp.cos(theta), sp.sin(theta)
    assert observability_map(unicycle) == sp.Matrix(
        [x, y, v * c, v * s, -v * omega * s, v * omega * c])
    O = observability_matrix(unicycle)
    assert O == sp.Matrix([[1, 0, 0], [0, 1, 0], [0, 0, -v * s], [0, 0, v * c],
                           [0, 0, -v * omega * c], [0, 0, -v * omega * s]])


def test_unicycle_full_rank_iff_v_nonzero():
    unicycle = BUILTIN_SYSTEMS["unicycle"]()
    theta = unicycle.states[2]
    v, omega = unicycle.inputs
    O = observability_matrix(unicycle)
    assert generic_rank(O) == 3
    assert rank_loss_conditions(O, 3) == [[v]]
    assert generic_rank(O.subs(v, 0)) == 2
    for heading in (0, sp.pi / 2, sp.pi):  # rank kept for every θ and for ω = 0
        assert generic_rank(O.subs({v: sp.Rational(1, 3), omega: 0, theta: heading})) == 3


def test_separation_bearing_determinant_eq_3_28():
    follower = BUILTIN_SYSTEMS["separation-bearing"]()
    separation, bearing, theta_f = follower.states
    v_f, omega_f = follower.inputs
    d, v_l, omega_l, theta_l = (follower.parameters[n] for n in ("d", "v_l", "omega_l", "theta_l"))
    gamma = theta_l + bearing - theta_f
    bearing_rate = (v_l * sp.sin(bearing) - v_f * sp.sin(gamma)
                    + d * omega_f * sp.cos(gamma)) / separation - omega_l
    O = observability_matrix(follower, order=1)  # rows φ, θ_f, φ̇, θ̇_f (Eq 3.27 order)
    determinant = O.extract([0, 1, 2], [0, 1, 2]).det()
    # det = +∂φ̇/∂l = −(φ̇ + ω_l)/l; the thesis prints −∂φ̇/∂l (a sign slip, same condition)
    assert sp.simplify(determinant - sp.diff(bearing_rate, separation)) == 0
    assert sp.simplify(determinant + (bearing_rate + omega_l) / separation) == 0
    loss = rank_loss_conditions(O, 3)
    assert len(loss) == 1
    assert sp.simplify(loss[0][0] ** 2 - (separation * (bearing_rate + omega_l)) ** 2) == 0


def test_separation_bearing_full_map_has_rank_3():
    follower = BUILTIN_SYSTEMS["separation-bearing"]()
    assert generic_rank(observability_matrix(follower)) == 3


def test_separation_separation_observable_from_both_separations():
    follower = BUILTIN_SYSTEMS["separation-separation"]()
    assert generic_rank(observability_matrix(follower)) == 3
    v_f, omega_f = follower.inputs
    # a follower at rest reveals nothing about its heading
    assert generic_rank(observability_matrix(follower).subs({v_f: 0, omega_f: 0})) == 2
