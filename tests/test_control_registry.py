"""The open controller API (nonholo.control.declare): a law registered from this module
is simulated, read its gains by name, and a wrong declaration fails at registration."""
import math

import numpy as np
import pytest
from numba import njit

import nonholo
from nonholo import references
from nonholo.control.declare import (MAX_LAW_FIELDS, NONZERO, POSITIVE, ControllerDeclarationError, Gain, GainRule,
                                     control_law, initial_state, unregister)
from nonholo.control.posture import POSTURE_CONTROLLERS, posture_controller
from nonholo.control.registry import CONTROLLERS, LAWS, follower_gains
from nonholo.control.tracking_errors import tracking_errors
from nonholo.errors import InfeasibleReferenceError, NonholoInputError
from nonholo.references.feedforward import REF_OMEGA, REF_V


# ------------------------------------------------------------------ laws of this module

@njit(error_model="numpy")
def proportional_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    """v = v_d + k e1,  ω = ω_d + k e3 (plus a lateral term kl v_d e2)."""
    e1, e2, e3 = tracking_errors(x, y, theta, cos_theta, sin_theta, ref)
    return ref[REF_V] + gains.k * e1, ref[REF_OMEGA] + gains.kl * ref[REF_V] * e2 + gains.k * e3, 0.0, 0.0


@njit(inline="always", error_model="numpy")
def swapped_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    """The same law; its gains are declared in the other order (kl, k)."""
    e1, e2, e3 = tracking_errors(x, y, theta, cos_theta, sin_theta, ref)
    return ref[REF_V] + gains.k * e1, ref[REF_OMEGA] + gains.kl * ref[REF_V] * e2 + gains.k * e3, 0.0, 0.0


@njit(inline="always", error_model="numpy")
def wrong_signature_law(x, y, theta, cos_theta, sin_theta, ref, gains):
    return 0.0, 0.0, 0.0, 0.0


@njit(inline="always", error_model="numpy")
def renamed_law(x, y, theta, cos_theta, sin_theta, xi, reference, gains):
    return 0.0, 0.0, 0.0, 0.0


def plain_python_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    return 0.0, 0.0, 0.0, 0.0


GAINS = {"k": Gain(1.0, POSITIVE), "kl": Gain(1.0, POSITIVE)}
TEST_LAWS = ("test-proportional", "test-swapped")


@pytest.fixture(scope="module")
def registered():
    control_law("test-proportional", title="Proportional tracking", source="tests", gains=GAINS,
                stiffness=lambda g, v_d, omega_d: max(g["k"], g["kl"] * v_d))(proportional_law)
    control_law("test-swapped", title="Proportional tracking, gains declared the other way round", source="tests",
                gains={"kl": Gain(1.0, POSITIVE), "k": Gain(1.0, POSITIVE)},
                stiffness=lambda g, v_d, omega_d: max(g["k"], g["kl"] * v_d))(swapped_law)
    yield
    for name in TEST_LAWS:
        unregister(name)


def test_a_law_registered_here_is_simulated_through_the_public_api(registered):
    spec = CONTROLLERS["test-proportional"]
    assert spec.kind == "tracking" and spec.fields == ("k", "kl") and spec.n_fields == 2
    assert spec.gain_tuple.__module__ == __name__ and getattr(__import__(__name__, fromlist=["_"]),
                                                              spec.gain_tuple.__qualname__) is spec.gain_tuple
    ref = references.circle()
    row = ref.table([0.0])[0]
    config = nonholo.controller("test-proportional", k=2.0, kl=1.0)
    robots = [nonholo.Robot("on", config, start=(row[1], row[2], row[7])),
              nonholo.Robot("off", config, start=(9.0, 1.0, 2.0))]
    result = nonholo.simulate(nonholo.Scenario(ref, robots, duration=40.0, dt=0.01), record=False)
    assert result.metrics.error_max[0] < 1e-7
    assert result.metrics.error_max[1] > 0.5 and result.metrics.error_final[1] < 1e-2 * result.metrics.error_max[1]


def test_gains_are_read_by_name_whatever_the_declaration_order(registered):
    """Both laws read gains.k and gains.kl: declared in opposite orders, they give the same
    trajectory for the same gains (k ≠ kl), i.e. no law depends on slot positions."""
    assert CONTROLLERS["test-swapped"].fields == ("kl", "k")
    assert list(nonholo.controller("test-swapped", k=3.0, kl=0.5).gain_vector()) == [0.5, 3.0]
    ref = references.circle()
    robots = [nonholo.Robot(name, nonholo.controller(name, k=3.0, kl=0.5), start=(9.0, 1.0, 2.0)) for name in TEST_LAWS]
    result = nonholo.simulate(nonholo.Scenario(ref, robots, duration=10.0, dt=0.01))
    assert np.array_equal(result.x[0], result.x[1]) and np.array_equal(result.theta[0], result.theta[1])
    assert result.metrics.error_final[0] < result.metrics.error_max[0]


def test_the_registered_law_is_validated_like_the_built_in_ones(registered):
    with pytest.raises(NonholoInputError, match=r"^unknown gain 'kx' for test-proportional \(gains: k, kl\)$"):
        nonholo.controller("test-proportional", kx=1.0)
    with pytest.raises(NonholoInputError, match=r"^gain 'kl' of test-proportional must be > 0, got -1$"):
        nonholo.controller("test-proportional", kl=-1.0)
    with pytest.raises(NonholoInputError, match=r"unknown variant 'sine' of test-proportional \(valid: default\)"):
        nonholo.controller("test-proportional", "sine")


def test_every_law_states_its_floating_point_options(registered):
    """numba compiles a function without its own fastmath choice with the options of the code
    that calls it first: a law first called by a kernel that fuses multiply-adds would keep
    them everywhere, and a formation's result would depend on what ran before it (seen: the
    wedge's near-singular passage moved from t = 7.25 s to 7.83 s)."""
    from nonholo.control.formation import separation_bearing_law, separation_separation_law
    laws = [law for spec in (*CONTROLLERS.values(), *POSTURE_CONTROLLERS.values()) for law in spec.laws.values()]
    assert proportional_law in laws   # registered from this module with @njit(error_model="numpy") only
    for law in laws + [separation_bearing_law, separation_separation_law]:
        assert law.targetoptions.get("fastmath") is False, law
        assert law.targetoptions.get("error_model") == "numpy", law


def test_built_in_declarations():
    assert set(CONTROLLERS) >= {"approximate-linearization", "nonlinear", "cascaded", "kanayama", "offset-point",
                                "dynamic-feedback"}
    assert set(POSTURE_CONTROLLERS) == {"time-varying", "polar", "dynamic-feedback-posture"}
    assert CONTROLLERS["cascaded"].variants == ("linear", "sine")
    assert CONTROLLERS["dynamic-feedback"].accepted_gains == ("kp1", "kp2", "kd1", "kd2", "xi_min", "kp", "kd", "xi0")
    assert POSTURE_CONTROLLERS["polar"].fields == ("goal_x", "goal_y", "goal_theta", "k1", "k2", "k3", "tolerance")
    assert [name for name, spec in LAWS.items() if spec.xi_is_speed] == ["dynamic-feedback", "dynamic-feedback-posture"]
    # nonholo.controller finds posture laws too; gain_vector leaves the goal out
    config = nonholo.controller("polar", k2=4.0)
    assert config.controller.kind == "posture" and list(config.gain_vector()) == [1.0, 4.0, 2.0, 1e-9]
    assert config.gain_values(goal=(1.0, 2.0, 0.5)).goal_y == 2.0
    assert posture_controller("polar", k2=4.0) == config


def test_initial_state_rules():
    assert initial_state(nonholo.controller("kanayama"), 1.0, "r") == 0.0
    assert initial_state(nonholo.controller("dynamic-feedback"), 0.7, "r") == 0.7
    assert initial_state(nonholo.controller("dynamic-feedback", xi0=-0.2), 0.7, "r") == -0.2
    with pytest.raises(InfeasibleReferenceError, match="robot 'r': xi0 defaults to v_d\\(0\\) = 0, the singular point"):
        initial_state(nonholo.controller("dynamic-feedback"), 0.0, "r")
    assert initial_state(posture_controller("time-varying"), 0.0, "r") == 0.0
    assert initial_state(posture_controller("dynamic-feedback-posture", xi0=-0.1), 0.0, "r") == -0.1
    with pytest.raises(NonholoInputError, match="gain 'xi0' of dynamic-feedback-posture must be != 0"):
        posture_controller("dynamic-feedback-posture", xi0=0.0)


def test_follower_gains():
    assert follower_gains({}) == {"k1": 1.0, "k2": 1.0}
    assert follower_gains({"k2": 3}) == {"k1": 1.0, "k2": 3.0}
    with pytest.raises(NonholoInputError, match=r"^gain 'k1' of separation-bearing must be > 0, got -1$"):
        follower_gains({"k1": -1.0}, "separation-bearing")
    with pytest.raises(NonholoInputError, match=r"^unknown gain 'k3' for follower \(gains: k1, k2\)$"):
        follower_gains({"k3": 1.0})
    with pytest.raises(NonholoInputError, match="must be a finite number"):
        follower_gains({"k1": math.inf})


# ------------------------------------------------------------------ declaration errors

def declare(name="test-bad", law=proportional_law, **options):
    options = {"title": "A test law", "source": "tests", "gains": GAINS} | options
    try:
        assert control_law(name, **options)(law) is law  # the decorator returns the law unchanged
        return LAWS[name]
    finally:
        if name != "kanayama":
            unregister(name)


@pytest.mark.parametrize("name, law, options, message", [
    ("kanayama", proportional_law, {}, "'kanayama': already registered \\(by nonholo.control.kanayama\\)"),
    ("My_Law", proportional_law, {}, "'My_Law': the name must be lower-case kebab-case"),
    ("test-bad", wrong_signature_law, {}, r"has the signature \(x, y, theta, cos_theta, sin_theta, ref, gains\), "
                                          r"expected \(x, y, theta, cos_theta, sin_theta, xi, ref, gains\)"),
    ("test-bad", renamed_law, {}, "has the signature .*reference.*expected"),
    ("test-bad", plain_python_law, {}, "must be a compiled law \\(decorate it with @njit"),
    ("test-bad", proportional_law, {"gains": {"k": Gain(-1.0, POSITIVE)}},
     "gain 'k': the default -1 violates its own rule \\(> 0\\)"),
    ("test-bad", proportional_law, {"gains": {"k": Gain(math.nan)}}, "gain 'k': the default must be a finite number"),
    ("test-bad", proportional_law, {"gains": {"k": 1.0}}, "gain 'k' must be declared as Gain\\(default, rule\\)"),
    ("test-bad", proportional_law, {"gains": {"k": Gain(1.0, rule=lambda g: g > 0)}}, "the rule must be a GainRule"),
    ("test-bad", proportional_law, {"aliases": {"kk": ("k", "kz")}}, "alias 'kk' refers to unknown gain\\(s\\) 'kz'"),
    ("test-bad", proportional_law, {"aliases": {"k": ("kl",)}}, "alias 'k' is also a gain name"),
    ("test-bad", proportional_law, {"state": "eta", "initial": 0.0}, "unknown state 'eta'.*at most one"),
    ("test-bad", proportional_law, {"state": ("xi", "eta"), "initial": 0.0}, "state must be one name.*at most one"),
    ("test-bad", proportional_law, {"state": "xi"}, "state 'xi' needs its initial value rule"),
    ("test-bad", proportional_law, {"state": "xi", "initial": "zero"}, "unknown initial='zero'"),
    ("test-bad", proportional_law, {"state": "xi", "initial": "gain:xi0"}, "names an undeclared gain 'xi0'"),
    ("test-bad", proportional_law, {"initial": 0.0}, "initial=0.0 given without a state"),
    ("test-bad", proportional_law, {"gains": GAINS | {"xi0": Gain(1.0)}, "state": "xi", "initial": "reference-speed"},
     "gain 'xi0' is implied by initial=\"reference-speed\""),
    ("test-bad", proportional_law, {"gains": {f"k{i}": Gain(1.0) for i in range(MAX_LAW_FIELDS + 1)}},
     f"{MAX_LAW_FIELDS + 1} gain-tuple fields .* at most {MAX_LAW_FIELDS}"),
    ("test-bad", proportional_law, {"kind": "posture", "gains": {f"k{i}": Gain(1.0) for i in range(8)}},
     f"11 gain-tuple fields \\(goal_x, goal_y, goal_theta, k0.*at most {MAX_LAW_FIELDS}"),
    ("test-bad", proportional_law, {"stiffness": 5.0}, "stiffness must be a function"),
    ("test-bad", proportional_law, {"stiffness": lambda g, v, w: g["kz"]},
     "stiffness fails on the default gains: KeyError"),
    ("test-bad", proportional_law, {"gains": {"k-1": Gain(1.0)}}, "gain name 'k-1' is not a Python identifier"),
    ("test-bad", proportional_law, {"gains": {"lambda": Gain(1.0)}}, "gain name 'lambda' is not a Python identifier"),
    ("test-bad", proportional_law, {"gains": {"goal_x": Gain(1.0)}}, "gain name 'goal_x' collides with the goal"),
    ("test-bad", proportional_law, {"kind": "posture", "needs_moving_reference": True},
     "a posture law does not read the reference"),
    ("test-bad", proportional_law, {"kind": "leader"}, "unknown kind 'leader'"),
])
def test_a_wrong_declaration_fails_at_registration_with_one_line(name, law, options, message):
    with pytest.raises(ControllerDeclarationError, match=f"^control law {message}" if message.startswith("'")
                       else f"^control law '{name}': .*{message}") as error:
        declare(name, law, **options)
    assert "\n" not in str(error.value)
    assert "test-bad" not in LAWS


def test_variant_declarations():
    with pytest.raises(ControllerDeclarationError, match="'no-such-law': variant 'x' of an unregistered law"):
        control_law.variant("no-such-law", "x")(proportional_law)
    with pytest.raises(ControllerDeclarationError, match="'cascaded': variant 'sine' is already registered"):
        control_law.variant("cascaded", "sine")(proportional_law)
    with pytest.raises(ControllerDeclarationError, match="'cascaded': variant 'odd' .*has the signature"):
        control_law.variant("cascaded", "odd")(wrong_signature_law)
    assert CONTROLLERS["cascaded"].variants == ("linear", "sine")


def test_declaration_extras():
    assert isinstance(NONZERO, GainRule) and issubclass(ControllerDeclarationError, ValueError)
    spec = declare("test-state", gains={"k": Gain(1.0, POSITIVE), "kl": Gain(1.0, POSITIVE), "x0": Gain(0.5, NONZERO)},
                   state="xi", initial="gain:x0")
    assert spec.fields == ("k", "kl") and spec.accepted_gains == ("k", "kl", "x0") and spec.xi_is_speed
    config = spec.configure({"x0": -0.25})
    assert config.xi0 == -0.25 and "x0" not in config.gains and initial_state(config, 0.0, "r") == -0.25
    assert config.describe() == {"controller": "test-state", "gains": {"k": 1.0, "kl": 1.0}, "xi0": -0.25}
    assert "test-state" not in LAWS
