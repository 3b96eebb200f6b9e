"""Laws called through their address (``nonholo.sim.lawcall``): the same numbers as the law
called directly, for every registered law and variant; single runs of every law share one
compiled function; and the guards on the reference rows a law reads by address."""
import numpy as np
import pytest
from numba import njit

from nonholo import references
from nonholo.control.declare import LAWS, POSITIVE, Gain, control_law, unregister
from nonholo.control.registry import controller
from nonholo.sim import kernel as kn
from nonholo.sim.lawcall import law_at_address, law_entry, row_address, stack_copy
from nonholo.sim.scenario import Robot, Scenario
from nonholo.sim.simulator import kernel_for, simulate

VARIANTS = [(name, variant) for name, spec in sorted(LAWS.items()) for variant in spec.variants]


@njit
def through_entry(address, states, rows, fields):
    """(v, ω, ξ̇, singular) of the law at ``address`` for each state and reference row."""
    out = np.empty((states.shape[0], 4))
    gains = (address, stack_copy((fields[0], fields[1], fields[2], fields[3], fields[4], fields[5], fields[6],
                                  fields[7], fields[8], fields[9])))
    for i in range(states.shape[0]):
        x, y, theta, xi = states[i, 0], states[i, 1], states[i, 2], states[i, 3]
        out[i] = law_at_address(x, y, theta, np.cos(theta), np.sin(theta), xi, row_address(rows, i), gains)
    return out


def direct(law, gains_class, states, rows, fields):
    """The same, the law called from Python (numba's own dispatch of the compiled law)."""
    gains = gains_class(*fields[:len(gains_class._fields)])
    return np.array([law(x, y, theta, np.cos(theta), np.sin(theta), xi, tuple(row), gains)
                     for (x, y, theta, xi), row in zip(states, rows)])


@pytest.mark.parametrize("name,variant", VARIANTS)
def test_a_law_through_its_entry_gives_the_law_s_own_numbers(name, variant):
    config = controller(name, variant)
    spec = config.controller
    rng = np.random.default_rng(7)
    states = np.column_stack([rng.normal(size=(50, 3)), rng.uniform(0.2, 1.0, 50)])
    rows = references.eight().table(np.linspace(0.0, 30.0, 50))
    fields = np.zeros(kn.MAX_FIELDS)
    values = config.gain_values((0.5, -0.3, 0.2) if spec.kind == "posture" else None)
    fields[:len(values)] = values
    entry = law_entry(config.law, spec.gain_tuple)
    assert law_entry(config.law, spec.gain_tuple) is entry   # one entry per law and process
    got = through_entry(entry.address, states, np.ascontiguousarray(rows), fields)
    want = direct(config.law, spec.gain_tuple, states, rows, fields)
    assert np.isfinite(want[:, :2]).all()
    np.testing.assert_array_equal(got, want)


def test_single_runs_of_every_law_share_one_compiled_function():
    before = len(kn.integrate_alone.signatures)
    for name in ("kanayama", "dynamic-feedback", "offset-point"):
        run = simulate(Scenario(references.eight(), [Robot("r", controller(name), (0.3, -0.2, 0.1))], duration=2.0,
                                dt=0.01))
        assert run.stats[kn.E_MAX, 0, 0] < 1.0
    assert len(kn.integrate_alone.signatures) <= max(before, 1)


def test_reference_rows_that_a_law_cannot_read_by_address_are_refused():
    config = controller("kanayama")
    kernel = kernel_for(((config.law, config.controller.gain_tuple),), False)
    states = np.zeros((3, 4, 1, 1))
    stats, pairs = kn.new_stats(1, 1)
    graph = (np.zeros((1, 4, 1)), np.zeros((2, 1, 1)), np.full(1, kn.ROOT_A, np.int64), np.zeros(1, np.int64),
             np.full((2, 1), -1, np.int64), np.zeros((1, 1)), 0.1, np.zeros(1))
    fields, limits = np.zeros((kn.MAX_FIELDS, 1, 1)), np.full((2, 1, 1), np.inf)
    with pytest.raises(ValueError, match=r"reference rows must be \(rows, 10\)"):
        kernel.score_alone(states, fields, limits, np.zeros((3, 9)), *graph, stats, pairs,
                           np.empty((kn.REC_COUNT, 0, 1, 1)), 0, np.zeros((0, kn.HELD_COUNT, 1, 1)))


@njit(error_model="numpy")
def raising_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    if ref[0] > 0.5:
        raise ValueError("the reference went past 0.5 s")
    return gains.k, 0.0, 0.0, 0.0


@njit(error_model="numpy")
def untypable_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    return gains.k * undefined_name, 0.0, 0.0, 0.0  # noqa: F821


def _registered(name, law):
    control_law(name, title="a test law", source="tests", gains={"k": Gain(0.3, POSITIVE)},
                stiffness=lambda g, v_d, omega_d: 1.0)(law)


def test_a_law_that_raises_in_a_single_run_raises_there_too(capfd):
    _registered("test-raising", raising_law)
    try:
        robot = Robot("r", controller("test-raising"), (0.0, 0.0, 0.0))
        scenario = Scenario(references.line(), [robot], duration=1.0, dt=0.01)
        with pytest.raises(ValueError, match="the reference went past"):   # the batch: the law's own error
            simulate([scenario] * kn.ALONE_BELOW, record=False)
        with pytest.raises(ValueError, match="control law raised an exception in a single run"):
            simulate(scenario, record=False)
        assert "Exception ignored" not in capfd.readouterr().err   # no traceback per step from the C entry
    finally:
        unregister("test-raising")


def test_a_law_that_fails_to_compile_fails_again_not_with_a_crash():
    _registered("test-untypable", untypable_law)
    try:
        scenario = Scenario(references.line(), [Robot("r", controller("test-untypable"))], duration=0.1, dt=0.01)
        for _ in range(2):   # the second call once crashed on an entry address left at 0
            with pytest.raises(Exception, match="undefined_name"):
                simulate(scenario, record=False)
    finally:
        unregister("test-untypable")
