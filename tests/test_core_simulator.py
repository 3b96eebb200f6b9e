import dataclasses
import math

import numpy as np
import pytest

from nonholo import examples, references
from nonholo.control.registry import controller
from nonholo.errors import InfeasibleReferenceError, NonholoInputError
from nonholo.sim.files import load_scenario
from nonholo.sim.scenario import Robot, Scenario
from nonholo.sim import kernel as kn
from nonholo.sim.simulator import simulate, stage_times


def test_rk4_agrees_with_solve_ivp():
    robots = [Robot("dfl", controller("dynamic-feedback"), (0.5, -0.5, 0.2)),
              Robot("nl", controller("nonlinear"), (0.5, -0.5, 0.2))]
    fast = simulate(Scenario(references.eight(), robots, duration=40.0, dt=0.01))
    exact = simulate(Scenario(references.eight(), robots, duration=40.0, dt=0.01, method="solve_ivp"))
    assert np.allclose(fast.metrics.error_mean, exact.metrics.error_mean, rtol=1e-7)
    assert np.max(np.abs(fast.x - exact.x)) < 1e-7


def test_batch_equals_single_runs():
    configs = [controller("kanayama", kx=3.0), controller("dynamic-feedback", kp=2.0), controller("cascaded"),
               controller("cascaded", c1=20.0)]  # a different stiffness: its own sub-steps
    robots = [Robot(f"r{i}", c, (0.1 * i, -0.2, 0.1)) for i, c in enumerate(configs)]
    batch = simulate(Scenario(references.circle(), robots, duration=30.0, dt=0.01), record=False)
    for i, robot in enumerate(robots):
        single = simulate(Scenario(references.circle(), [robot], duration=30.0, dt=0.01), record=False)
        assert np.array_equal(single.stats[:, 0], batch.stats[:, i])


def test_recording_does_not_change_statistics():
    robots = [Robot("r", controller("approximate-linearization"), (1.0, 0.0, 0.0))]
    sc = Scenario(references.eight(), robots, duration=30.0, dt=0.01)
    a, b = simulate(sc, record=True), simulate(sc, record=False)
    assert np.array_equal(a.stats, b.stats)
    e = a.error_norm()[0]
    assert a.metrics.error_mean[0] == pytest.approx(e.mean(), rel=1e-12)
    assert a.metrics.error_std[0] == pytest.approx(e.std(), rel=1e-9)
    assert a.metrics.error_max[0] == pytest.approx(e.max(), rel=1e-12)
    assert a.metrics.error_final[0] == pytest.approx(e[-1], rel=1e-12)


def test_grid_is_uniform_with_round_duration_over_dt():
    sc = Scenario(references.eight(), [Robot("r")], duration=1.004, dt=0.01)
    result = simulate(sc)
    assert sc.n_steps == 100 and result.t.size == 101 and result.t[-1] == pytest.approx(1.0)


def test_saturation_limits_and_counts():
    robot = Robot("r", controller("kanayama"), (0.0, 0.0, 0.0), v_max=1.0, omega_max=0.5)
    result = simulate(Scenario(references.circle(), [robot], duration=30.0, dt=0.01))
    assert result.metrics.peak_v[0] <= 1.0 and result.metrics.peak_omega[0] <= 0.5
    assert result.metrics.saturated_v[0] > 0


@pytest.mark.parametrize("record", [True, False])
def test_saturated_samples_count_samples_where_either_command_was_clipped(record):
    """``saturated_samples``: samples with v, ω or both clipped — not the larger of the two
    counts (here they overlap only in part), in batches too."""
    robot = Robot("r", controller("dynamic-feedback"), (0.0, 0.0, 3.0), v_max=1.5, omega_max=0.4)
    scenario = Scenario(references.circle(radius=3.0, period=20.0), [robot], duration=30.0, dt=0.01)
    recorded = simulate(scenario)
    v, omega = np.abs(recorded.v[0]), np.abs(recorded.omega[0])
    at_v, at_w = v >= 1.5 * (1 - 1e-12), omega >= 0.4 * (1 - 1e-12)
    assert 0 < (at_v & at_w).sum() < min(at_v.sum(), at_w.sum())    # the counts overlap in part
    events = simulate(scenario, record=record).to_dict()["robots"]["r"]["events"]
    assert events["saturated_v_samples"] == at_v.sum() and events["saturated_omega_samples"] == at_w.sum()
    assert events["saturated_samples"] == (at_v | at_w).sum()
    assert events["saturated_fraction"] == pytest.approx((at_v | at_w).mean(), rel=1e-12)
    batch = simulate([scenario] * 5, record=record)   # (the batch kernel's own statistics)
    assert np.all(batch.stats[kn.SAT_ANY, 0] == (at_v | at_w).sum())
    assert np.all(batch.stats[kn.SAT_V, 0] == at_v.sum()) and np.all(batch.stats[kn.SAT_W, 0] == at_w.sum())


def test_sampled_data_control_holds_the_command():
    robot = Robot("r", controller("dynamic-feedback"), (0.3, -0.3, 0.0))
    held = simulate(Scenario(references.eight(), [robot], duration=60.0, dt=0.01, control_period=0.1))
    v = held.v[0]
    assert np.all(v[1:10] == v[0]) and v[10] != v[0]
    continuous = simulate(Scenario(references.eight(), [robot], duration=60.0, dt=0.01))
    assert held.metrics.error_final[0] < 5e-3 and held.metrics.error_mean[0] != continuous.metrics.error_mean[0]
    with pytest.raises(NonholoInputError, match="multiple of dt"):
        Scenario(references.eight(), [robot], dt=0.01, control_period=0.015)


@pytest.mark.parametrize("substeps", [None, 1, 3])
def test_the_result_holds_the_reference_at_the_output_instants(substeps):
    """One sub-step per output step gives a view of the stage table (every other row), more
    a copy; both are the reference's own table at the output grid, bit for bit."""
    robot = Robot("r", controller("dynamic-feedback"), (0.3, -0.3, 0.0))
    result = simulate(Scenario(references.eight(), [robot], duration=20.0, dt=0.01, substeps=substeps))
    assert result.reference_rows.shape == (result.t.size, 10)
    times, row_start = stage_times(0.01, np.full(2000, result.substeps[0]))
    assert np.array_equal(result.reference_rows, references.eight().table(times[row_start]))
    assert np.allclose(result.reference_rows[:, 0], result.t, rtol=0, atol=1e-12)
    shared = np.shares_memory(result.reference_rows, result.reference_rows.base) if result.reference_rows.base \
        is not None else False
    assert shared == (substeps in (None, 1)) == (result.reference_rows.strides[0] == 160)


@pytest.mark.parametrize("plan, window", [(np.full(7, 1), (0, 7)), (np.full(9, 3), (2, 6)),
                                          (np.array([20, 20, 4, 1, 1, 1, 7, 1000, 2]), (0, 9)),
                                          (np.array([20, 20, 4, 1, 1, 1, 7, 1000, 2]), (3, 8))])
def test_stage_times_are_k_dt_plus_half_sub_steps(plan, window):
    """Each stage row's time is k·dt + j·(dt/(2m)) for the j-th half sub-step of output step k,
    bit for bit (a row's time does not depend on the rest of the plan), then k1·dt; rows are
    numbered from the window's first, and ``row_start`` is the whole plan's."""
    dt, (k0, k1) = 0.013, window
    times, row_start = stage_times(dt, plan, k0, k1)
    expected = [k * dt + j * (dt / (2 * m)) for k, m in zip(range(k0, k1), plan[k0:k1]) for j in range(2 * m)]
    assert times.tolist() == expected + [k1 * dt]
    assert row_start.tolist() == [0, *np.cumsum(2 * plan).tolist()]


def test_stiff_cascaded_law_is_substepped():
    result = simulate(Scenario(references.sinusoid(), [Robot("r", controller("cascaded"))], duration=5.0, dt=0.01))
    assert result.substeps[0] >= 5 and math.isfinite(result.metrics.error_mean[0])


def test_a_tracking_transient_is_sub_stepped_from_the_rates_it_meets():
    """Dynamic feedback from a far start with a small ξ(0): ω reaches 38 rad/s, which the
    prior plan (gains and reference) does not know. One RK4 step per dt drives ξ through 0
    (h·ω = 2.5 at the second step) and ends on the wrong branch, driving backward; planned
    from the rates met (h·|ω| ≤ 0.5 for a tracking law), the run is the converged one, alone
    and in a batch of other starts."""
    scenario = _transient()
    exact = simulate(dataclasses.replace(scenario, method="solve_ivp"))
    coarse = simulate(dataclasses.replace(scenario, substeps=1))
    assert coarse.xi[0, 1] < 0 < exact.xi[0, 1] and abs(coarse.metrics.heading_final[0]) > 3.0
    robot = scenario.robots[0]
    others = [dataclasses.replace(scenario, robots=(dataclasses.replace(robot, start=(float(x), 0.0, 0.0)),))
              for x in range(4, 10)]
    # one copy that diverges (ω overflows, then NaN): its rates must not hide the others' in
    # its chunk of the batch loops; the fast copy comes last
    diverging = dataclasses.replace(scenario, robots=(Robot("r", controller("dynamic-feedback", xi0=0.0,
                                                                             xi_min=1e-300), robot.start),))
    runs = ((simulate(scenario), 0), (simulate([*others, scenario]), -1),
            (simulate([diverging, *others, scenario], on_divergence="report"), -1))
    for planned, copy in runs:
        assert planned.substeps.max() > 1 and (planned.record[kn.REC_XI, :, 0, copy] > 0).all()
        xy = planned.record[[kn.REC_X, kn.REC_Y], :, 0, copy]
        assert np.abs(xy - exact.record[[kn.REC_X, kn.REC_Y], :, 0, 0]).max() < 1e-5
        assert np.ravel(planned.metrics.error_mean)[copy] == pytest.approx(exact.metrics.error_mean[0], rel=1e-6)
    assert not np.isfinite(runs[2][0].stats[kn.E_MEAN, 0, 0])


def test_a_batch_runs_again_only_the_copies_that_need_more_sub_steps(monkeypatch):
    """One fast copy (``_transient``) among starts that need no more sub-steps than planned in
    advance: only it runs again, so the others keep the prior plan and equal their runs
    alone bit for bit, and it gets at least the sub-steps it gets alone (its run again shares
    a plan with the other copies run again). Here every copy ends within its own plan's
    factor (its ``STEP_RATE``; a copy still short after ``PLAN_ATTEMPTS`` runs would not)."""
    from nonholo.sim import simulator as sm

    transient = _transient()
    fast = transient.robots[0]
    calm = [dataclasses.replace(fast, name=f"c{i}", start=(0.05 * i, 0.1 * i - 0.3, 0.02 * i)) for i in range(9)]
    robots = (*calm[:4], fast, *calm[4:])
    batch = dataclasses.replace(transient, robots=robots)
    copies_run = []
    run_roots = sm.kn.Kernel.integrator

    def counting(self, sampled_data, copies):
        copies_run.append(copies)
        return run_roots(self, sampled_data, copies)

    monkeypatch.setattr(sm.kn.Kernel, "integrator", counting)
    together = simulate(batch)
    assert copies_run[0] == len(robots) and copies_run[1:] and set(copies_run[1:]) == {1}   # the fast one again
    assert (together.stats[kn.STEP_RATE] <= sm.STABLE_STEP_FACTOR).all()
    for i, robot in enumerate(robots):
        alone = simulate(dataclasses.replace(transient, robots=(robot,)))
        if robot is fast:
            assert together.substeps[i] >= alone.substeps[0] > 1
            assert np.abs(together.record[:2, :, i, 0] - alone.record[:2, :, 0, 0]).max() < 1e-6
        else:
            assert together.substeps[i] == alone.substeps[0] == 1
            assert np.array_equal(together.stats[:, i, 0], alone.stats[:, 0, 0], equal_nan=True)
            assert np.array_equal(together.record[:, :, i, 0], alone.record[:, :, 0, 0], equal_nan=True)


def test_members_that_differ_in_gains_get_their_own_prior_plans():
    # a stiff member (kp = 2500: its law's rate 50/s asks for 20 sub-steps at start-up, then 2)
    # in a batch with a member of the default gains: each integrates on the plan it gets
    # alone, bit for bit (a batch took the first member's prior plan for all: 1.1e-5 m off)
    eight = references.eight()

    def member(**gains):
        return Scenario(eight, [Robot("r", controller("dynamic-feedback", **gains), (0.01, 0.01, 0.0))], duration=4.0,
                        dt=0.01)

    members = [member(), member(kp=2500.0, kd=100.0), member()]
    together = simulate(members)
    assert together.member_substeps.tolist() == [[1, 20, 1]] and together.substeps.tolist() == [20]
    assert [together.to_dict(m)["robots"]["r"]["substeps"] for m in range(3)] == [1, 20, 1]
    for m, scenario in enumerate(members):
        alone = simulate(scenario)
        assert np.array_equal(together.record[..., m], alone.record[..., 0], equal_nan=True)
        assert np.array_equal(together.stats[..., m], alone.stats[..., 0], equal_nan=True)


def _transient() -> Scenario:
    """Dynamic feedback from a far start with a small ξ(0): ω reaches 38 rad/s (see below)."""
    robot = Robot("r", controller("dynamic-feedback", kp=1.0, kd=0.7, xi0=0.05), (18.0, -6.0, -0.8579290802496002))
    return Scenario(references.circle(), [robot], duration=10.0, dt=0.01)


def test_a_tracking_robot_from_rest_is_planned_in_a_few_runs():
    """ξ(0) = 0: ξ grows as ξ̇·t, so |ξ̇/ξ| ≈ 1/t at a sub-step's first stage whatever the
    step; a tracking robot's plan follows |ω| (guarded by ξ_min), which more sub-steps
    resolve, not |ξ̇/ξ|, which no plan would meet (every run then asked for 4x more, up to
    1 000 sub-steps everywhere)."""
    robot = Robot("r", controller("dynamic-feedback", xi0=0.0), (0.5, -0.5, 0.3))
    result = simulate(Scenario(references.eight(), [robot], duration=10.0, dt=0.01))
    assert result.substeps.max() < 100   # (its largest per step: 14 where ξ passes ξ_min)


def test_the_control_period_reported_is_the_one_held():
    # control_period is taken to within 1e-6 of a multiple of dt: the JSON says what ran
    eight = Scenario(references.eight(), [Robot("r", controller("nonlinear"))], duration=1.0, dt=0.01)
    for given, held in ((0.05000001, 0.05), (0.03, 0.03)):
        result = simulate(dataclasses.replace(eight, control_period=given))
        assert result.to_dict()["simulation"]["control_period"] == held


def test_reference_with_vanishing_speed_is_rejected_for_laws_that_need_v_d():
    ref = references.waypoints([[0, 0, 0], [5, 2, 1], [10, 4, 0]], boundary="clamped")
    with pytest.raises(InfeasibleReferenceError, match=r"vanishes at t = 0 s.*kanayama"):
        simulate(Scenario(ref, [Robot("r", controller("kanayama"))], dt=0.01))
    with pytest.raises(InfeasibleReferenceError, match="xi0 defaults to v_d"):
        simulate(Scenario(ref, [Robot("r", controller("dynamic-feedback"))], dt=0.01))
    ok = simulate(Scenario(ref, [Robot("r", controller("dynamic-feedback", xi0=0.01))], dt=0.01))
    assert ok.metrics.error_final[0] < 0.05


def test_scenario_validation():
    with pytest.raises(NonholoInputError, match="unique"):
        Scenario(references.eight(), [Robot("a"), Robot("a")])
    with pytest.raises(NonholoInputError, match="duration"):
        Scenario(references.expression("t", "0"), [Robot("a")])
    with pytest.raises(NonholoInputError, match="dt must be a positive"):
        Scenario(references.eight(), [Robot("a")], dt=-1.0)


def test_reference_tables_kept_for_reuse_are_bounded():
    """A sweep has a sub-step plan (and a reference table) per gain: the tables kept for groups
    that share a plan stay under the bound, oldest dropped first, the newest always kept."""
    from nonholo.sim import simulator as sm

    table = (np.zeros((sm.REFERENCE_CACHE_BYTES // 8 // 3, 1)), np.zeros(1), np.zeros(1))
    cache = {}
    for key in (b"a", b"b", b"c", b"d"):
        cache[key] = table
        sm.trim_reference_cache(cache, key)
    assert list(cache) == [b"c", b"d"]
    huge = (np.zeros((sm.REFERENCE_CACHE_BYTES // 8 + 1, 1)), np.zeros(1), np.zeros(1))
    cache[b"e"] = huge
    sm.trim_reference_cache(cache, b"e")
    assert list(cache) == [b"e"]


def test_a_large_batch_is_set_up_without_rebuilding_the_robot_list_per_robot(monkeypatch):
    # ``Scenario.names`` builds a tuple of every robot's name per call: set-up code that calls
    # it once per robot is quadratic (it took 10^4 robots from 0.4 s to 2 s per run)
    calls = []
    names = Scenario.names.fget
    monkeypatch.setattr(Scenario, "names", property(lambda self: calls.append(1) or names(self)))
    robots = [Robot(f"r{i}", controller("kanayama"), (0.01 * i, 0.0, 0.0)) for i in range(2000)]
    run = simulate(Scenario(references.circle(), robots, duration=0.05, dt=0.01), record=False)
    assert run.stats.shape[1] == 2000 and len(calls) < 50


def _copies(scenario: Scenario, n: int) -> list[Scenario]:
    return [dataclasses.replace(scenario, robots=tuple(
        dataclasses.replace(r, start=(r.start[0] + 0.2 * i, r.start[1], r.start[2])) if isinstance(r, Robot) else r
        for r in scenario.robots)) for i in range(n)]


def _progress_cases():
    eight = Scenario(references.eight(), [Robot("r", controller("dynamic-feedback"), (0.5, -0.5, 0.3))], duration=4.0,
                     dt=0.01)
    chain = load_scenario(examples.resolve("formation-chain"))
    chain = dataclasses.replace(chain, duration=1.0)
    return {
        "alone": [eight],                                                 # Kernel.alone
        "roots": _copies(eight, 9),                                       # Kernel.roots
        "roots-substeps": _copies(dataclasses.replace(eight, substeps=3), 9),
        "alone-replanned": [_transient()],                                # run again with more sub-steps
        "roots-replanned": _copies(_transient(), 9),
        "posture": _copies(Scenario(None, [Robot("p", controller("polar"), (-1.0, -1.0, 0.5), goal=(0.0, 0.0, 0.0))],
                                    duration=4.0, dt=0.02), 5),           # measured turn rates
        "sampled": _copies(dataclasses.replace(eight, control_period=0.05), 5),   # Kernel.integrate
        "formation": [chain],                                             # Kernel.integrate with followers
    }


@pytest.mark.parametrize("case", ["alone", "roots", "roots-substeps", "alone-replanned", "roots-replanned", "posture",
                                  "sampled", "formation"])
def test_a_run_shown_with_progress_equals_one_run_without(case):
    # a progress bar runs the kernel in 50 resumed pieces (k_start, k_stop): every kernel
    # must give the same numbers as in one call
    members = _progress_cases()[case]
    whole = simulate(members, progress=False)
    pieces = simulate(members, progress=True)
    assert np.array_equal(whole.stats, pieces.stats, equal_nan=True)
    assert np.array_equal(whole.record, pieces.record, equal_nan=True)
    assert np.array_equal(whole.substeps, pieces.substeps)


def _limited_on_some(members: list[Scenario]) -> list[Scenario]:
    """Every other member's robot with limits that bind (the loop with limits, for every copy)."""
    return [dataclasses.replace(m, robots=tuple(dataclasses.replace(r, v_max=0.3, omega_max=0.5) for r in m.robots))
            if i % 2 else m for i, m in enumerate(members)]


@pytest.mark.parametrize("case", ["roots", "roots-substeps", "roots-replanned", "roots-limited"])
def test_unrecorded_pieces_keep_the_final_errors_and_counts_of_a_recorded_run(case):
    # unrecorded, ``Kernel.roots`` takes the sample at t_k in stage 1's loop, which leaves the
    # final errors to the run's last sample (and, without limits, the saturation counts as
    # they are): in 50 pieces too, every statistic is the recorded run's
    members = _limited_on_some(_progress_cases()["roots"]) if case == "roots-limited" else _progress_cases()[case]
    recorded = simulate(members, progress=False)
    pieces = simulate(members, record=False, progress=True)
    assert np.array_equal(recorded.stats, pieces.stats, equal_nan=True)
    assert (recorded.stats[kn.E_FINAL] != recorded.stats[kn.E_MAX]).any()   # (final errors of their own)
    if case == "roots-limited":   # (counts that move, on the copies with limits only)
        counts = recorded.stats[[kn.SAT_V, kn.SAT_W, kn.SAT_ANY], 0]
        assert (counts[:, 1::2] > 0).all() and not counts[:, ::2].any()


def _chain(duration: float) -> Scenario:
    return dataclasses.replace(load_scenario(examples.path("formation-chain")), duration=duration)


def _switch_at(at: float, **simulation) -> Scenario:
    # the leader starts on its reference and the follower in formation: the first windows need
    # no more sub-steps than planned in advance, the step change at ``at`` does
    base = load_scenario(examples.path("formation-circle-switch"))
    leader, follower = base.robots
    row = base.reference.table(np.zeros(1))[0]
    leader = dataclasses.replace(leader, start=(float(row[1]), float(row[2]), float(row[7])))
    follower = dataclasses.replace(follower, start=None, changes=(dataclasses.replace(follower.changes[0], at=at),))
    return dataclasses.replace(base, robots=(leader, follower), duration=20.0, **simulation)


@pytest.mark.parametrize("case", ["chain", "switch", "switch-sampled"])
def test_a_window_run_again_leaves_no_trace(monkeypatch, case):
    # A window whose rates ask for more sub-steps is run again from its start: the state,
    # bearings, statistics and held commands go back to the window's start, and the rows of the
    # windows before keep their times. So the planned run equals one run straight through on
    # the plan it ended with (no window runs again then), bit for bit.
    from nonholo.sim import simulator as sm

    plans = []
    run_rk4 = sm._run_rk4
    monkeypatch.setattr(sm, "_run_rk4", lambda *args: plans.append(run_rk4(*args).plan) or run_rk4(*args))
    scenario = {"chain": lambda: _chain(3.0), "switch": lambda: _switch_at(10.0, dt=0.1),
                "switch-sampled": lambda: _switch_at(10.0, dt=0.05, control_period=0.1)}[case]()
    planned = simulate(scenario)
    plan = plans[0]
    if case == "chain":
        assert plan.max() > 100 and plan.min() == 1   # re-planned: the start-up needs hundreds of sub-steps
    else:   # re-planned at the change only
        changed = np.flatnonzero(plan != plan[0])
        assert changed.size and changed[0] >= int(10.0 / scenario.dt) - 1
    monkeypatch.setattr(sm, "prior_plan", lambda scenario, rate: plan.copy())
    straight = simulate(scenario)
    assert np.array_equal(plans[-1], plan)
    assert np.array_equal(planned.record, straight.record, equal_nan=True)
    assert np.array_equal(planned.stats, straight.stats, equal_nan=True)
    assert np.array_equal(planned.reference_rows, straight.reference_rows)


def test_a_planned_run_is_as_accurate_as_its_rule():
    # h·|ω| ≤ 0.05 at every step of the chain's violent start-up (3 400 rad/s): within 2e-5 m of
    # a run with 800 sub-steps everywhere; 100 sub-steps everywhere (10× the planned run's work)
    # are short of the start-up's needs: 1.4e-4 m off
    chain = _chain(3.0)
    fine = simulate(dataclasses.replace(chain, substeps=800)).record
    planned = simulate(chain).record
    assert np.abs(planned[:2] - fine[:2]).max() < 2e-5
    coarse = simulate(dataclasses.replace(chain, substeps=100)).record
    assert np.abs(coarse[:2] - fine[:2]).max() > 5e-5


def test_the_plan_of_a_window_is_the_plan_of_the_whole_run_there():
    from nonholo.sim.simulator import measured_plan

    rng = np.random.default_rng(3)
    for n in (1, 2, 7, 40):
        rate = rng.uniform(0.0, 60.0, n + 1)
        rate[rng.integers(0, n + 1)] = np.nan   # a non-finite rate asks for the most sub-steps
        prior = rng.integers(1, 4, n)
        whole = measured_plan(rate, prior, 0.01)
        assert whole.max() == 1000 and (whole >= prior).all()
        for k0 in range(n):
            for k1 in range(k0 + 1, n + 1):
                assert np.array_equal(measured_plan(rate, prior, 0.01, k0, k1), whole[k0:k1])


def test_a_plan_s_reference_table_is_built_once(monkeypatch):
    # Shown with a progress bar (50 windows) or not, a run with a fixed plan evaluates its
    # reference once per stage row; a measured plan that is never changed builds its table once.
    from nonholo.sim import simulator as sm

    built = []
    reference_rows = sm._reference_rows
    monkeypatch.setattr(sm, "_reference_rows", lambda scenario, times: built.append(times.size) or
                        reference_rows(scenario, times))
    circle = dataclasses.replace(load_scenario(examples.path("test4-circle")), substeps=2, duration=20.0, steps=None)
    for progress in (False, True):
        built.clear()
        simulate(circle, record=False, progress=progress)
        assert built == [2 * 2 * circle.n_steps + 1]
    leader, follower = _switch_at(10.0, dt=0.1).robots   # measured (a follower); no change: no re-plan
    still = dataclasses.replace(_switch_at(10.0, dt=0.1), robots=(leader, dataclasses.replace(follower, changes=())))
    built.clear()
    simulate(still)
    assert len(built) == 1


def test_a_record_has_link_rows_only_where_the_scenario_has_followers():
    """Lone roots record their robot rows only (a follower's link rows would be zeros); a
    scenario with followers records every row, a lone root's link rows zeros and its robot
    rows those of its run alone."""
    eight = Scenario(references.eight(), [Robot("r", controller("dynamic-feedback"), (0.5, -0.5, 0.3))], duration=2.0,
                     dt=0.01)
    alone = simulate(eight)
    assert alone.record.shape == (kn.REC_ROBOT_COUNT, eight.n_steps + 1, 1, 1)
    assert not alone.outputs("r")[0].any() and not alone.sin_gamma_difference("r").any()   # no link: zeros
    chain = load_scenario(examples.resolve("formation-chain"))
    mixed = dataclasses.replace(chain, robots=(*chain.robots[:2], eight.robots[0]), duration=2.0,
                                reference=eight.reference, piconet=False)
    both = simulate(mixed)
    assert both.record.shape == (kn.REC_COUNT, mixed.n_steps + 1, 3, 1)
    assert np.array_equal(both.record[:kn.REC_ROBOT_COUNT, :, 2], alone.record[:, :, 0])
    assert not both.record[kn.REC_ROBOT_COUNT:, :, 2].any()
    l, phi = both.outputs(chain.robots[1].name)
    assert l[0] > 0 and np.isfinite(phi).all()   # the follower's link rows are recorded


def test_the_result_counts_the_rk4_steps_its_plan_cost():
    # given sub-steps: exactly robots x steps x sub-steps; a planned run counts its runs again
    eight = Scenario(references.eight(), [Robot("a", controller("kanayama")), Robot("b", controller("kanayama"))],
                     duration=1.0, dt=0.01)
    assert simulate(dataclasses.replace(eight, substeps=3)).rk4_steps == 2 * 100 * 3
    assert simulate(eight).to_dict()["simulation"]["rk4_steps"] == 2 * 100
    transient = simulate(_transient())
    n = _transient().n_steps
    assert transient.rk4_steps > 2 * n   # its first run (n) and at least one more, with more sub-steps
    assert simulate(dataclasses.replace(_transient(), method="solve_ivp")).rk4_steps == 0


def test_the_bench_batch_runs_again_only_its_few_fast_starts():
    """``nonholo bench``'s batch of 10^4 random starts: 25 turn fast at their start and need
    more sub-steps there. Only they run again: about one RK4 step per robot-step (when the
    whole batch ran again, up to four times, its figure fell fivefold)."""
    from nonholo.sim import benchmark

    batch = benchmark.batch_scenario(duration=2.0)
    result = simulate(batch, record=False)
    assert result.substeps.max() > 1 and (result.substeps > 1).sum() < 100
    assert result.rk4_steps < 1.1 * len(batch.robots) * batch.n_steps
