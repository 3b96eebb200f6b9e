"""Chained forms (thesis Eq 3.30, corrected Eq 3.32) and flatness (§3.5)."""
import sympy as sp

from nonholo.analysis import (BUILTIN_SYSTEMS, ChainedFormTransform, FlatParametrization,
                              chained_form_rates, check_chained_form, check_flatness)


def _unicycle():
    return BUILTIN_SYSTEMS["unicycle"]()


def _transform(reference):
    return next(t for t in _unicycle().chained_forms if t.reference == reference)


def test_chained_form_rates_2_4():
    z = sp.symbols("z1:5")
    w1, w2 = sp.symbols("w1 w2")
    assert chained_form_rates(z, (w1, w2)) == sp.Matrix([w1, w2, z[1] * w1, z[2] * w1])


def test_eq_3_30_gives_chained_form():
    check = check_chained_form(_unicycle(), _transform("Eq 3.30"))
    theta = _unicycle().states[2]
    assert check.residual == sp.zeros(3, 1)
    assert sp.simplify(check.coordinate_determinant + 1 / sp.cos(theta) ** 2) == 0
    assert check.is_chained_form


def test_corrected_eq_3_32_gives_chained_form():
    check = check_chained_form(_unicycle(), _transform("Eq 3.32 (corrected)"))
    assert check.residual == sp.zeros(3, 1)
    assert check.coordinate_determinant == -1
    assert check.is_chained_form


def test_printed_eq_3_32_fails_as_erratum_3_says():
    corrected = _transform("Eq 3.32 (corrected)")
    v_1, v_2 = corrected.new_inputs
    z_3 = corrected.coordinates[2]
    printed = ChainedFormTransform("Eq 3.32 (printed)", corrected.coordinates, (v_1, v_2),
                                   (z_3 * v_1 + v_2, v_2))  # u2 = v2 instead of v1
    check = check_chained_form(_unicycle(), printed)
    assert not check.is_chained_form
    z_2 = corrected.coordinates[1]
    expected = sp.Matrix([v_2 - v_1, z_3 * (v_1 - v_2), z_2 * (v_2 - v_1)])
    assert (check.residual - expected).applyfunc(sp.simplify) == sp.zeros(3, 1)


def test_unicycle_is_flat_in_x_y():
    unicycle = _unicycle()
    check = check_flatness(unicycle, unicycle.flatness)
    assert check.dynamics_residual == sp.zeros(3, 1)
    assert check.output_residual == sp.zeros(2, 1)
    assert check.is_flat_parametrization


def test_wrong_flat_parametrization_is_rejected():
    flat = _unicycle().flatness
    x_t, y_t = flat.flat_outputs
    dx, dy = x_t.diff(flat.time), y_t.diff(flat.time)
    swapped = FlatParametrization(flat.time, flat.flat_outputs, flat.output_map,
                                  (x_t, y_t, sp.atan2(dx, dy)), flat.inputs, flat.validity)
    check = check_flatness(_unicycle(), swapped)
    assert not check.is_flat_parametrization
    assert check.output_residual == sp.zeros(2, 1)
    assert check.dynamics_residual != sp.zeros(3, 1)
