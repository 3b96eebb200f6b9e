"""A few copies of lone roots run one robot at a time (``Kernel.alone``, state and statistics
in registers); many copies run in loops over the batch (``Kernel.roots``). Both must give
the same trajectories, statistics and event counts, for every law, with limits, singular
passages, sub-steps and posture goals."""
import dataclasses
import math

import numpy as np
import pytest
from numba import literal_unroll, njit

from nonholo import references
from nonholo.control.registry import CONTROLLERS, POSTURE_CONTROLLERS, controller
from nonholo.sim import kernel as kn
from nonholo.sim.scenario import Robot, Scenario
from nonholo.sim.simulator import kernel_for, simulate

COPIES = kn.ALONE_BELOW + 3   # enough copies for the loops over the batch
# Laws whose batches are also run with limits that bind (their time loop with limits; the
# others' batches run the one without, ``Kernel.roots``): the limits' code is the same for
# every law (``kernel.law_command``), and each further law compiled both ways costs a fresh
# suite ~6 s.
LIMITED = ("dynamic-feedback",)


def limited(name: str) -> dict:
    """Actuator limits that bind at the start for the laws in ``LIMITED``, none for the others."""
    return dict(v_max=0.5, omega_max=0.6) if name in LIMITED else {}


def runs(scenario: Scenario, spread: float = 1.0):
    """(one copy: ``alone``, COPIES copies: the batch loops), recorded; the copies' starts
    are offset by ``spread`` times a few tenths (0: identical copies)."""
    members = [dataclasses.replace(scenario, robots=tuple(
        dataclasses.replace(r, start=(r.start[0] + 0.3 * spread * i, r.start[1] - 0.2 * spread * i, r.start[2]))
        for r in scenario.robots)) for i in range(COPIES)]
    return simulate(members[:1]), simulate(members)


def assert_same(one, many, rtol=1e-12):
    assert one.stats.shape[-1] == 1 and many.stats.shape[-1] == COPIES
    rows = list(range(kn.ROBOT_STATS))
    a, b = one.stats[rows, :, 0], many.stats[rows, :, 0]
    assert np.array_equal(np.isinf(a), np.isinf(b))
    assert np.allclose(np.where(np.isinf(a), 0, a), np.where(np.isinf(b), 0, b), rtol=rtol, atol=1e-12)
    assert np.allclose(one.record[..., 0], many.record[..., 0], rtol=rtol, atol=1e-10)


@pytest.mark.parametrize("name", sorted(CONTROLLERS))
@pytest.mark.parametrize("substeps", [None, 4])
def test_alone_equals_the_batch_loops_for_every_tracking_law(name, substeps):
    # actuator limits that bind at the start (``LIMITED``): saturation counts and peaks are
    # compared too. Planned sub-steps (None) come from the rates the copies meet, one plan per
    # batch: identical copies, so that the batch plans as the single run does; given ones,
    # copies from different starts.
    robot = Robot("r", controller(name), (2.0, -1.5, 0.3), **limited(name))
    one, many = runs(Scenario(references.eight(), [robot], duration=20.0, dt=0.01, substeps=substeps),
                     spread=0.0 if substeps is None else 1.0)
    assert (one.stats[kn.SAT_V, 0, 0] + one.stats[kn.SAT_W, 0, 0] > 0) == (name in LIMITED)   # the limits acted
    assert np.array_equal(one.substeps, many.substeps)
    assert_same(one, many)


def test_alone_equals_the_batch_loops_through_singular_passages():
    # dynamic feedback from rest: ξ starts at 0, the guarded singular region is entered
    robot = Robot("r", controller("dynamic-feedback", xi0=0.0), (0.5, -0.5, 0.3))
    one, many = runs(Scenario(references.eight(), [robot], duration=10.0, dt=0.01), spread=0.0)
    assert one.stats[kn.SINGULAR, 0, 0] > 0 and np.isfinite(one.stats[kn.FIRST_SINGULAR, 0, 0])
    assert np.array_equal(one.substeps, many.substeps)
    assert_same(one, many)


@pytest.mark.parametrize("name", sorted(POSTURE_CONTROLLERS))
def test_alone_equals_the_batch_loops_for_posture_goals(name):
    # posture laws measure their turn rates (sub-step planning, one plan per batch): identical
    # copies, so that the batch plans as the single run does
    robot = Robot("r", controller(name), (-2.0, -1.0, 0.5), goal=(0.0, 0.0, 0.0))
    one, many = runs(Scenario(None, [robot], duration=15.0, dt=0.02), spread=0.0)
    assert np.array_equal(one.substeps, many.substeps)
    assert_same(one, many, rtol=1e-10)


def test_several_lone_roots_of_two_laws_alone():
    robots = [Robot("a", controller("kanayama"), (0.2, 0.1, 0.0)), Robot("b", controller("cascaded"), (-0.3, 0.2, 0.1)),
              Robot("c", controller("kanayama", kx=2.0), (0.1, -0.4, 0.2))]
    one, many = runs(Scenario(references.circle(), robots, duration=10.0, dt=0.01))
    assert_same(one, many)


@pytest.mark.parametrize("name, substeps", [("kanayama", None), ("dynamic-feedback", 2), ("polar", None)])
def test_batches_past_one_chunk_integrate_every_copy_alike(name, substeps):
    # ``roots`` runs ROOTS_CHUNK copies at a time: copies in the second, partial chunk and on
    # both sides of the boundary follow the same trajectories as one copy alone (sub-steps
    # fixed, and a posture law's measured ones; limits that bind for the laws in ``LIMITED``)
    posture = name == "polar"
    robot = Robot("r", controller(name), (2.0, -1.5, 0.3), goal=(0.0, 0.0, 0.0) if posture else None,
                  **limited(name))
    scenario = Scenario(None if posture else references.eight(), [robot], duration=3.0, dt=0.01, substeps=substeps)
    copies = kn.ROOTS_CHUNK + 5
    members = [dataclasses.replace(scenario, robots=(dataclasses.replace(robot, start=(2.0 + 0.01 * i, -1.5, 0.3)),))
               for i in range(copies)]
    many = simulate(members)
    rows = list(range(kn.ROBOT_STATS))
    for i in (0, kn.ROOTS_CHUNK - 1, kn.ROOTS_CHUNK, copies - 1):
        if not posture:   # (a posture batch plans its sub-steps for all copies at once)
            one = simulate(members[i])
            assert np.allclose(one.stats[rows, 0, 0], many.stats[rows, 0, i], rtol=1e-12, atol=1e-12)
            assert np.allclose(one.record[..., 0], many.record[..., i], rtol=1e-12, atol=1e-10)
        # the statistics taken from each step's first RK4 stage equal the batch scoring code's,
        # which evaluates the law once more at every recorded state
        scored = score_both(members[i], many.record[:, :, :, i:i + 1])[1][0]
        assert np.allclose(scored[rows, 0, 0], many.stats[rows, 0, i], rtol=1e-12, atol=1e-12)
    # and the copies differ (a chunk that ran one copy's state for another would not)
    assert not np.allclose(many.record[kn.REC_X, -1, 0, 0], many.record[kn.REC_X, -1, 0, copies - 1])


@njit
def _mark(workspace):
    """Every element of each part of ``workspace_views`` set to 100 × part + its row, written
    through the views (their shapes as compiled)."""
    views = kn.workspace_views(workspace)
    shapes = []
    for part in literal_unroll((0, 1, 2, 3, 4, 5, 6, 7, 8)):
        view = views[part]
        shapes.append(view.shape[0] * 1000 + view.shape[-1])
        for row in range(view.shape[0]):
            view[row] = 100.0 * part + row
    return shapes


def test_the_roots_workspace_is_aligned_and_its_parts_tile_it_row_by_row():
    # ``run_roots`` reads a chunk's state, statistics, fields, limits and scratch rows through
    # views whose shapes are constants of the compiled code: each must be its own rows of the
    # workspace (none overlapping, none missed), in order, each row 64-byte aligned
    workspace = kn.new_workspace()
    assert workspace.shape == (kn.WORKSPACE_ROWS, kn.WORKSPACE_WIDTH) and workspace.flags.c_contiguous
    assert workspace.ctypes.data % 64 == 0 and workspace.strides[0] % 64 == 0
    assert kn.WORKSPACE_WIDTH >= kn.ROOTS_CHUNK and not (workspace.strides[0] & (workspace.strides[0] - 1)) == 0
    shapes = _mark(workspace)
    assert shapes == [count * 1000 + kn.WORKSPACE_WIDTH for count in kn.WORKSPACE_COUNTS]
    expected = np.concatenate([100.0 * part + np.arange(count) for part, count in enumerate(kn.WORKSPACE_COUNTS)])
    assert np.array_equal(workspace, np.repeat(expected[:, None], kn.WORKSPACE_WIDTH, axis=1))
    # the first four are indexed as the simulator's arrays, [row, robot 0, copy]
    views = [np.asarray(v) for v in _views(workspace)]
    assert [v.ndim for v in views] == [3] * kn.WORKSPACE_KEPT + [2] * (len(views) - kn.WORKSPACE_KEPT)


@njit
def _views(workspace):
    return kn.workspace_views(workspace)


@pytest.mark.parametrize("name", sorted(CONTROLLERS))
def test_unrecorded_batches_add_each_sample_in_the_step_s_loop_alike(name):
    # unrecorded, ``roots`` adds the sample at t_k to the statistics inside the RK4 step's
    # loop; recorded, in a loop of its own after it: the same statistics to rounding (LLVM may
    # fuse a multiply-add in one loop and not the other), the same event counts (limits that
    # bind for the laws in ``LIMITED``, two sub-steps per output step, copies past one chunk)
    robot = Robot("r", controller(name), (2.0, -1.5, 0.3), **limited(name))
    scenario = Scenario(references.eight(), [robot], duration=2.0, dt=0.01, substeps=2)
    members = [dataclasses.replace(scenario, robots=(dataclasses.replace(robot, start=(2.0 + 0.01 * i, -1.5, 0.3)),))
               for i in range(kn.ROOTS_CHUNK + 3)]
    recorded, unrecorded = simulate(members), simulate(members, record=False)
    assert (recorded.stats[kn.SAT_V].sum() + recorded.stats[kn.SAT_W].sum() > 0) == (name in LIMITED)
    a, b = recorded.stats, unrecorded.stats
    assert np.array_equal(np.isinf(a), np.isinf(b))
    assert np.allclose(np.where(np.isinf(a), 0, a), np.where(np.isinf(b), 0, b), rtol=1e-14, atol=0)
    assert np.array_equal(a[[kn.SAT_V, kn.SAT_W, kn.SINGULAR]], b[[kn.SAT_V, kn.SAT_W, kn.SINGULAR]])


def test_inf_limits_clip_nothing():
    # the premise of ``Kernel.roots``' time loop without limits: clipping to inf limits returns
    # every command as it is (NaN, signed zeros and infinities included) and flags nothing
    values = [math.nan, -0.0, 0.0, math.inf, -math.inf, 1e308, -5e-324, 3.5]
    for v in values:
        for omega in values:
            clipped = kn.saturate(v, omega, math.inf, math.inf)
            assert np.array_equal(np.array(clipped[:2]), np.array([v, omega]), equal_nan=True)
            assert [math.copysign(1.0, x) for x in clipped[:2]] == [math.copysign(1.0, v), math.copysign(1.0, omega)]
            assert clipped[2:] == (0.0, 0.0)


@pytest.mark.parametrize("record", [False, True])
def test_batches_without_limits_run_a_time_loop_of_their_own_with_the_same_numbers(record):
    # copies without limits run ``roots``' time loop that calls the law alone, not clipped by
    # inf limits: the same trajectories, statistics and event counts, bit for bit, as with
    # limits that never bind. Dynamic feedback (v = ξ): LLVM merges the plant's v·cos θ with
    # the law's ξ·cos θ there; a plant with multiply-adds fused then gave other last bits.
    # (Its only law: each law compiled both ways costs a fresh suite ~6 s.)
    scenario = Scenario(references.eight(), [Robot("r", controller("dynamic-feedback"), (2.0, -1.5, 0.3))],
                        duration=8.0, dt=0.01)
    members = [dataclasses.replace(scenario, robots=tuple(dataclasses.replace(r, start=(2.0 - 0.3 * i, -1.5, 0.3 * i))
                                                          for r in scenario.robots)) for i in range(COPIES)]
    wide = [dataclasses.replace(m, robots=tuple(dataclasses.replace(r, v_max=1e300, omega_max=1e300)
                                                for r in m.robots)) for m in members]
    free, clipped = simulate(members, record=record), simulate(wide, record=record)
    assert np.array_equal(free.stats, clipped.stats) and np.array_equal(free.substeps, clipped.substeps)
    if record:
        assert np.array_equal(free.record, clipped.record)
    assert not clipped.stats[[kn.SAT_V, kn.SAT_W]].any()
    config = scenario.robots[0].controller
    roots = kernel_for(((config.law, config.controller.gain_tuple),), False).roots
    assert roots.time_loop.signatures and roots.limited_time_loop.signatures   # (each ran)


def test_a_batch_with_limits_on_some_copies_clips_each_copy_by_its_own():
    # copies with both limits, none, only v_max or only omega_max in one batch: the time loop
    # with limits runs them all (the one without is for batches where every limit is inf), each
    # copy clipped by its own limits and equal to itself alone, bit for bit
    base = Robot("r", controller("dynamic-feedback"), (2.0, -1.5, 0.3))
    scenario = Scenario(references.eight(), [base], duration=4.0, dt=0.01, substeps=2)
    limits = [dict(v_max=0.5, omega_max=0.6), {}, dict(omega_max=0.6), dict(v_max=0.5), {},
              dict(v_max=0.5, omega_max=0.6), {}, {}]
    members = [dataclasses.replace(scenario, robots=(dataclasses.replace(base, start=(2.0 - 0.3 * i, -1.5, 0.3 * i),
                                                                         **given),)) for i, given in enumerate(limits)]
    many = simulate(members)
    rows = list(range(kn.ROBOT_STATS))
    for i, given in enumerate(limits):
        one = simulate(members[i])
        assert np.array_equal(one.record[..., 0], many.record[..., i])
        assert np.array_equal(one.stats[rows, 0, 0], many.stats[rows, 0, i])
        assert many.stats[kn.SAT_V, 0, i] == 0 or "v_max" in given   # (no clipping without a limit)
        assert many.stats[kn.SAT_W, 0, i] == 0 or "omega_max" in given
        assert np.abs(many.record[kn.REC_V, :, 0, i]).max() <= given.get("v_max", math.inf)
        assert np.abs(many.record[kn.REC_OMEGA, :, 0, i]).max() <= given.get("omega_max", math.inf)
    assert many.stats[kn.SAT_V, 0, 3] > 0 and many.stats[kn.SAT_W, 0, 2] > 0   # the one-sided limits acted


def test_every_batch_of_a_law_runs_one_compiled_time_loop():
    # recorded or not, in one chunk or several: ``run_roots`` is compiled once per law (the
    # record it writes is the simulator's whole array, never a slice whose layout varies:
    # each further signature cost a fresh install 5-8 s of compiling per law); with limits and
    # without alike (dynamic feedback: the suite compiles both of its loops anyway)
    config = controller("dynamic-feedback")
    robot = Robot("r", config, (2.0, -1.5, 0.3))
    scenario = Scenario(references.eight(), [robot], duration=0.5, dt=0.01)
    for copies, record in ((kn.ALONE_BELOW + 3, True), (kn.ROOTS_CHUNK + 3, True), (kn.ALONE_BELOW + 3, False),
                           (kn.ROOTS_CHUNK + 3, False)):
        simulate([scenario] * copies, record=record)
    roots = kernel_for(((config.law, config.controller.gain_tuple),), False).roots
    assert len(roots.time_loop.signatures) == 1
    for copies, record in ((kn.ALONE_BELOW + 3, True), (kn.ROOTS_CHUNK + 3, False)):   # and the loop with limits
        simulate([dataclasses.replace(scenario, robots=(dataclasses.replace(robot, v_max=1.0),))] * copies,
                 record=record)
    assert len(roots.limited_time_loop.signatures) == 1


def test_integrate_refuses_what_it_leaves_to_roots_and_alone():
    # (dynamic feedback: the sampled-data tests compile its ``integrate`` anyway)
    robot = Robot("r", controller("dynamic-feedback"), (0.2, 0.1, 0.0))
    kernel = kernel_for(((robot.controller.law, robot.controller.controller.gain_tuple),), False)
    assert kernel.integrator(False, kn.ALONE_BELOW) is kernel.roots
    assert kernel.integrator(False, 1) is kernel.alone and kernel.integrator(True, 100) is kernel.integrate
    other = controller("kanayama")
    with pytest.raises(ValueError, match="runs one law"):   # lone roots are grouped by law
        kn.make_kernel(robot.controller.law, robot.controller.controller.gain_tuple, other.law,
                       other.controller.gain_tuple, False)
    state = np.zeros((4, 1, 1))
    with pytest.raises(ValueError, match="Kernel.roots or Kernel.alone"):
        kernel.integrate(state, np.zeros((kn.MAX_FIELDS, 1, 1)), np.full((2, 1, 1), np.inf), np.zeros((3, 10)),
                         np.zeros(2, np.int64), np.ones(1, np.int64), np.zeros((1, 4, 1)), np.zeros((2, 1, 1)),
                         np.full(1, kn.ROOT_A, np.int64), np.zeros(1, np.int64), np.full((2, 1), -1, np.int64),
                         np.zeros(1, np.int64), np.zeros((1, 1)), 0.0, np.zeros(1), 0.0, 0.01, 0, 0, 1, 1,
                         *kn.new_stats(1, 1), np.empty((kn.REC_COUNT, 0, 1, 1)), np.zeros((kn.HELD_COUNT, 1, 1)),
                         np.zeros(2), False)


def score_both(scenario: Scenario, record: np.ndarray):
    """Score the recorded trajectory ``record`` (rows, N+1, 1, 1) of the one robot of
    ``scenario`` with ``score_alone`` and with the loops over the batch (``score``): the
    (stats, record) of each."""
    (robot,) = scenario.robots
    config = robot.controller
    kernel = kernel_for(((config.law, config.controller.gain_tuple),), False)
    assert kernel.scorer(False) is kernel.score_alone and kernel.scorer(True) is kernel.score
    grid = np.arange(scenario.n_steps + 1) * scenario.dt
    states = np.ascontiguousarray(np.moveaxis(record[[kn.REC_X, kn.REC_Y, kn.REC_THETA, kn.REC_XI]], 0, 1))
    if scenario.reference is not None:
        rows = scenario.reference.table(grid)
    else:
        rows = np.zeros((grid.size, 10))
        rows[:, 0] = grid
    values = config.gain_values(robot.goal)   # a posture law's goal first
    fields = np.zeros((kn.MAX_FIELDS, 1, 1))
    fields[:len(values), 0, 0] = values
    limits = np.array([robot.v_max, robot.omega_max]).reshape(2, 1, 1)
    graph = (np.zeros((1, 4, 1)), np.zeros((2, 1, 1)), np.full(1, kn.ROOT_A, np.int64), np.zeros(1, np.int64),
             np.full((2, 1), -1, np.int64), np.zeros((1, 1)), scenario.sin_floor, np.zeros(1))
    out = []
    for score in (kernel.score_alone, kernel.score):
        stats, pair_stats = kn.new_stats(1, 1)
        scored = np.empty((kn.record_rows(False), grid.size, 1, 1))
        score(states, fields, limits, rows, *graph, stats, pair_stats, scored, 0, np.zeros((0, kn.HELD_COUNT, 1, 1)))
        out.append((stats, scored))
    return out


@pytest.mark.parametrize("name", ["kanayama", "dynamic-feedback", "polar"])
def test_score_alone_equals_the_batch_score(name):
    # trajectories computed elsewhere (here: a recorded run, its limits binding) scored one
    # robot at a time by alone's code and by the batch loops: the same statistics and record
    posture = name == "polar"
    robot = Robot("r", controller(name), (2.0, -1.5, 0.3), v_max=0.5, omega_max=0.6,
                  goal=(0.0, 0.0, 0.0) if posture else None)
    scenario = Scenario(None if posture else references.eight(), [robot], duration=10.0, dt=0.01)
    run = simulate(scenario)
    (alone_stats, alone_record), (batch_stats, batch_record) = score_both(scenario, run.record)
    rows = list(range(kn.ROBOT_STATS))
    assert np.array_equal(alone_stats[rows], batch_stats[rows])
    assert np.array_equal(alone_record, batch_record)
    # and scoring the run's own trajectory reproduces the run's statistics
    assert np.allclose(alone_stats[rows, 0, 0], run.stats[rows, 0, 0], rtol=1e-12, atol=1e-12)
    assert alone_stats[kn.SAT_V, 0, 0] + alone_stats[kn.SAT_W, 0, 0] > 0


def lone_roots(integrate, config, states, dt, plan, recorded=False):
    """Run the lone-root time loop ``integrate`` (``Kernel.alone`` or ``Kernel.roots``) of
    ``config``'s law directly, for copies starting at ``states`` (4, copies) on sub-step
    ``plan`` over the figure eight: (statistics, step_rate)."""
    from nonholo.sim.simulator import stage_times
    from nonholo.sim.targets import TABLE_COLUMNS

    n, n_steps = states.shape[1], plan.size
    times, row_start = stage_times(dt, plan)
    fields = np.zeros((kn.MAX_FIELDS, 1, n))
    fields[:len(config.gain_vector())] = np.array(config.gain_vector())[:, None, None]
    stats, pair_stats = kn.new_stats(1, n)
    rate = np.zeros(n_steps + 1)
    integrate(states[:, None, :].copy(), fields, np.full((2, 1, n), np.inf), references.eight().table(times), row_start,
              plan, np.zeros((1, len(TABLE_COLUMNS), 1)), np.zeros((2, 1, n)), np.full(1, kn.ROOT_A, np.int64),
              np.zeros(1, np.int64), np.full((2, 1), -1, np.int64), np.zeros(1, np.int64), np.zeros((1, n)), 1e-3,
              np.zeros(n), 1.0, dt, 0, 0, n_steps, n_steps, stats, pair_stats,
              np.empty((kn.REC_ROBOT_COUNT, n_steps + 1 if recorded else 0, 1, n)), np.zeros((kn.HELD_COUNT, 1, n)),
              rate, False)
    return stats, rate


def test_stages_beyond_the_rotation_s_range_take_the_full_sin_cos_copy_by_copy():
    """RK4 stages 2–4 of lone roots rotate stage 1's sin θ, cos θ by δ = step·θ̇ where
    |δ| ≤ ROTATION_MAX and compute them in full elsewhere (``kernel.rotated_heading``). With
    dt = 0.2 s and far starts, some copies of one chunk turn faster than 1/8 rad per stage and
    others do not: ``Kernel.roots`` must choose copy by copy as ``Kernel.alone`` does (the
    same statistics, bit for bit; a chunk-wide choice, or none, would differ)."""
    from nonholo.numerics import ROTATION_MAX

    config = controller("dynamic-feedback", xi0=0.5)
    kernel = kernel_for(((config.law, config.controller.gain_tuple),), False)
    dt, copies, n_steps = 0.2, 9, 40
    plan = np.ones(n_steps, dtype=np.int64)
    states = np.array([[0.3 * i - 1.0, 1.5 * (i % 2), 0.9 * i, 0.5] for i in range(copies)]).T   # x, y, θ, ξ
    batch, rate = lone_roots(kernel.integrator(False, copies), config, states, dt, plan)
    assert (rate[:n_steps] * dt / 2).max() > 2 * ROTATION_MAX   # some stages beyond the range
    assert (rate[n_steps // 2:n_steps] * dt).min() < ROTATION_MAX   # and steps within it
    rows = list(range(kn.ROBOT_STATS))
    for c in range(copies):
        own, _ = lone_roots(kernel.integrator(False, 1), config, states[:, c:c + 1], dt, plan)
        assert np.array_equal(own[rows, 0, 0], batch[rows, 0, c])


@pytest.mark.parametrize("recorded", [False, True])
def test_a_nan_copy_does_not_hide_the_rates_of_its_chunk(recorded):
    """``Kernel.roots`` takes each step's largest rate over a chunk of copies (as integers):
    a copy whose state is NaN adds nothing, as in ``Kernel.alone``, instead of making the
    chunk's largest NaN and so dropping its other copies' rates (the sub-step plan would then
    miss them)."""
    config = controller("dynamic-feedback")
    kernel = kernel_for(((config.law, config.controller.gain_tuple),), False)
    n_steps, dt, copies = 3, 0.01, 9

    def step_rate(states):
        return lone_roots(kernel.roots, config, states, dt, np.ones(n_steps, np.int64), recorded)[1]

    states = np.array([[0.3 * i, -0.2 * i, 0.4 * i, 0.5] for i in range(copies)]).T   # x, y, θ, ξ
    finite = step_rate(states[:, 1:])
    with_nan = states.copy()
    with_nan[2, 0] = np.nan
    assert finite[:n_steps].min() > 0
    assert np.array_equal(step_rate(with_nan)[:n_steps], finite[:n_steps])


@pytest.mark.parametrize("plan", [(4, 1, 3, 2, 2, 1, 4, 1), (1, 4, 4, 2, 1, 3, 1, 4)])
def test_each_copy_keeps_its_own_check_of_the_sub_step_plan(plan):
    """A lone tracking root keeps, in its statistic ``STEP_RATE``, its largest rate met at a
    sub-step's first stage times dt over the fewest sub-steps of that output step and its
    neighbours: the largest over steps of its own ``step_rate`` times that, bit for bit, in
    ``Kernel.alone`` and in ``Kernel.roots`` alike. It is within a factor f exactly when the
    plan gives the copy every sub-step its own rates ask for (``measured_plan`` at f), which
    is how the simulator picks the copies of a batch to run again."""
    from nonholo.sim.simulator import measured_plan

    config = controller("dynamic-feedback", xi0=0.3)
    kernel = kernel_for(((config.law, config.controller.gain_tuple),), False)
    dt, copies = 0.01, 9
    plan = np.array(plan, dtype=np.int64)
    n_steps = plan.size

    def run(states, integrate):
        stats, rate = lone_roots(integrate, config, states, dt, plan)
        return stats[kn.STEP_RATE, 0], rate

    states = np.array([[0.3 * i - 1.0, -0.2 * i, 0.7 * i, 0.3] for i in range(copies)]).T   # x, y, θ, ξ
    batch, _ = run(states, kernel.integrator(False, copies))
    fewest = np.minimum.reduce([plan, np.r_[plan[:1], plan[:-1]], np.r_[plan[1:], plan[-1:]]])
    for c in range(copies):
        own, step_rate = run(states[:, c:c + 1], kernel.integrator(False, 1))
        assert own[0] == batch[c] == (step_rate[:n_steps] * (dt / fewest)).max() > 0
        for factor, fits in ((own[0] * (1 + 1e-9), True), (own[0] * (1 - 1e-9), False)):
            assert (measured_plan(step_rate, np.ones(n_steps, np.int64), dt, factor=factor) <= plan).all() == fits


def test_steps_at_the_most_sub_steps_ask_for_no_more():
    # measured_plan never asks for more than MAX_SUBSTEPS: a step already there is never
    # short, so it leaves the copy's own check (a copy whose rates ask for more than the
    # most would otherwise be run again at every attempt of its batch)
    wide, most = kn.wide_substep.py_func, kn.MAX_SUBSTEPS
    plan = np.array([most, most, 5, most, 2 * most], dtype=np.int64)
    assert [wide(plan, k, plan.size, 0.01) for k in range(plan.size)] == [0.0, 0.01 / 5, 0.01 / 5, 0.01 / 5, 0.0]
