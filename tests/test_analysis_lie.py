"""Lie brackets, involutivity, accessibility filtration and nilpotency (thesis §2.2, §3.1)."""
import sympy as sp

from nonholo.analysis import (BUILTIN_SYSTEMS, accessibility_filtration, bracket_tree,
                              is_involutive, lie_bracket, lie_derivative, nilpotency_step)
from nonholo.analysis.summary import field_generators

x, y, z = sp.symbols("x y z", real=True)


def _levels(system, depth):
    return bracket_tree(field_generators(system), system.states, depth)


def test_unicycle_bracket_has_thesis_sign_eq_2_21():
    unicycle = BUILTIN_SYSTEMS["unicycle"]()
    theta = unicycle.states[2]
    g1, g2 = unicycle.fields
    assert g1 == sp.Matrix([sp.cos(theta), sp.sin(theta), 0])
    assert g2 == sp.Matrix([0, 0, 1])
    assert lie_bracket(g1, g2, unicycle.states) == sp.Matrix([sp.sin(theta), -sp.cos(theta), 0])
    # skew symmetry, Eq 2.6: the other order has the opposite sign
    assert lie_bracket(g2, g1, unicycle.states) == sp.Matrix([-sp.sin(theta), sp.cos(theta), 0])


def test_bracket_convention_on_linear_fields():
    # f = (y, 0, 0), g = (0, x, 0): (∂g/∂x) f − (∂f/∂x) g = (−x, y, 0) with Eq 2.5
    f, g = sp.Matrix([y, 0, 0]), sp.Matrix([0, x, 0])
    assert lie_bracket(f, g, (x, y, z)) == sp.Matrix([-x, y, 0])


def test_lie_derivative_is_gradient_along_field():
    assert lie_derivative(x ** 2 * y, sp.Matrix([1, z, 0]), (x, y, z)) == 2 * x * y + x ** 2 * z


def test_unicycle_tree_labels_and_third_level():
    unicycle = BUILTIN_SYSTEMS["unicycle"]()
    theta = unicycle.states[2]
    levels = _levels(unicycle, 3)
    assert [node.label for node in levels[1]] == ["[g1, g2]"]
    third = {node.label: node.vector for node in levels[2]}
    assert third == {"[g1, [g1, g2]]": sp.zeros(3, 1),
                     "[g2, [g1, g2]]": sp.Matrix([sp.cos(theta), sp.sin(theta), 0])}


def test_unicycle_accessibility_rank_3_at_degree_2_eq_3_9():
    unicycle = BUILTIN_SYSTEMS["unicycle"]()
    levels = _levels(unicycle, 3)
    filtration = accessibility_filtration(levels, unicycle.n)
    assert filtration.ranks == (2, 3, 3)
    assert filtration.degree == 2
    assert filtration.basis == ("g1", "g2", "[g1, g2]")
    assert not is_involutive(unicycle.fields, [levels[1][0].vector])
    assert nilpotency_step(levels) is None


def test_filtration_at_a_point_uses_the_values():
    unicycle = BUILTIN_SYSTEMS["unicycle"]()
    theta = unicycle.states[2]
    at_point = accessibility_filtration(_levels(unicycle, 2), 3, {theta: sp.pi / 3})
    assert at_point.ranks == (2, 3) and at_point.degree == 2


def test_car_reaches_rank_4_at_degree_3():
    car = BUILTIN_SYSTEMS["car"]()
    filtration = accessibility_filtration(_levels(car, 4), car.n)
    assert filtration.ranks == (2, 3, 4, 4)
    assert filtration.degree == 3


def test_trailer_reaches_rank_4_at_degree_3():
    trailer = BUILTIN_SYSTEMS["unicycle-trailer"]()
    assert accessibility_filtration(_levels(trailer, 3), 4).degree == 3


def test_holonomic_system_is_involutive_with_rank_2():
    from nonholo.analysis import ControlSystem
    planar = ControlSystem("planar", "translation only", (x, y, z), sp.symbols("u1 u2"),
                           (sp.Matrix([1, 0, 0]), sp.Matrix([0, 1, 0])))
    levels = _levels(planar, 3)
    assert levels[1][0].vector == sp.zeros(3, 1)
    assert is_involutive(planar.fields, [levels[1][0].vector])
    filtration = accessibility_filtration(levels, 3)
    assert filtration.ranks == (2, 2, 2) and filtration.degree is None
    assert nilpotency_step(levels) == 1


def test_chained_form_2_4_is_nilpotent_of_step_3():
    from nonholo.analysis import ControlSystem
    z1, z2, z3, z4 = states = sp.symbols("z1:5", real=True)
    chained = ControlSystem("chained", "(2,4) chained form", states, sp.symbols("w1 w2"),
                            (sp.Matrix([1, 0, z2, z3]), sp.Matrix([0, 1, 0, 0])))
    levels = _levels(chained, 4)
    assert nilpotency_step(levels) == 3
    assert accessibility_filtration(levels, 4).ranks == (2, 3, 4, 4)
    # [g1, [g1, g2]] = (0, 0, 0, 1) with the thesis sign convention
    assert {n.label: n.vector for n in levels[2]}["[g1, [g1, g2]]"] == sp.Matrix([0, 0, 0, 1])
