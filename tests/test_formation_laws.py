"""Follower laws against their mathematics (spec follower-posture.md §2–4, §6)."""
import math

import numpy as np
import pytest

from nonholo import controller, references
from nonholo.formation import (Change, Formation, FormationError, Leader, link_state, place_follower,
                               separation_bearing, separation_separation, simulate_formation)
from nonholo.control.formation import separation_bearing_law, separation_separation_law
from nonholo.models.formation_kinematics import bearing_rate, separation_rate

TEST1_START = (0.0, 0.0, math.atan2(0.25, 0.5))


def eight_leader():
    return Leader("leader", controller("dynamic-feedback", kp=1.0, kd=0.7), start=TEST1_START)


def circle_leader():
    return Leader("leader", controller("dynamic-feedback", kp=1.0, kd=0.7, xi0=0.5), start=(0.0, 0.0, math.pi / 2))


def behind(name="f1", leader="leader", k1=1.0, k2=1.0, **options):
    return separation_bearing(name, leader, 2.0, math.pi / 3, k1=k1, k2=k2, start=(-4.0, 0.0, 0.0),
                              start_frame="leader", **options)


def grid_mean(e0, k, dt, n_steps):
    """Mean of e0·exp(−k t_j) over the samples t_j = j·dt, j = 0…N."""
    q = math.exp(-k * dt)
    return e0 * (1 - q ** (n_steps + 1)) / (1 - q) / (n_steps + 1)


def test_geometry_castor_ahead_and_inverse_placement():
    leader = (1.0, 2.0, 0.3)
    for l, phi, theta_f in [(2.0, math.pi / 3, 0.1), (3.0, math.pi, -2.0), (1.5, -1.2, 2.5)]:
        pose = place_follower(leader, l, phi, theta_f, d=0.7)
        sep, bearing, gamma = link_state(leader, pose, 0.7)
        assert sep == pytest.approx(l, abs=1e-12)
        assert math.remainder(bearing - phi, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
        assert math.remainder(gamma - (leader[2] + phi - theta_f), 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
    # 4 m straight behind with d = 1: castor 3 m behind, bearing π (spec §6 (a))
    sep, bearing, _ = link_state((0, 0, 0), (-4.0, 0.0, 0.0), 1.0)
    assert sep == pytest.approx(3.0) and abs(bearing) == pytest.approx(math.pi)


@pytest.mark.parametrize("seed", range(5))
def test_laws_invert_the_follower_kinematics(seed):
    """Feeding each law's (v_f, ω_f) through the model gives exactly the target rates."""
    rng = np.random.default_rng(seed)
    l, phi, gamma = rng.uniform(0.5, 4), rng.uniform(-np.pi, np.pi), rng.uniform(-np.pi, np.pi)
    v_l, w_l, l_d, phi_d, l_rate, phi_rate, k1, k2, d = rng.uniform(-2, 2, 9)
    k1, k2, d = abs(k1) + 0.1, abs(k2) + 0.1, abs(d) + 0.1
    cp, sp, cg, sg = math.cos(phi), math.sin(phi), math.cos(gamma), math.sin(gamma)
    v, w = separation_bearing_law.py_func(l, phi, cp, sp, cg, sg, v_l, w_l, l_d, phi_d, l_rate, phi_rate, k1, k2, d)
    assert separation_rate.py_func(v, w, v_l, d, cp, cg, sg) == pytest.approx(k1 * (l_d - l) + l_rate, abs=1e-12)
    assert bearing_rate.py_func(v, w, v_l, w_l, l, d, sp, cg, sg) == pytest.approx(k2 * (phi_d - phi) + phi_rate, abs=1e-12)
    # cos γ = 0 is not singular in the G⁻¹ form
    v, w = separation_bearing_law.py_func(l, phi, cp, sp, 0.0, 1.0, v_l, w_l, l_d, phi_d, 0.0, 0.0, k1, k2, d)
    assert math.isfinite(v) and math.isfinite(w)
    # l–l
    l2, phi2, gamma2, v2 = rng.uniform(0.5, 4), rng.uniform(-np.pi, np.pi), gamma + rng.uniform(0.3, 2.5), rng.uniform(-2, 2)
    cp2, cg2, sg2 = math.cos(phi2), math.cos(gamma2), math.sin(gamma2)
    v, w, s, singular = separation_separation_law.py_func(l, l2, cp, cp2, cg, sg, cg2, sg2, v_l, v2, l_d, phi_d,
                                                          l_rate, phi_rate, k1, k2, d, 1e-6)
    assert singular == 0.0 and s == pytest.approx(math.sin(gamma - gamma2))
    assert separation_rate.py_func(v, w, v_l, d, cp, cg, sg) == pytest.approx(k1 * (l_d - l) + l_rate, abs=1e-10)
    assert separation_rate.py_func(v, w, v2, d, cp2, cg2, sg2) == pytest.approx(k2 * (phi_d - l2) + phi_rate, abs=1e-10)


def test_separation_bearing_closed_loop_is_exactly_exponential():
    """l̇ = k1 (l_d − l), φ̇ = k2 (φ_d − φ): distinct gains catch swapped or sign-flipped terms."""
    formation = Formation([eight_leader(), behind(k1=1.5, k2=0.6)], references.eight(), duration=20.0)
    result = simulate_formation(formation)
    t = result.t
    e_l, e_phi = result.output_errors("f1")
    # errors desired minus actual (spec README): l_d − l = −1 m, φ_d − φ = −(π − π/3) at the start
    np.testing.assert_allclose(e_l, -1.0 * np.exp(-1.5 * t), atol=2e-8)
    np.testing.assert_allclose(e_phi, -(math.pi - math.pi / 3) * np.exp(-0.6 * t), atol=2e-8)
    l_rate, phi_rate = result.output_rates("f1")
    np.testing.assert_allclose(l_rate, 1.5 * e_l, atol=1e-9)      # l̇ = k1 (l_d − l)
    np.testing.assert_allclose(phi_rate, 0.6 * e_phi, atol=1e-9)
    # the model rates agree with the integrated trajectory (finite differences)
    l, _ = result.outputs("f1")
    np.testing.assert_allclose(np.gradient(l, t)[5:-5], l_rate[5:-5], atol=2e-4)


def test_test4_reference_numbers():
    """Spec §6 (a), Test 4: finals, means (grid means of e0·e^{−t}), peak demands, leader error."""
    result = simulate_formation(Formation([circle_leader(), behind()], references.circle(), duration=40 * math.pi))
    m = result.follower_metrics("f1")
    n = result.formation.n_steps
    assert m["l_error"]["final"] < 1e-11 and m["phi_error"]["final"] < 1e-11
    assert m["l_error"]["mean"] == pytest.approx(grid_mean(1.0, 1.0, 0.01, n), rel=1e-6)
    assert m["phi_error"]["mean"] == pytest.approx(grid_mean(2 * math.pi / 3, 1.0, 0.01, n), rel=1e-6)
    # the continuous-time means of the spec (e0 (1 − e^{−T}) / T) up to the grid's dt/2 bias
    assert m["l_error"]["mean"] == pytest.approx(0.007958, rel=6e-3)
    assert m["safety"]["peak_v"] == pytest.approx(54.8, abs=0.1)
    assert m["safety"]["peak_omega"] == pytest.approx(66.1, abs=0.2)
    assert m["safety"]["min_distance"] == pytest.approx(1.01, abs=0.01)
    assert result.tracking_metrics("leader")["mean"] == pytest.approx(0.168, abs=5e-4)


def test_eq_5_9_switch_passes_behind_and_settles_in_ln50():
    change = Change(100.0, {"phi": math.pi / 3 + math.pi}, direction="counterclockwise")
    result = simulate_formation(Formation([circle_leader(), behind(changes=(change,))], references.circle(),
                                          duration=40 * math.pi))
    settling = result.follower_metrics("f1")["settling"][0]
    assert settling["phi_settling_time"] == pytest.approx(3.92, abs=1e-9)
    assert abs(settling["phi_settling_time"] - math.log(50)) < 0.01
    assert settling["l_disturbance"] < 1e-3
    t = result.t
    _, phi = result.outputs("f1")
    after = (t > 100) & (t < 115)
    assert np.all(np.diff(phi[after]) > 0)                        # bearing increases ...
    crossing = after & (np.abs(np.remainder(phi, 2 * np.pi) - np.pi) < 0.02)
    assert crossing.any()                                          # ... through π: behind the leader
    assert result.safety()["min_distance"] == pytest.approx(1.01, abs=0.01)
    window = t > 100
    x, y = result.trajectory("x"), result.trajectory("y")
    assert np.hypot(x[0] - x[1], y[0] - y[1])[window].min() == pytest.approx(math.sqrt(3), abs=0.01)


@pytest.mark.parametrize("dt", [0.01, 0.0025])
def test_step_change_is_integrated_on_its_new_target(dt):
    """Across a step at t = at (on the grid) the closed loop stays exactly φ̇ = k2 (φ_d − φ),
    l̇ = k1 (l_d − l): after the step φ_d − φ = π e^{−k2 (t − at)} to integration accuracy,
    and l is not disturbed (spec §2.2, §6 b). The sample at t = at still shows the old target.
    (Taking the old target at the first RK4 stage after the step left π·k2·dt/6: 5e-3 rad.)"""
    at, k2 = 20.0, 1.3
    change = Change(at, {"phi": math.pi / 3 + math.pi}, direction="counterclockwise")
    formation = Formation([circle_leader(), behind(k1=0.8, k2=k2, changes=(change,))], references.circle(),
                          duration=26.0, dt=dt)
    result = simulate_formation(formation)
    t = result.t
    e_l, e_phi = result.output_errors("f1")
    after = t > at + 1e-9
    np.testing.assert_allclose(e_phi[after], math.pi * np.exp(-k2 * (t[after] - at)), rtol=0, atol=1e-7)
    at_step = np.searchsorted(t, at)
    assert abs(e_phi[at_step]) < 1e-7     # the sample at the step: the old target, met
    # l only goes on decaying from the start (e^{−k1 at} = 1.1e-7 m left at the step; the
    # fast turn moves it by integration error, 2e-8 m; the old first stage moved it 2e-5 m)
    left = abs(e_l[at_step])
    np.testing.assert_allclose(np.abs(e_l[after]), left * np.exp(-0.8 * (t[after] - at)), rtol=0, atol=5e-8)
    assert result.follower_metrics("f1")["settling"][0]["l_disturbance"] <= left + 5e-8


def test_clockwise_switch_and_ambiguous_shortest():
    change = Change(5.0, {"phi": math.pi / 3 + math.pi}, direction="clockwise")
    result = simulate_formation(Formation([eight_leader(), separation_bearing("f1", "leader", 2.0, math.pi / 3,
                                                                              changes=(change,))],
                                          references.eight(), duration=15.0))
    _, phi = result.outputs("f1")
    assert phi[-1] == pytest.approx(math.pi / 3 - math.pi, abs=1e-3)   # turned the other way, in front
    ambiguous = separation_bearing("f1", "leader", 2.0, math.pi / 3, changes=(Change(5.0, {"phi": 4 * math.pi / 3}),))
    with pytest.raises(FormationError, match="ambiguous"):
        simulate_formation(Formation([eight_leader(), ambiguous], references.eight(), duration=15.0))


def test_ramp_feeds_the_target_rate_forward():
    """Starting in formation, a ramped change keeps the output error at integration level."""
    change = Change(2.0, {"l": 3.0, "phi": math.pi / 2}, mode="ramp", duration=5.0)
    follower = separation_bearing("f1", "leader", 2.0, math.pi / 3, changes=(change,))
    result = simulate_formation(Formation([eight_leader(), follower], references.eight(), duration=10.0))
    e_l, e_phi = result.output_errors("f1")
    assert np.abs(e_l).max() < 1e-7 and np.abs(e_phi).max() < 1e-7
    l, phi = result.outputs("f1")
    assert l[-1] == pytest.approx(3.0) and phi[-1] == pytest.approx(math.pi / 2)


def test_a_ramp_settles_after_its_ramp():
    """Settling is the time until the changed output stays within 2 % of the change around
    its new target: a ramp fed forward tracks its moving target exactly, and settles when
    its target arrives there, within a sample (its error alone would say 0 s)."""
    change = Change(2.0, {"phi": math.pi / 2}, mode="ramp", duration=5.0)
    follower = separation_bearing("f1", "leader", 2.0, math.pi / 3, changes=(change,))
    result = simulate_formation(Formation([eight_leader(), follower], references.eight(), duration=10.0))
    settling = result.follower_metrics("f1")["settling"][0]
    from nonholo.sim.targets import target_table
    target = target_table(follower, result.t)[:, 1]      # the ramp's profile (smooth: not linear)
    inside = np.abs(target - math.pi / 2) <= 0.02 * (math.pi / 2 - math.pi / 3)
    arrives = result.t[np.argmax(inside & (result.t > 2.0))] - 2.0
    assert 4.0 < arrives < 5.0 and settling["phi_settling_time"] == pytest.approx(arrives, abs=0.0101)


def triangle(wedge=False, reference=None, duration=None):
    if wedge:
        r2 = separation_bearing("R2", "leader", math.sqrt(13), math.atan2(-2 * math.sqrt(3), 1),
                                start=(-1.0, -4.0, 0.0), start_frame="leader")
    else:
        r2 = separation_bearing("R2", "leader", 2.0, 2 * math.pi / 3, start=(-2.0, 3.0, 0.0), start_frame="leader")
    f = separation_separation("F", ("leader", "R2"), (2.0, 2.0), start=(-3.0, -2.0, 0.0), start_frame="leader")
    leader = eight_leader() if reference is None else circle_leader()
    return Formation([leader, r2, f], reference or references.eight(), duration=duration)


def test_separation_separation_test1_reference_numbers():
    result = simulate_formation(triangle())
    m = result.follower_metrics("F")
    n = result.formation.n_steps
    assert m["l1_error"]["final"] < 1e-12 and m["l2_error"]["final"] < 1e-12
    e1, e2 = result.output_errors("F")
    assert m["l1_error"]["mean"] == pytest.approx(grid_mean(abs(e1[0]), 1.0, 0.01, n), rel=1e-6)
    assert m["l2_error"]["mean"] == pytest.approx(grid_mean(abs(e2[0]), 1.0, 0.01, n), rel=1e-6)
    assert m["l1_error"]["mean"] == pytest.approx(0.00330, rel=6e-3)
    assert m["l2_error"]["mean"] == pytest.approx(0.01194, rel=6e-3)
    assert m["safety"]["min_abs_sin_gamma_difference"] == pytest.approx(0.707, abs=1e-3)
    r1, r2 = result.output_rates("F")
    np.testing.assert_allclose(r1, e1, atol=1e-9)      # l̇i = k (li_d − li), k = 1
    np.testing.assert_allclose(r2, e2, atol=1e-9)


def test_wedge_is_nearly_singular_and_reported():
    result = simulate_formation(triangle(wedge=True, reference=references.circle(), duration=20.0))
    safety = result.follower_metrics("F")["safety"]
    # spec §6 (c): 0.012 at t = 7.25 s; the value at the sample depends on how the fast passage
    # near sin(γ1 − γ2) = 0 is integrated (|v| > 200 m/s there), the time does not
    assert safety["min_abs_sin_gamma_difference"] < 0.02
    assert safety["min_abs_sin_gamma_time"] == pytest.approx(7.25, abs=0.05)
    # the passage goes *through* sin(γ1 − γ2) = 0 between two samples (an exact solver's step
    # size collapses at t = 7.2499 s): the sign changes are counted, exactly those of the record
    from nonholo.sim import kernel as kn

    sin_gamma = result.record[kn.REC_SIN_GAMMA, :, result.index("F"), 0]
    flips = int(np.count_nonzero(sin_gamma[1:] * sin_gamma[:-1] < 0.0))
    assert safety["sin_gamma_sign_changes"] == flips >= 1
    first = np.flatnonzero(sin_gamma[1:] * sin_gamma[:-1] < 0.0)[0]
    assert result.t[first] == pytest.approx(7.24, abs=0.015)
    fine = simulate_formation(triangle(reference=references.circle(), duration=20.0))   # Test 4, no wedge
    assert fine.follower_metrics("F")["safety"]["sin_gamma_sign_changes"] == 0


def test_sign_changes_through_exact_zeros_are_counted():
    """sin(γ1 − γ2) of −, 0, +, 0, −, − over six samples: two passages through the singular
    configuration, each through a sample where it is exactly 0 (scored by the kernel's
    statistics code from given states, as a fleet's run is)."""
    from nonholo.sim import kernel as kn
    from nonholo.sim.scenario import Follower, Robot, Scenario
    from nonholo.sim.simulator import planned_groups, score_states

    leader = Robot("L", controller("dynamic-feedback"), (0.0, 0.0, 0.0))
    r2 = Follower("R2", "separation-bearing", ("L",), targets=(2.0, 3.0), start=(2.0, 0.0, 0.0))
    f = Follower("F", "separation-separation", ("L", "R2"), targets=(3.0, 3.0), d=0.5, start=(-3.0, 0.1, 0.0))
    ys = [0.1, 0.0, -0.1, -0.0, 0.1, 0.2]   # F's castor point above, on, below… the line through L and R2
    scenario = Scenario(references.line(), [leader, r2, f], duration=0.01 * (len(ys) - 1), dt=0.01,
                        control_period=0.01)
    states = np.zeros((len(ys), 4, 3))
    states[:, 0, 1] = 2.0
    states[:, 0, 2], states[:, 1, 2] = -3.0, ys
    result = score_states(scenario, planned_groups(scenario), states, np.zeros((len(ys), kn.HELD_COUNT, 3)), 0.0)
    signs = np.sign(result.record[kn.REC_SIN_GAMMA, :, 2, 0])
    assert signs.tolist() == [-1.0, 0.0, 1.0, 0.0, -1.0, -1.0]
    safety = result.follower_metrics("F")["safety"]
    assert safety["sin_gamma_sign_changes"] == 2 and safety["min_abs_sin_gamma_difference"] == 0.0


def test_collinear_start_is_flagged_singular():
    leader = Leader("leader", controller("dynamic-feedback", kp=1.0, kd=0.7), start=(0.0, 0.0, 0.0))
    r2 = separation_bearing("R2", "leader", 3.0, math.pi, start=(-4.0, 0.0, 0.0))
    f = separation_separation("F", ("leader", "R2"), (2.0, 2.0), start=(-2.0, -1.0, math.pi / 2))  # castor (−2, 0)
    result = simulate_formation(Formation([leader, r2, f], references.line(), duration=2.0))
    safety = result.follower_metrics("F")["safety"]
    assert safety["min_abs_sin_gamma_difference"] < 1e-12 and safety["singular_samples"] >= 1


def test_chain_of_seven_errors_do_not_propagate():
    robots = [eight_leader()] + [behind(f"f{i}", "leader" if i == 1 else f"f{i - 1}") for i in range(1, 8)]
    result = simulate_formation(Formation(robots, references.eight(), duration=40.0, piconet=True))
    means = [result.follower_metrics(f"f{i}")["l_error"]["mean"] for i in range(1, 8)]
    np.testing.assert_allclose(means, means[0], rtol=1e-5)   # spec: 0.00398 on every link (T = 80π)
    peaks = [result.follower_metrics(f"f{i}")["safety"]["peak_omega"] for i in range(1, 8)]
    np.testing.assert_allclose(peaks[:4], [6.28, 12.6, 44, 126], rtol=0.02)
    assert all(b > a for a, b in zip(peaks, peaks[1:]))


def test_batch_matches_single_runs_and_solve_ivp():
    gains = [(1.0, 1.0), (2.0, 0.5), (0.7, 3.0)]
    formations = [Formation([eight_leader(), behind(k1=a, k2=b)], references.eight(), duration=10.0) for a, b in gains]
    batch = simulate_formation(formations)
    for member, formation in enumerate(formations):
        single = simulate_formation(formation)
        np.testing.assert_allclose(batch.output_errors("f1", member)[0], single.output_errors("f1")[0], atol=1e-10)
        np.testing.assert_allclose(batch.output_errors("f1", member)[0], -np.exp(-gains[member][0] * batch.t), atol=1e-6)
    scipy = simulate_formation(Formation([eight_leader(), behind()], references.eight(), duration=10.0,
                                         method="solve_ivp"))
    np.testing.assert_allclose(scipy.output_errors("f1")[1], batch.output_errors("f1", 0)[1], atol=1e-7)
    np.testing.assert_allclose(scipy.trajectory("x"), batch.trajectory("x", 0), atol=1e-7)


def test_castor_point_starting_on_a_parents_axle_centre_is_bad_input():
    """l(0) = 0: the bearing and the link laws are undefined there (spec §2.4)."""
    on_axle = separation_bearing("f1", "leader", 2.0, math.pi / 3, d=1.0, start=(-1.0, 0.0, 0.0), start_frame="leader")
    with pytest.raises(FormationError, match="castor point .* starts on leader's axle centre"):
        Formation([circle_leader(), on_axle], references.circle(), duration=1.0)
    off_axle = separation_bearing("f1", "leader", 2.0, math.pi / 3, d=1.0, start=(-1.0, 1e-6, 0.0), start_frame="leader")
    Formation([circle_leader(), off_axle], references.circle(), duration=1.0)   # accepted
