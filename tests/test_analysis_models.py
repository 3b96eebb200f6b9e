"""One model definition (issue 5, item 8): the analysed systems are built from the functions
the simulator compiles, and both agree numerically at random states."""
import numpy as np
import pytest
import sympy as sp

from nonholo.analysis import BUILTIN_SYSTEMS
from nonholo.analysis.system import control_affine_from_rates
from nonholo.models.formation_kinematics import (separation_bearing_rates,
                                                 separation_separation_rates)
from nonholo.models.unicycle import unicycle_rates

RNG = np.random.default_rng(5)


def _analysed(system):
    """The analysed right-hand side as a numpy function of (states, inputs, parameters)."""
    parameters = [p for p in system.parameters.values() if isinstance(p, sp.Symbol)]
    arguments = (*system.states, *system.inputs, *parameters)
    return sp.lambdify(arguments, list(system.rhs()), "numpy")


def test_unicycle_fields_come_from_the_compiled_model():
    unicycle = BUILTIN_SYSTEMS["unicycle"]()
    rates = _analysed(unicycle)
    for _ in range(20):
        x, y, theta, v, omega = RNG.uniform(-4, 4, 5)
        compiled = unicycle_rates(v, omega, np.cos(theta), np.sin(theta))
        np.testing.assert_allclose(rates(x, y, theta, v, omega), compiled, rtol=1e-13, atol=1e-13)


def test_separation_bearing_agrees_with_compiled_model():
    follower = BUILTIN_SYSTEMS["separation-bearing"]()
    assert tuple(follower.parameters) == ("d", "v_l", "omega_l", "theta_l")
    rates = _analysed(follower)
    for _ in range(20):
        bearing, theta_f, v_f, omega_f, v_l, omega_l, theta_l = RNG.uniform(-3, 3, 7)
        separation, d = RNG.uniform(0.5, 4, 2)
        gamma = theta_l + bearing - theta_f
        compiled = separation_bearing_rates(v_f, omega_f, v_l, omega_l, separation, d,
                                            np.cos(bearing), np.sin(bearing),
                                            np.cos(gamma), np.sin(gamma))
        analysed = rates(separation, bearing, theta_f, v_f, omega_f, d, v_l, omega_l, theta_l)
        np.testing.assert_allclose(analysed, compiled, rtol=1e-12, atol=1e-12)


def test_separation_separation_agrees_with_compiled_model():
    follower = BUILTIN_SYSTEMS["separation-separation"]()
    assert tuple(follower.parameters) == ("d", "v_1", "v_2", "theta_1", "theta_2", "phi_1", "phi_2")
    rates = _analysed(follower)
    for _ in range(20):
        theta_f, v_f, omega_f, v_1, v_2, theta_1, theta_2, phi_1, phi_2 = RNG.uniform(-3, 3, 9)
        l_1, l_2, d = RNG.uniform(0.5, 4, 3)
        gamma_1, gamma_2 = theta_1 + phi_1 - theta_f, theta_2 + phi_2 - theta_f
        compiled = separation_separation_rates(
            v_f, omega_f, v_1, v_2, d, np.cos(phi_1), np.cos(gamma_1), np.sin(gamma_1),
            np.cos(phi_2), np.cos(gamma_2), np.sin(gamma_2))
        analysed = rates(l_1, l_2, theta_f, v_f, omega_f, d, v_1, v_2, theta_1, theta_2,
                         phi_1, phi_2)
        np.testing.assert_allclose(analysed, compiled, rtol=1e-12, atol=1e-12)


def test_follower_fields_match_spec_decoupling_matrix():
    follower = BUILTIN_SYSTEMS["separation-bearing"]()
    separation, bearing, theta_f = follower.states
    d, theta_l = follower.parameters["d"], follower.parameters["theta_l"]
    gamma = theta_l + bearing - theta_f
    G = sp.Matrix.hstack(*follower.fields)[:2, :]
    assert G == sp.Matrix([[sp.cos(gamma), d * sp.sin(gamma)],
                           [-sp.sin(gamma) / separation, d * sp.cos(gamma) / separation]])
    assert sp.simplify(G.det() - d / separation) == 0  # spec §2.2: det G = d / l


def test_non_affine_model_is_rejected():
    u, x = sp.symbols("u x")
    with pytest.raises(ValueError, match="not affine"):
        control_affine_from_rates([u ** 2, x], [u])


@pytest.mark.parametrize("omega", [0.7, -1.3, 4e-8, 8e-10, 1e-12, 0.0])
def test_unicycle_arc_is_the_exact_solution_of_the_model(omega):
    """``unicycle_arc`` (the pose after h s under constant v, ω) against a fine RK4
    integration of ``unicycle_rates``, also at ω h of 1e-7 and 2e-9, where the difference of
    sines (v/ω)(sin(θ + ω h) − sin θ) lost 1e-8 m; h = 0 returns the pose itself."""
    from nonholo.models.unicycle import unicycle_arc

    x, y, theta, v, h = 1.5, -2.0, 0.4, 0.9, 2.5
    q = np.array([x, y, theta])
    rates = lambda q: np.array(unicycle_rates.py_func(v, omega, np.cos(q[2]), np.sin(q[2])))  # noqa: E731
    steps = 2000
    for _ in range(steps):
        k1 = rates(q)
        k2 = rates(q + 0.5 * h / steps * k1)
        k3 = rates(q + 0.5 * h / steps * k2)
        k4 = rates(q + h / steps * k3)
        q = q + h / steps / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert np.allclose(unicycle_arc(x, y, theta, v, omega, h), q, rtol=0, atol=1e-12)
    assert unicycle_arc(x, y, theta, v, omega, 0.0) == (x, y, theta)
