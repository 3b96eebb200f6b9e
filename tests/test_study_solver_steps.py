"""Variable-step (Simulink-like) statistics: the compiled Dormand–Prince loop against
scipy's RK45 on the same problem."""
import dataclasses

import numpy as np
import pytest

from nonholo import examples
from nonholo.sim.files import load_scenario
from nonholo.studies.solver_steps import solver_step_statistics


@pytest.fixture(scope="module")
def circle():
    scenario = load_scenario(examples.path("test4-circle"))
    robots = tuple(r for r in scenario.robots if r.name != "cascaded")  # stiff: slow under scipy
    return dataclasses.replace(scenario, robots=robots, steps=None)


def test_compiled_engine_reproduces_scipy_rk45(circle):
    compiled = solver_step_statistics(circle)
    reference = solver_step_statistics(circle, engine="scipy")
    np.testing.assert_array_equal(compiled.samples, reference.samples)
    for a, b in zip(compiled.times, reference.times):
        np.testing.assert_allclose(a, b, rtol=1e-5)
    np.testing.assert_allclose(compiled.metrics.error_mean, reference.metrics.error_mean, rtol=1e-6)
    np.testing.assert_allclose(compiled.metrics.error_std, reference.metrics.error_std, rtol=1e-6)


def test_samples_are_accepted_steps(circle):
    result = solver_step_statistics(circle)
    duration = circle.duration
    for times in result.times:
        assert times[0] == 0.0 and times[-1] == pytest.approx(duration, abs=1e-9)
        assert np.all(np.diff(times) > 0) and np.diff(times).max() <= duration / 50 * (1 + 1e-12)
    data = result.to_dict()
    assert data["settings"]["rtol"] == 1e-3 and data["settings"]["atol"] == 1e-6
    assert data["robots"]["kanayama"]["samples"] == int(result.samples[list(result.names).index("kanayama")])


def test_solver_steps_weight_the_transient(circle):
    """Spec §5.3: on Test 4 the converging laws' solver-step means are many times their
    uniform-grid means (steps are dense in the initial transient), the slow stable-tracking
    law's are not."""
    from nonholo.sim.simulator import simulate

    solver = solver_step_statistics(circle).metrics.error_mean
    uniform = simulate(circle, record=False).metrics.error_mean
    ratio = dict(zip([r.name for r in circle.robots], solver / uniform))
    for name in ("approximate-linearization", "nonlinear", "dynamic-feedback", "offset-point"):
        assert ratio[name] > 5, name
    assert ratio["kanayama"] == pytest.approx(1.0, abs=0.1)


def test_unknown_engine(circle):
    with pytest.raises(ValueError, match="engine"):
        solver_step_statistics(circle, engine="ode45")
