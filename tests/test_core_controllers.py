"""Each tracking law against its mathematics (spec leader.md §3)."""
import math

import numpy as np
import pytest

from nonholo import references
from nonholo.control.registry import CONTROLLERS, controller
from nonholo.errors import NonholoInputError
from nonholo.sim.scenario import Robot, Scenario
from nonholo.sim.simulator import simulate
from tests.conftest import pose_from_errors

ALL = [("approximate-linearization", None), ("nonlinear", None), ("cascaded", "linear"), ("cascaded", "sine"),
       ("kanayama", None), ("offset-point", None), ("dynamic-feedback", None)]


@pytest.mark.parametrize("name, variant", ALL)
def test_starting_on_the_reference_keeps_the_error_zero(name, variant):
    ref = references.eight()
    row = ref.table([0.0])[0]
    robot = Robot("r", controller(name, variant), start=(row[1], row[2], row[7]))
    result = simulate(Scenario(ref, [robot], duration=60.0, dt=0.01), record=False)
    assert result.metrics.error_max[0] < 1e-7


@pytest.mark.parametrize("name, variant", [("approximate-linearization", None), ("nonlinear", None),
                                           ("dynamic-feedback", None), ("offset-point", None), ("kanayama", None)])
def test_converges_from_perturbed_starts(name, variant):
    """Tracking of the figure eight from several off-path starts (ω_d persistently exciting)."""
    ref = references.eight()
    starts = [(0.5, -0.5, 0.3), (-1.0, 0.5, -1.0), (0.3, 0.8, 2.0)]
    robots = [Robot(f"r{i}", controller(name, variant, **({"ky": 64.0, "ktheta": 16.0} if name == "kanayama" else {})),
                    start=s) for i, s in enumerate(starts)]
    result = simulate(Scenario(ref, robots, duration=120.0, dt=0.01), record=False)
    assert np.all(result.metrics.error_max > 0.3)
    assert np.all(result.metrics.error_final < 1e-3), result.metrics.error_final


@pytest.mark.parametrize("name", ["approximate-linearization", "nonlinear", "dynamic-feedback"])
def test_converges_driving_backward(name):
    """A reference driven backward (spec leader.md §2, s = −1: v_d < 0, θ_d the reversed
    tangent): from off-path starts the robot reaches it, and drives it backward."""
    ref = references.circle(direction=-1)
    starts = [(10.5, 0.3, -1.4), (9.0, -0.5, -2.0)]
    robots = [Robot(f"r{i}", controller(name), start=s) for i, s in enumerate(starts)]
    result = simulate(Scenario(ref, robots, duration=120.0, dt=0.01))
    assert np.all(result.metrics.error_max > 0.4)
    assert np.all(result.metrics.error_final < 1e-6), result.metrics.error_final
    assert np.all(result.trajectory("v")[:, -1] < -0.4)   # v_d = −0.5 m/s


def test_kanayama_refuses_a_reference_driven_backward(tmp_path, capsys):
    """Kanayama's law needs v_d > 0 (spec §3.4: its Lyapunov function): driven backward it
    diverges, so the run is refused with one line (exit 2), before anything is integrated."""
    from nonholo.cli import main
    from nonholo.errors import InfeasibleReferenceError

    robot = Robot("r", controller("kanayama"), start=(10.5, 0.3, -1.4))
    with pytest.raises(InfeasibleReferenceError, match="kanayama controller follows forward motion only"):
        simulate(Scenario(references.circle(direction=-1), [robot], duration=10.0, dt=0.01))
    path = tmp_path / "k.toml"
    path.write_text('[reference]\nkind = "circle"\ndirection = "backward"\n[[robots]]\nname = "r"\n'
                    'controller = "kanayama"\nstart = [10.5, 0.3, -1.4]\n')
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "driven backward" in err
    forward = simulate(Scenario(references.circle(), [robot], duration=1.0, dt=0.01))   # forward: runs
    assert forward.metrics.error_final[0] < 1.0


def test_offset_point_follows_the_direction_its_point_leads():
    """The offset-point law's heading is internal dynamics, ė3 ≈ −(v_d/d) sin e3: d < 0 tracks a
    reference driven backward (to 1e-6 m, heading too, driving backward); d > 0 there, or
    d < 0 forward, would turn the robot around, and is refused with one line."""
    from nonholo.errors import InfeasibleReferenceError

    backward, forward = references.circle(direction=-1), references.circle()
    robot = Robot("r", controller("offset-point", d=-0.5), start=(10.5, 0.3, -1.4))
    result = simulate(Scenario(backward, [robot], duration=120.0, dt=0.01))
    assert result.metrics.error_max[0] > 0.4 and result.metrics.error_final[0] < 1e-6
    assert abs(result.heading_metrics("r")["final"]) < 1e-6
    assert result.trajectory("v")[0, -1] < -0.4
    for d, reference, way in ((0.5, backward, "forward"), (-0.5, forward, "backward")):
        with pytest.raises(InfeasibleReferenceError, match=f"with d = {d:g}, k1 = 1, k2 = 1 follows {way} motion only"):
            simulate(Scenario(reference, [Robot("r", controller("offset-point", d=d), start=(10.5, 0.3, 1.7))],
                              duration=1.0, dt=0.01))


def test_a_law_declares_the_directions_it_follows():
    from nonholo.control.declare import POSITIVE, ControllerDeclarationError, Gain, control_law
    from nonholo.control.registry import LAWS

    for direction in (2, True, lambda g: 0.5, lambda g: g["missing"]):
        with pytest.raises(ControllerDeclarationError, match="direction"):
            @control_law("test-direction-law", title="t", source="s", gains={"k": Gain(1.0, POSITIVE)},
                         direction=direction)
            def law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):   # pragma: no cover - refused first
                return 0.0, 0.0, 0.0, 0.0
    assert "test-direction-law" not in LAWS
    assert controller("kanayama").direction_of() == 1 and controller("nonlinear").direction_of() == 0
    assert controller("offset-point", d=-0.2).direction_of() == -1


@pytest.mark.parametrize("variant", ["linear", "sine"])
def test_cascaded_converges_when_omega_d_excites_the_cross_track_error(variant):
    """Spec §3.3: position errors obey λ² + c2 λ + (1 + c3) ω_d²; ω_d = 1 rad/s gives a
    slow pole of about −0.43 1/s, so 60 s leaves e⁻²⁵ of the initial error."""
    ref = references.circle(radius=1.0, period=2 * math.pi)
    result = simulate(Scenario(ref, [Robot("r", controller("cascaded", variant), start=(1.5, 0.3, 1.0))],
                               duration=60.0, dt=0.01), record=False)
    assert result.metrics.error_final[0] < 1e-6


def test_cascaded_cannot_remove_a_lateral_offset_on_a_straight_line():
    """Spec §3.3: with ω_d ≡ 0 the cross-track error is not corrected."""
    robot = Robot("r", controller("cascaded"), start=(0.7, 0.0, math.pi / 2))
    result = simulate(Scenario(references.line(), [robot], duration=100.0, dt=0.01), record=False)
    assert result.metrics.error_final[0] == pytest.approx(0.7, rel=1e-9)


def test_dynamic_feedback_error_obeys_the_closed_form():
    """Spec §3.6: with e(0) = 0, ∫|e|² dt = |ė(0)|² / (2 kp kd) and e decays as a damped oscillator."""
    kp, kd = 1.0, 0.7
    ref = references.line()  # p_d(0) = 0, ṗ_d = (0, 1); robot at rest heading +x with ξ(0) = 1
    result = simulate(Scenario(ref, [Robot("r", controller("dynamic-feedback", kp=kp, kd=kd), (0, 0, 0))],
                               duration=60.0, dt=0.001))
    e_dot0_sq = 2.0  # ė(0) = (0, 1) − 1·(1, 0)
    integral = result.metrics.error_rms[0] ** 2 * (result.t.size * 0.001)
    assert integral == pytest.approx(e_dot0_sq / (2 * kp * kd), rel=2e-3)
    # Each Cartesian error is exactly the impulse response h(t) of 1/(s² + kd s + kp) times ė_i(0).
    wd = math.sqrt(kp - kd**2 / 4)
    h = np.exp(-kd * result.t / 2) * np.sin(wd * result.t) / wd
    assert np.allclose(result.x_d - result.x[0], -1.0 * h, atol=1e-8)
    assert np.allclose(result.y_d - result.y[0], 1.0 * h, atol=1e-8)


@pytest.mark.parametrize("v_d, omega_d", [(1.0, 0.0), (0.5, 0.05), (2.0, -0.3)])
def test_approximate_linearization_places_the_frozen_time_poles(v_d, omega_d):
    """Spec §3.1: eigenvalues of the linearized closed loop are −2ζa, −ζa ± a·sqrt(ζ²−1)."""
    zeta, b = 0.5, 2.0
    law = CONTROLLERS["approximate-linearization"].laws["default"].py_func
    ref_row = np.array([0, 0, 0, v_d, 0, 0, 0, 0, v_d, omega_d], dtype=float)
    gains = CONTROLLERS["approximate-linearization"].gain_tuple(zeta=zeta, b=b)

    def error_rates(e):
        x, y, th = pose_from_errors(ref_row, *e)
        v, w, _, _ = law(x, y, th, math.cos(th), math.sin(th), 0.0, tuple(ref_row), gains)
        return np.array([w * e[1] - v + v_d * math.cos(e[2]), -w * e[0] + v_d * math.sin(e[2]), omega_d - w])

    jac = np.column_stack([(error_rates(h) - error_rates(-h)) / 2e-7 for h in np.eye(3) * 1e-7])
    a = math.sqrt(omega_d**2 + b * v_d**2)
    expected = np.sort_complex(np.array([-2 * zeta * a, -zeta * a + a * np.sqrt(complex(zeta**2 - 1)),
                                         -zeta * a - a * np.sqrt(complex(zeta**2 - 1))]))
    assert np.allclose(np.sort_complex(np.linalg.eigvals(jac)), expected, atol=1e-6)


@pytest.mark.parametrize("variant", ["linear", "sine"])
@pytest.mark.parametrize("v_d, omega_d", [(1.0, 0.3), (0.5, -0.8)])
def test_cascaded_error_dynamics_have_the_designed_structure(variant, v_d, omega_d):
    """Spec §3.3: linearized at e = 0 the heading loop is ė3 = −c1 e3 and the position
    errors obey λ² + c2 λ + (1 + c3) ω_d² (the cross-track error corrected only through ω_d)."""
    c1, c2, c3 = 216.9, 1.355, -0.414
    law = CONTROLLERS["cascaded"].laws[variant].py_func
    ref_row = np.array([0, 0, 0, v_d, 0, 0, 0, 0, v_d, omega_d], dtype=float)

    def error_rates(e):
        x, y, th = pose_from_errors(ref_row, *e)
        v, w, _, _ = law(x, y, th, math.cos(th), math.sin(th), 0.0, tuple(ref_row),
                         CONTROLLERS["cascaded"].gain_tuple(c1=c1, c2=c2, c3=c3))
        return np.array([w * e[1] - v + v_d * math.cos(e[2]), -w * e[0] + v_d * math.sin(e[2]), omega_d - w])

    jac = np.column_stack([(error_rates(h) - error_rates(-h)) / 2e-7 for h in np.eye(3) * 1e-7])
    assert np.allclose(jac[2], [0, 0, -c1], atol=1e-6)  # decoupled heading loop
    position = jac[:2, :2]
    assert np.allclose(np.poly(position), [1, c2, (1 + c3) * omega_d**2], atol=1e-6)


def test_nonlinear_law_lyapunov_function_decreases():
    """Spec §3.2: V = (b/2)(e1² + e2²) + e3²/2 is non-increasing along the closed loop."""
    ref = references.circle()
    result = simulate(Scenario(ref, [Robot("r", controller("nonlinear"), start=(9.0, 1.0, 2.0))], duration=30.0,
                               dt=0.001))
    b = 2.0
    th = result.theta[0]
    dx, dy = result.x_d - result.x[0], result.y_d - result.y[0]
    e1, e2 = np.cos(th) * dx + np.sin(th) * dy, -np.sin(th) * dx + np.cos(th) * dy
    e3 = np.angle(np.exp(1j * (result.theta_d - th)))
    V = b / 2 * (e1**2 + e2**2) + e3**2 / 2
    assert np.all(np.diff(V) <= 1e-9) and V[-1] < 1e-3 * V[0]


def test_dynamic_feedback_singularity_is_guarded_and_reported():
    robot = Robot("r", controller("dynamic-feedback", xi0=0.0), start=(0.0, 0.0, 0.0))
    result = simulate(Scenario(references.line(), [robot], duration=20.0, dt=0.01))
    assert result.metrics.singular[0] > 0 and result.metrics.first_singular[0] == 0.0
    assert np.all(np.isfinite(result.omega)) and np.isfinite(result.metrics.error_mean[0])
    assert result.to_dict()["robots"]["r"]["events"]["first_singular_time"] == 0.0


def test_gain_validation_messages():
    with pytest.raises(NonholoInputError, match="unknown controller 'pid'.*dynamic-feedback"):
        controller("pid")
    with pytest.raises(NonholoInputError, match=r"unknown gain 'k9' for kanayama \(gains: kx, ky, ktheta\)"):
        controller("kanayama", k9=1.0)
    with pytest.raises(NonholoInputError, match="zeta.*in \\(0, 1\\)"):
        controller("nonlinear", zeta=1.5)
    with pytest.raises(NonholoInputError, match="c3.*> -1"):
        controller("cascaded", c3=-2.0)
    with pytest.raises(NonholoInputError, match="conflicts"):
        controller("dynamic-feedback", kp=1.0, kp1=2.0)
    assert controller("dynamic-feedback", kp=2.0).gains["kp2"] == 2.0
