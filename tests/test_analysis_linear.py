"""Linear controllability at a point and along trajectories (thesis Eq 3.3–3.18)."""
import sympy as sp

from nonholo.analysis import (BUILTIN_SYSTEMS, body_frame_model, body_frame_rotation,
                              controllability_matrix, generic_rank, linearize_along_reference,
                              linearize_at_point, rank_loss_conditions, similarity_transform,
                              time_varying_controllability_matrix)
from nonholo.analysis.linear import equilibrium_point

R = sp.Symbol  # reference and equilibrium symbols carry the states' real assumption
theta_e, theta_d, v_d, omega_d = (R(n, real=True) for n in ("theta_e", "theta_d", "v_d", "omega_d"))


def _unicycle():
    return BUILTIN_SYSTEMS["unicycle"]()


def test_linearization_at_a_point_eq_3_5_and_3_6_rank_2():
    unicycle = _unicycle()
    model = linearize_at_point(unicycle, equilibrium_point(unicycle, {}))
    assert model.A == sp.zeros(3, 3)
    assert model.B == sp.Matrix([[sp.cos(theta_e), 0], [sp.sin(theta_e), 0], [0, 1]])
    C = controllability_matrix(model.A, model.B)
    assert C == sp.Matrix([[sp.cos(theta_e), 0, 0, 0, 0, 0],
                           [sp.sin(theta_e), 0, 0, 0, 0, 0],
                           [0, 1, 0, 0, 0, 0]])
    assert generic_rank(C) == 2


def test_given_coordinates_are_used_at_the_point():
    unicycle = _unicycle()
    x, y, theta = unicycle.states
    point = equilibrium_point(unicycle, {theta: sp.pi / 2})
    assert point == {x: R("x_e", real=True), y: R("y_e", real=True), theta: sp.pi / 2}
    assert linearize_at_point(unicycle, point).B == sp.Matrix([[0, 0], [1, 0], [0, 1]])


def test_linearization_along_reference_eq_3_13():
    model = linearize_along_reference(_unicycle())
    assert model.A == sp.Matrix([[0, 0, -v_d * sp.sin(theta_d)],
                                 [0, 0, v_d * sp.cos(theta_d)],
                                 [0, 0, 0]])
    assert model.B == sp.Matrix([[sp.cos(theta_d), 0], [sp.sin(theta_d), 0], [0, 1]])


def test_body_frame_similarity_transform_eq_3_17():
    body = body_frame_model(_unicycle())
    assert body.A == sp.Matrix([[0, omega_d, 0], [-omega_d, 0, v_d], [0, 0, 0]])
    assert body.B == sp.Matrix([[1, 0], [0, 0], [0, 1]])


def test_similarity_transform_is_appendix_d_formula():
    t = sp.Symbol("t", real=True)
    T = sp.Matrix([[sp.exp(t), 0], [0, 1]])
    A, B = sp.Matrix([[0, 1], [0, 0]]), sp.Matrix([0, 1])
    from nonholo.analysis.linear import LinearModel
    new = similarity_transform(LinearModel(A, B), T, T.diff(t))
    # Ṫ T⁻¹ = diag(1, 0); T A T⁻¹ = [[0, e^t], [0, 0]]
    assert new.A == sp.Matrix([[1, sp.exp(t)], [0, 0]])
    assert new.B == sp.Matrix([0, 1])


def test_body_frame_controllability_eq_3_18_rank_3_unless_reference_at_rest():
    body = body_frame_model(_unicycle())
    C = controllability_matrix(body.A, body.B)
    assert C == sp.Matrix([[1, 0, 0, 0, -omega_d ** 2, v_d * omega_d],
                           [0, 0, -omega_d, v_d, 0, 0],
                           [0, 1, 0, 0, 0, 0]])
    assert generic_rank(C) == 3
    assert rank_loss_conditions(C, 3) == [[omega_d, v_d]]
    assert generic_rank(C.subs({v_d: 0})) == 3
    assert generic_rank(C.subs({omega_d: 0})) == 3
    assert generic_rank(C.subs({v_d: 0, omega_d: 0})) == 2


def test_silverman_meadows_rank_3_iff_reference_moves():
    unicycle = _unicycle()
    K = time_varying_controllability_matrix(unicycle, linearize_along_reference(unicycle))
    assert K[:, 2:4] == sp.Matrix([[-omega_d * sp.sin(theta_d), v_d * sp.sin(theta_d)],
                                   [omega_d * sp.cos(theta_d), -v_d * sp.cos(theta_d)],
                                   [0, 0]])
    assert generic_rank(K) == 3
    assert rank_loss_conditions(K, 3) == [[omega_d, v_d]]
    assert generic_rank(K.subs({v_d: 0, omega_d: 0})) == 2


def test_body_frame_rotation_is_eq_3_15():
    assert body_frame_rotation(_unicycle()) == sp.Matrix(
        [[sp.cos(theta_d), sp.sin(theta_d), 0], [-sp.sin(theta_d), sp.cos(theta_d), 0], [0, 0, 1]])
