"""The simulator: wires a reference, unicycle plants and tracking laws, then runs the
compiled RK4 kernel (or scipy ``solve_ivp`` for cross-checks).

Robots that share a law are integrated together as one batch; the reference is
evaluated once per distinct time grid (rows at every RK4 stage time).
"""
from __future__ import annotations

import math
import sys
import time
from collections import defaultdict
from functools import cache

import numpy as np
from scipy.integrate import solve_ivp

from nonholo.control.registry import CONTROLLERS, TrackingController, initial_state
from nonholo.errors import InfeasibleReferenceError, NonholoInputError, SimulationError
from nonholo.references.feedforward import REF_OMEGA, REF_V
from nonholo.sim.kernel import MAX_GAINS, STAT_COUNT, make_integrator, new_stats, packed_law
from nonholo.sim.result import SimulationResult
from nonholo.sim.scenario import Scenario

# RK4 sub-step size relative to the fastest closed-loop rate λ: h·λ ≤ 0.5.
STABLE_STEP_FACTOR = 0.5
# Stiff laws (more than one sub-step) also refine their first 50/λ seconds tenfold, to
# resolve the initial transient (the cascaded law turns at ~300 rad/s for ~20 ms).
STARTUP_TIME_CONSTANTS = 50.0
STARTUP_REFINEMENT = 10
MAX_SUBSTEPS = 1000
# RK4 is stable for a linear mode of rate λ while h·λ < 2.785 (real axis).
RK4_STABILITY_LIMIT = 2.78
# The reference is surveyed at this many points to size the sub-steps.
SURVEY_POINTS = 2001
# Above this many robot-sub-steps a run is split into chunks with a progress bar.
PROGRESS_WORK = 2e8


@cache
def integrator(law, recording: bool):
    return make_integrator(law, recording)


def _substep_plan(scenario: Scenario, stiffness: float) -> tuple[int, int, int]:
    """(sub-steps per output step, refined sub-steps, output steps refined at the start):
    uniform if the scenario gives them, else from the law's stiffness (the fastest
    closed-loop rate, 1/s)."""
    if scenario.method != "rk4":
        return 1, 1, 0
    if scenario.substeps is not None:
        step = scenario.dt / scenario.substeps
        if stiffness * step > RK4_STABILITY_LIMIT:
            raise NonholoInputError(
                f"substeps = {scenario.substeps} is unstable for this law: its fastest rate {stiffness:.3g} 1/s times "
                f"the step {step:.3g} s exceeds RK4's stability limit {RK4_STABILITY_LIMIT}; use more substeps or "
                "leave them automatic")
        return scenario.substeps, scenario.substeps, 0
    needed = stiffness * scenario.dt / STABLE_STEP_FACTOR
    if not needed <= MAX_SUBSTEPS:  # also catches inf and nan
        raise NonholoInputError(
            f"the control law is too stiff for dt = {scenario.dt:g} s (fastest rate {stiffness:.3g} 1/s would need "
            f"{needed:.3g} sub-steps per step, at most {MAX_SUBSTEPS}): reduce dt or lower the gains")
    base = max(1, math.ceil(needed))
    if base == 1:
        return 1, 1, 0
    return base, base * STARTUP_REFINEMENT, math.ceil(STARTUP_TIME_CONSTANTS / stiffness / scenario.dt)


def _plan_array(plan: tuple[int, int, int], n_steps: int) -> np.ndarray:
    base, refined, refined_steps = plan
    substeps = np.full(n_steps, base, dtype=np.int64)
    substeps[:refined_steps] = refined
    return substeps


def stage_times(dt: float, plan: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Times of every RK4 stage row and the first row of each output step."""
    if (plan == plan[0]).all():  # uniform sub-steps: a plain arithmetic sequence
        m = int(plan[0])
        return np.arange(2 * m * plan.size + 1) * (dt / (2 * m)), np.arange(plan.size + 1) * (2 * m)
    row_start = np.zeros(plan.size + 1, dtype=np.int64)
    np.cumsum(2 * plan, out=row_start[1:])
    step_of_row = np.repeat(np.arange(plan.size), 2 * plan)
    offset = np.arange(row_start[-1]) - row_start[step_of_row]
    times = np.empty(row_start[-1] + 1)
    times[:-1] = step_of_row * dt + offset * (dt / (2 * plan[step_of_row]))
    times[-1] = plan.size * dt
    return times, row_start


def _check_finite(scenario: Scenario, rows: np.ndarray) -> None:
    bad = ~np.isfinite(rows).all(axis=1)
    if bad.any():
        raise InfeasibleReferenceError(
            f"the {scenario.reference.kind} reference is not finite at t = {rows[np.argmax(bad), 0]:.6g} s "
            "(position or its first two derivatives): use a formula defined and smooth over the whole run")


def _check_reference(scenario: Scenario, controller: TrackingController, rows: np.ndarray) -> None:
    if not controller.needs_moving_reference:
        return
    speed = np.abs(rows[:, REF_V])
    if speed.min() < 1e-3 * max(1.0, speed.max()):
        scenario.reference.check_speed(0.0, rows[-1, 0], who=f"the {controller.name} controller")


def _initial_states(scenario: Scenario, robots, config_rows: np.ndarray) -> np.ndarray:
    v_d0 = float(config_rows[0, REF_V])
    return np.array([[*r.start, initial_state(r.controller, v_d0, r.name)] for r in robots], dtype=float).T.copy()


def _group_robots(scenario: Scenario, v_peak: float, omega_peak: float) -> dict:
    """Robots integrated together: same law and same sub-step plan, so that a robot's
    result does not depend on the batch it is simulated in."""
    groups = defaultdict(list)
    for index, robot in enumerate(scenario.robots):
        config = robot.controller
        # Laws that use ω_d must also resolve the reference's own turning.
        stiffness = max(config.stiffness(v_peak, omega_peak),
                        omega_peak if config.controller.needs_moving_reference else 0.0)
        groups[packed_law(config.law, config.controller.gain_tuple), _substep_plan(scenario, stiffness)].append(index)
    return groups


def simulate(scenario: Scenario, record: bool = True, progress: bool | None = None) -> SimulationResult:
    """Simulate every robot of ``scenario``; ``record`` keeps trajectories (else only the
    statistics, for large batches). ``progress``: show a progress bar (default: on a
    terminal, for long runs)."""
    started = time.perf_counter()
    n_steps, n_robots = scenario.n_steps, len(scenario.robots)
    grid = np.arange(n_steps + 1) * scenario.dt
    survey = scenario.reference.table(np.linspace(0.0, grid[-1], SURVEY_POINTS))
    v_peak = float(np.abs(survey[:, REF_V]).max())
    omega_peak = float(np.abs(survey[:, REF_OMEGA]).max())
    grid_rows = None
    stats = np.empty((STAT_COUNT, n_robots))
    record_array = np.empty((6, n_steps + 1 if record else 0, n_robots))
    substeps = np.empty(n_robots, dtype=np.int64)
    _check_finite(scenario, survey)
    rows_by_plan: dict[tuple, tuple] = {}
    for controller_name in dict.fromkeys(r.controller.name for r in scenario.robots):
        _check_reference(scenario, CONTROLLERS[controller_name], survey)
    for (law, plan_key), members in _group_robots(scenario, v_peak, omega_peak).items():
        robots = [scenario.robots[i] for i in members]
        plan = _plan_array(plan_key, n_steps)
        if plan_key not in rows_by_plan:
            times, row_start = stage_times(scenario.dt, plan)
            rows_by_plan[plan_key] = (scenario.reference.table(times), row_start)
            _check_finite(scenario, rows_by_plan[plan_key][0])
        rows, row_start = rows_by_plan[plan_key]
        if grid_rows is None:  # every plan has a row at each t_k
            stride = row_start[1] - row_start[0]
            uniform = row_start[-1] == stride * n_steps
            grid_rows = rows[::stride] if uniform else rows[row_start]
        gains = np.zeros((MAX_GAINS, len(robots)))
        for i, robot in enumerate(robots):
            vector = robot.controller.gain_vector()
            gains[:vector.size, i] = vector
        limits = np.array([[r.v_max, r.omega_max] for r in robots]).T.copy()
        state = _initial_states(scenario, robots, rows)
        group_stats = new_stats(len(robots))
        group_record = np.empty((6, record_array.shape[1], len(robots)))
        law_rates, integrate, score = integrator(law, record)
        if scenario.method == "rk4":
            _run_rk4(integrate, scenario, state, gains, limits, rows, row_start, plan, group_stats, group_record,
                     progress)
        else:
            _run_solve_ivp(law_rates, score, scenario, robots, state, gains, limits, grid_rows, group_stats,
                           group_record)
        _check_diverged(robots, group_stats)
        stats[:, members] = group_stats
        record_array[:, :, members] = group_record
        substeps[members] = plan.max()
    return SimulationResult(scenario=scenario, t=grid, reference_rows=grid_rows, stats=stats,
                            record=record_array if record else None, substeps=substeps,
                            elapsed_s=time.perf_counter() - started)


def _run_rk4(integrate, scenario, state, gains, limits, rows, row_start, plan, stats, record, progress):
    """Integrate all robots of a group; in time chunks with a progress bar on long runs."""
    n_steps, n_robots = scenario.n_steps, state.shape[1]
    held = np.zeros((6, n_robots))
    if progress is None:
        progress = float(plan.sum()) * n_robots > PROGRESS_WORK and sys.stderr.isatty()
    if not progress:
        integrate(state, gains, limits, rows, row_start, plan, scenario.dt, scenario.hold_every, 0, n_steps, n_steps,
                  stats, record, held)
        return
    from tqdm import tqdm

    chunks = np.linspace(0, n_steps, 51).astype(np.int64)
    with tqdm(total=n_steps, unit="step", desc=f"{scenario.name}: {n_robots} robots", file=sys.stderr) as bar:
        for k_start, k_stop in zip(chunks[:-1], chunks[1:]):
            integrate(state, gains, limits, rows, row_start, plan, scenario.dt, scenario.hold_every, int(k_start),
                      int(k_stop), n_steps, stats, record, held)
            bar.update(int(k_stop - k_start))


SOLVE_IVP_TOLERANCE = 1e-10
# Laws faster than this (1/s) are stiff against the references' time scales: use Radau.
STIFF_RATE = 50.0


def _check_diverged(robots, stats: np.ndarray) -> None:
    diverged = [r.name for r, ok in zip(robots, np.isfinite(stats[:STAT_COUNT - 1]).all(axis=0)) if not ok]
    if diverged:
        shown = ", ".join(repr(name) for name in diverged[:5]) + (" …" if len(diverged) > 5 else "")
        raise SimulationError(
            f"the simulation of robot(s) {shown} diverged (non-finite state): reduce dt, set more substeps or "
            "check the gains and actuator limits")


def _run_solve_ivp(law_rates, score, scenario, robots, state, gains, limits, grid_rows, stats, record):
    """scipy cross-check: DOP853 (Radau for stiff laws), rtol = atol = 1e-10, dense output
    sampled on the same grid and scored by the same compiled code."""
    n = state.shape[1]
    rates = np.empty((4, n))
    reference = scenario.reference

    def rhs(t, y):
        law_rates(y.reshape(4, n), reference.table(np.array([t])), gains, limits, rates)
        return rates.ravel().copy()

    v_peak, omega_peak = np.abs(grid_rows[:, REF_V]).max(), np.abs(grid_rows[:, REF_OMEGA]).max()
    stiffness = max(r.controller.stiffness(v_peak, omega_peak) for r in robots)
    method = "Radau" if stiffness > STIFF_RATE else "DOP853"
    solution = solve_ivp(rhs, (0.0, grid_rows[-1, 0]), state.ravel(), method=method, t_eval=grid_rows[:, 0],
                         rtol=SOLVE_IVP_TOLERANCE, atol=SOLVE_IVP_TOLERANCE)
    if not solution.success:
        raise RuntimeError(f"solve_ivp failed: {solution.message}")
    states = np.ascontiguousarray(solution.y.T.reshape(-1, 4, n))
    score(states, np.ascontiguousarray(grid_rows), gains, limits, stats, record)
