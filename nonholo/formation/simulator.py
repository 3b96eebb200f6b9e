"""The formation simulator: packs one formation, or a batch of formations that share a
structure (graph, laws, targets, reference, grid) but differ in gains, offsets, goals and
starts, into the arrays of ``nonholo.formation.kernel`` and integrates them with the
compiled RK4 (or scipy ``solve_ivp`` for cross-checks).

Sub-steps (RK4 steps per output step): given, or planned automatically so that
h·rate ≤ ``RATE_STEP`` for the fastest rate met during each output step (|ω| of every
robot, |ξ̇/ξ| of dynamic-feedback leaders, the follower gains, the leader's stiffness).
The rates are measured by running the formation: a pilot run on a plan from the gains,
then re-runs on the plan the previous run asked for until a run's own rates are within
its plan (spec §8 sub-steps when (|ω|, |r|/|ξ|)·dt > 0.05).
"""
from __future__ import annotations

import math
import time
from functools import cache

import numpy as np
from scipy.integrate import solve_ivp

from nonholo.control.registry import initial_state
from nonholo.errors import NonholoInputError, SimulationError
from nonholo.formation import kernel as fk
from nonholo.formation.geometry import separation_bearing, wrap
from nonholo.formation.model import SEPARATION_BEARING, Follower, Formation, Leader
from nonholo.formation.result import FormationResult
from nonholo.formation.schedule import target_table
from nonholo.references.feedforward import REF_OMEGA, REF_V
from nonholo.sim.kernel import packed_law
from nonholo.sim.simulator import MAX_SUBSTEPS, SOLVE_IVP_TOLERANCE, SURVEY_POINTS, stage_times

RATE_STEP = 0.05
PLAN_ITERATIONS = 6


@cache
def formation_integrator(law):
    return fk.make_formation_integrator(law)


class Packed:
    """The kernel's arrays for a batch of formations of one structure."""

    def __init__(self, formations: list[Formation]):
        first = formations[0]
        for other in formations[1:]:
            if other.structure() != first.structure():
                raise NonholoInputError(f"formation {other.name!r} differs in structure from {first.name!r}: a batch "
                                        "shares robots, links, targets, reference and time grid")
        self.formations = formations
        robots = first.robots
        n_robots, n_batch = len(robots), len(formations)
        names = first.names
        self.order = np.array(first.order(), dtype=np.int64)
        self.kinds = np.array([fk.LEADER if isinstance(r, Leader) else
                               (fk.SEPARATION_BEARING if r.law == SEPARATION_BEARING else fk.SEPARATION_SEPARATION)
                               for r in robots], dtype=np.int64)
        self.parents = np.full((2, n_robots), -1, dtype=np.int64)
        for i, robot in enumerate(robots):
            if isinstance(robot, Follower):
                for j, parent in enumerate(robot.leaders):
                    self.parents[j, i] = names.index(parent)
        leader = first.leaders[0]
        self.law = packed_law(leader.controller.law, leader.controller.controller.gain_tuple)
        self.posture = leader.posture
        self.xi_speed = 1.0 if leader.controller.controller.xi_is_speed else 0.0
        self.leader_gains = np.zeros((fk.LEADER_GAINS, n_robots, n_batch))
        self.params = np.zeros((3, n_robots, n_batch))
        self.limits = np.empty((2, n_robots, n_batch))
        self.state = np.zeros((4, n_robots, n_batch))
        for b, formation in enumerate(formations):
            poses = formation.initial_poses()
            for i, robot in enumerate(formation.robots):
                self.state[:3, i, b] = poses[i]
                self.limits[:, i, b] = robot.v_max, robot.omega_max
                if isinstance(robot, Leader):
                    vector = robot.controller.gain_vector()
                    if robot.posture:
                        vector = np.concatenate([robot.goal, vector])
                    self.leader_gains[:vector.size, i, b] = vector
                else:
                    self.params[:, i, b] = robot.k1, robot.k2, robot.d

    def stiffness(self) -> float:
        """Fastest rate known before running: follower gains and the leaders' stiffness."""
        first = self.formations[0]
        rate = max([max(r.k1, r.k2) for f in self.formations for r in f.followers] or [0.0])
        if first.reference is not None:
            survey = first.reference.table(np.linspace(0.0, first.duration, SURVEY_POINTS))
            v_peak, omega_peak = float(np.abs(survey[:, REF_V]).max()), float(np.abs(survey[:, REF_OMEGA]).max())
        else:
            v_peak = omega_peak = 0.0
        for f in self.formations:
            for leader in f.leaders:
                rate = max(rate, leader.controller.stiffness(v_peak, omega_peak), omega_peak)
        return rate

    def reference_rows(self, times: np.ndarray) -> np.ndarray:
        first = self.formations[0]
        if self.posture:
            rows = np.zeros((times.size, 10))
            rows[:, 0] = times
            return rows
        return first.reference.table(times)

    def target_rows(self, times: np.ndarray) -> np.ndarray:
        targets = np.zeros((times.size, 4, len(self.formations[0].robots)))
        for i, robot in enumerate(self.formations[0].robots):
            if isinstance(robot, Follower):
                targets[:, :, i] = target_table(robot, times)
        return targets

    def initial_compensators(self, first_row: np.ndarray) -> None:
        for b, formation in enumerate(self.formations):
            for i, robot in enumerate(formation.robots):
                if not isinstance(robot, Leader):
                    continue
                self.state[3, i, b] = initial_state(robot.controller, float(first_row[REF_V]), robot.name)

    def initial_branches(self, first_targets: np.ndarray) -> np.ndarray:
        """Each l–φ bearing at t = 0 on the 2π branch nearest its target φ_d(0)."""
        branch = np.zeros(self.state.shape[1:])
        for i in np.flatnonzero(self.kinds == fk.SEPARATION_BEARING):
            p = self.parents[0, i]
            _, raw, _ = separation_bearing(self.state[:3, p], self.state[:3, i], self.params[2, i])
            target = first_targets[1, i]
            branch[i] = target + wrap(raw - target)
        return branch


def needed_substeps(step_rate: np.ndarray, floor_rate: float, dt: float) -> np.ndarray:
    """Sub-steps per output step so that h·rate ≤ RATE_STEP, with each step also covering
    the rates of its neighbours (a transient may start just after a sample)."""
    rate = np.where(np.isfinite(step_rate), step_rate, np.inf)
    widened = rate[:-1].copy()
    widened[1:] = np.maximum(widened[1:], rate[:-2])
    widened = np.maximum(widened, rate[1:])
    needed = np.ceil(np.maximum(widened, floor_rate) * dt / RATE_STEP)
    return np.clip(np.where(np.isfinite(needed), needed, MAX_SUBSTEPS), 1, MAX_SUBSTEPS).astype(np.int64)


def simulate_formation(formation: Formation | list[Formation]) -> FormationResult:
    """Simulate one formation or a batch of formations of one structure (a list)."""
    started = time.perf_counter()
    formations = list(formation) if isinstance(formation, (list, tuple)) else [formation]
    packed = Packed(formations)
    first = formations[0]
    n_steps, dt = first.n_steps, first.dt
    grid = np.arange(n_steps + 1) * dt
    integrate, rates, sample = formation_integrator(packed.law)
    packed.initial_compensators(packed.reference_rows(grid[:1])[0])
    branch0 = packed.initial_branches(packed.target_rows(grid[:1])[0])
    record_shape = (fk.RECORD_FIELDS, n_steps + 1, *packed.state.shape[1:])
    if first.method == "solve_ivp":
        record = _solve_ivp(packed, rates, sample, grid, branch0.copy(), record_shape)
        plan = np.ones(n_steps, dtype=np.int64)
    else:
        record, plan = _rk4(packed, integrate, first, grid, branch0, record_shape)
    states = record[fk.REC_X:fk.REC_OMEGA + 1]
    finite = np.isfinite(states).all(axis=(0, 1, 3))
    if not finite.all():
        names = [robot.name for robot, ok in zip(first.robots, finite) if not ok]
        raise SimulationError(f"the simulation of robot(s) {', '.join(map(repr, names))} diverged (non-finite "
                              "state): lower the gains or the step (dt), or check the formation's geometry")
    return FormationResult(formations=formations, t=grid, record=record,
                           reference_rows=None if packed.posture else packed.reference_rows(grid),
                           substeps=plan, elapsed_s=time.perf_counter() - started)


def _rk4(packed: Packed, integrate, first: Formation, grid, branch0, record_shape):
    n_steps, dt = first.n_steps, first.dt
    floor_rate = packed.stiffness()
    if first.substeps is not None:
        plan = np.full(n_steps, first.substeps, dtype=np.int64)
        iterations = 1
    else:
        plan = np.clip(np.full(n_steps, math.ceil(floor_rate * dt / RATE_STEP)), 1, MAX_SUBSTEPS).astype(np.int64)
        iterations = PLAN_ITERATIONS
    for iteration in range(iterations):
        times, row_start = stage_times(dt, plan)
        rows, targets = packed.reference_rows(times), packed.target_rows(times)
        state, branch = packed.state.copy(), branch0.copy()
        record = np.empty(record_shape)
        step_rate = np.zeros(n_steps + 1)
        integrate(state, branch, rows, targets, row_start, plan, dt, packed.order, packed.kinds, packed.parents,
                  packed.leader_gains, packed.params, packed.limits, first.sin_floor, packed.xi_speed, record,
                  step_rate, 0, n_steps, n_steps)
        if first.substeps is not None:
            break
        needed = needed_substeps(step_rate, floor_rate, dt)
        if np.all(needed <= plan):
            break
        plan = needed if iteration < iterations - 2 else np.maximum(plan, needed)
    return record, plan


def _solve_ivp(packed: Packed, rates, sample, grid, branch, record_shape):
    """scipy cross-check: DOP853 at rtol = atol = 1e-10, sampled on the grid and recorded
    by the same compiled evaluation as the RK4 path."""
    shape = packed.state.shape
    slope = np.zeros(shape)
    live_branch = branch.copy()
    bearing_robots = np.flatnonzero(packed.kinds == fk.SEPARATION_BEARING)

    def rhs(t, y):
        state = y.reshape(shape)
        for i in bearing_robots:
            p = packed.parents[0, i]
            _, raw, _ = separation_bearing(state[:3, p], state[:3, i], packed.params[2, i])
            live_branch[i] += wrap(raw - live_branch[i])
        times = np.array([t])
        rates(state, live_branch, packed.reference_rows(times), packed.target_rows(times), packed.order,
              packed.kinds, packed.parents, packed.leader_gains, packed.params, packed.limits,
              packed.formations[0].sin_floor, packed.xi_speed, slope)
        return slope.ravel().copy()

    solution = solve_ivp(rhs, (0.0, grid[-1]), packed.state.ravel(), method="DOP853", t_eval=grid,
                         rtol=SOLVE_IVP_TOLERANCE, atol=SOLVE_IVP_TOLERANCE)
    if not solution.success:
        raise RuntimeError(f"solve_ivp failed: {solution.message}")
    states = np.ascontiguousarray(solution.y.T.reshape(-1, *shape))
    record = np.empty(record_shape)
    sample(states, branch, packed.reference_rows(grid), packed.target_rows(grid), packed.order, packed.kinds,
           packed.parents, packed.leader_gains, packed.params, packed.limits, packed.formations[0].sin_floor,
           packed.xi_speed, record)
    return record
