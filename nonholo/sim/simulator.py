"""The one simulator: packs a scenario (or a batch of scenarios of one structure) into the
arrays of ``nonholo.sim.kernel`` and integrates them with the compiled RK4, or with scipy
``solve_ivp`` for cross-checks.

**Groups.** A scenario's robots split into connected formations (a lone robot is one). The
formations that share a structure (graph, laws, targets) and a sub-step plan planned in
advance from their own gains (members of a batch that differ in gains may not) are integrated
together as one batch, copies along the kernel's batch axis: 10 000 lone robots under one
law are one group of 10 000 copies of a one-robot graph. So a robot's result depends on the
other formations it is simulated with only through the sub-steps planned from the rates the
group meets (below): where one copy needs more, all get them, never fewer than their own —
except in groups of lone tracking roots, where only the copies whose own rates asked for more
run again (their statistic ``STEP_RATE``): the others equal their runs alone bit for bit.

**The sub-step rule.** RK4 sub-steps per output step are given (``substeps``) or planned so
that h·λ ≤ ``STABLE_STEP_FACTOR`` for every rate λ known in advance — each root law's
declared stiffness at the reference's peak speed and turn rate, the reference's own turn
rate, the followers' gains — with the first ``STARTUP_TIME_CONSTANTS``/λ seconds of a stiff
law refined ``STARTUP_REFINEMENT``-fold (its start-up transient), and so that h·ω ≤
``MEASURED_STEP_FACTOR`` for the rates measured while running where they cannot be known in
advance — a formation's and a posture law's turn rates (|ω|, and |ξ̇/ξ| of speed
compensators) — and h·ω ≤ ``STABLE_STEP_FACTOR`` for a tracking law's (at the first stage of
each sub-step: a far start, or ξ of dynamic feedback near 0, turns far faster than the
reference; one RK4 step per dt at h·ω = 2.5 drove ξ through 0 and the robot on backward).
A tracking group runs its horizon at once and again, with more sub-steps where its rates
asked for them, only if they did, and only the copies whose own rates did. Formations' and
posture laws' rates are met while running: the horizon is integrated in ``PLAN_WINDOWS``
windows of output steps (``plan_windows``), and a window whose own rates ask for more
sub-steps than it ran is run again from its start (state, bearings, statistics and held
commands put back) with more — at most ``PLAN_GROWTH`` times as many per step at each attempt,
since an under-resolved run's rates overshoot — until its rates are within its plan or after
``PLAN_ATTEMPTS`` runs (the last stands: a singular passage asks for more than
``kernel.MAX_SUBSTEPS``). Only the windows that need it are run again: the 7-follower chain's
start-up (3 400 rad/s in its first second) no longer re-runs the whole horizon. Each step's
sub-steps also cover the rates of the steps beside it (``measured_plan``), except the last
step of a window, which covers its own and its predecessor's: the next window's rates are
not known when it is accepted.
"""
from __future__ import annotations

import math
import sys
import time
from collections import namedtuple
from collections.abc import Sequence
from functools import cache
from itertools import chain

import numpy as np

from nonholo.control.registry import initial_state
from nonholo.errors import InfeasibleReferenceError, NonholoInputError, SimulationError
from nonholo.models.formation_geometry import separation_bearing, wrap
from nonholo.references.feedforward import REF_OMEGA, REF_V
from nonholo.sim import kernel as kn
from nonholo.sim.linkstep import integrate_linked, linked
from nonholo.sim.result import SimulationResult
from nonholo.sim.scenario import SEPARATION_BEARING, Follower, Robot, Scenario
from nonholo.sim.targets import TABLE_COLUMNS, target_table

STABLE_STEP_FACTOR = 0.5
MEASURED_STEP_FACTOR = 0.05
STARTUP_TIME_CONSTANTS = 50.0
STARTUP_REFINEMENT = 10
# A copy whose ``STEP_RATE`` is within this relative margin below its factor counts as short:
# the kernel's rate × (dt/m) and ``measured_plan``'s ⌈rate·dt/factor⌉ round apart at ties.
OWN_RATE_MARGIN = 1e-9
# Runs of a window at most (the last stands), and the most its sub-steps grow from one run to
# the next: an under-resolved run's rates overshoot (see plan_windows).
PLAN_ATTEMPTS = 8
PLAN_GROWTH = 4
PLAN_WINDOWS = 50
# RK4 is stable for a linear mode of rate λ while h·λ < 2.785 (real axis).
RK4_STABILITY_LIMIT = 2.78
# The reference is surveyed at this many points to size the sub-steps.
SURVEY_POINTS = 2001
# Above this many robot-sub-steps a run is split into chunks with a progress bar.
PROGRESS_WORK = 2e8
# Refuse runs whose arrays would exceed this many bytes (estimated before allocating).
MAX_BYTES = 8 * 2**30
SOLVE_IVP_TOLERANCE = 1e-10
# Laws faster than this (1/s) are stiff against the references' time scales: use Radau.
STIFF_RATE = 50.0


@cache
def kernel_for(laws: tuple, followers: bool) -> kn.Kernel:
    """The compiled functions of a group whose roots run ``laws``: one or two (law function,
    field namedtuple class) pairs."""
    (law_a, fields_a), (law_b, fields_b) = laws if len(laws) == 2 else (laws[0], (kn.idle_law, kn.IdleFields))
    return kn.make_kernel(law_a, fields_a, law_b, fields_b, followers)


def plan_rows(plan: np.ndarray) -> np.ndarray:
    """The first stage row of each output step of ``plan`` (and the row of the last sample)."""
    row_start = np.zeros(plan.size + 1, dtype=np.int64)
    np.cumsum(2 * plan, out=row_start[1:])
    return row_start


def stage_times(dt: float, plan: np.ndarray, k0: int = 0, k1: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Times of the RK4 stage rows of output steps [k0, k1) (default: all) and of the sample
    at k1, and the first row of each output step (``plan_rows``). Each time is k·dt + j·h/2,
    the j-th half sub-step of output step k, whatever the plan: a row's time does not depend on
    the rest of the plan (a window planned again keeps the rows before it), and the output
    instants are k·dt exactly."""
    k1 = plan.size if k1 is None else k1
    row_start = plan_rows(plan)
    times = np.empty(row_start[k1] - row_start[k0] + 1)
    kn.fill_stage_times(float(dt), plan, k0, k1, times)
    return times, row_start


def prior_plan(scenario: Scenario, rate: float) -> np.ndarray:
    """Sub-steps per output step from the rates known in advance (see the module docstring)."""
    base, refined = prior_parts(scenario, rate)
    plan = np.full(scenario.n_steps, base, dtype=np.int64)
    plan[:refined] = base * STARTUP_REFINEMENT
    return plan


def prior_parts(scenario: Scenario, rate: float) -> tuple[int, int]:
    """``prior_plan`` as (sub-steps per output step, the first output steps that get
    ``STARTUP_REFINEMENT`` times as many): equal parts, equal plans."""
    n_steps, dt = scenario.n_steps, scenario.dt
    if scenario.method != "rk4":
        return 1, 0
    if scenario.substeps is not None:
        step = dt / scenario.substeps
        if rate * step > RK4_STABILITY_LIMIT:
            raise NonholoInputError(
                f"substeps = {scenario.substeps} is unstable for this law: its fastest rate {rate:.3g} 1/s times "
                f"the step {step:.3g} s exceeds RK4's stability limit {RK4_STABILITY_LIMIT}; use more substeps or "
                "leave them automatic")
        return scenario.substeps, 0
    needed = rate * dt / STABLE_STEP_FACTOR
    if not needed <= kn.MAX_SUBSTEPS:  # also catches inf and nan
        raise NonholoInputError(
            f"the control law is too stiff for dt = {dt:g} s (fastest rate {rate:.3g} 1/s would need "
            f"{needed:.3g} sub-steps per step, at most {kn.MAX_SUBSTEPS}): reduce dt or lower the gains")
    base = max(1, math.ceil(needed))
    return base, (min(math.ceil(STARTUP_TIME_CONSTANTS / rate / dt), n_steps) if base > 1 else 0)


def measured_plan(step_rate: np.ndarray, prior: np.ndarray, dt: float, k0: int = 0, k1: int | None = None,
                  factor: float = MEASURED_STEP_FACTOR) -> np.ndarray:
    """Sub-steps of output steps [k0, k1) (default: all) so that h·rate ≤ ``factor`` for the
    rates met in each output step, each step also covering its neighbours' (a transient may
    start just after a sample)."""
    k1 = prior.size if k1 is None else k1
    low = max(k0 - 1, 0)
    rate = step_rate[low:k1 + 1]
    rate = np.where(np.isfinite(rate), rate, np.inf)
    widened = np.maximum(rate[k0 - low:k1 - low], rate[k0 - low + 1:k1 - low + 1])
    if k0 > 0:
        widened = np.maximum(widened, rate[:k1 - k0])
    else:
        widened[1:] = np.maximum(widened[1:], rate[:k1 - k0 - 1])
    needed = np.ceil(widened * dt / factor)
    needed = np.clip(np.where(np.isfinite(needed), needed, kn.MAX_SUBSTEPS), 1, kn.MAX_SUBSTEPS).astype(np.int64)
    return np.maximum(needed, prior[k0:k1])


class Group:
    """The kernel's arrays for the copies of one formation structure: copy b is robots
    ``index[b]`` (parents-first) of member ``members[b]``."""

    def __init__(self, scenarios: list[Scenario], members: np.ndarray, index: np.ndarray, laws: tuple,
                 prior: np.ndarray, v_d0: float, poses: list):
        self.scenarios, self.members, self.index, self.prior = scenarios, members, index, prior
        scenario = scenarios[members[0]]
        robots = [scenario.robots[i] for i in index[0]]
        local = {robot.name: j for j, robot in enumerate(robots)}
        n_robots, n_batch = len(robots), len(members)
        self.followers = any(isinstance(r, Follower) for r in robots)
        # Plans from measured rates where they are not known in advance (see the docstring):
        # formations' and posture laws' to MEASURED_STEP_FACTOR, tracking laws' (under
        # continuous-time control) to STABLE_STEP_FACTOR, as their rates known in advance.
        self.measured = self.followers or any(isinstance(r, Robot) and r.posture for r in robots)
        self.rate_factor = MEASURED_STEP_FACTOR if self.measured else STABLE_STEP_FACTOR
        self.laws = laws
        law_functions = [law for law, _ in laws]
        self.kinds = np.array([kn.ROOT_A + law_functions.index(r.controller.law) if isinstance(r, Robot) else
                               (kn.SEPARATION_BEARING if r.law == SEPARATION_BEARING else kn.SEPARATION_SEPARATION)
                               for r in robots], dtype=np.int64)
        self.order = np.arange(n_robots, dtype=np.int64)   # copies list robots parents-first
        self.parents = np.full((2, n_robots), -1, dtype=np.int64)
        for j, robot in enumerate(robots):
            for slot, parent in enumerate(robot.parents):
                self.parents[slot, j] = local[parent]
        self.feeds = np.zeros(n_robots, dtype=np.int64)
        self.feeds[self.parents[self.parents >= 0]] = 1
        self.fields = np.zeros((kn.MAX_FIELDS, n_robots, n_batch))
        self.limits = np.empty((2, n_robots, n_batch))
        self.state = np.zeros((4, n_robots, n_batch))
        self.offsets = np.zeros((2, n_robots, n_batch))
        self.d_max = np.zeros(n_batch)
        self.xi_speed = 0.0
        # A batch of 10^4 lone roots is set up in a few ms: each robot's attributes are read in
        # one pass each (``np.fromiter``), and its configuration by the object's identity, once
        # per distinct object (a batch shares a few), then indexed per copy.
        member_list = members.tolist()
        as_given = n_robots == 1 and n_batch == len(scenario.robots) and (members == members[0]).all() and \
            (index[:, 0] == np.arange(n_batch)).all()   # (a scenario of lone roots: its robots as they are)
        for j, robot in enumerate(robots):   # one position of the graph in every copy at once
            if as_given:
                column, starts = scenario.robots, chain.from_iterable(poses[member_list[0]])
            else:
                at = index[:, j].tolist()
                column = [scenarios[m].robots[i] for m, i in zip(member_list, at)]
                starts = chain.from_iterable(poses[m][i] for m, i in zip(member_list, at))
            self.state[:3, j] = np.fromiter(starts, float, 3 * n_batch).reshape(n_batch, 3).T
            self.limits[0, j] = np.fromiter((r.v_max for r in column), float, n_batch)
            self.limits[1, j] = np.fromiter((r.omega_max for r in column), float, n_batch)
            if isinstance(robot, Robot):
                configs = [r.controller for r in column]
                first, rows = first_seen(np.fromiter(map(id, configs), np.int64, n_batch))
                gain_rows, xi_starts = [], []
                for b in first.tolist():
                    config = configs[b]
                    gain_rows.append(config.gain_vector())
                    xi_starts.append(initial_state(config, v_d0, column[b].name))
                    self.xi_speed = 1.0 if config.controller.xi_is_speed or self.xi_speed else 0.0
                block = np.array(gain_rows, dtype=float)[rows]
                if robot.posture:   # a posture law's goal comes first
                    block = np.hstack([np.array([r.goal for r in column], dtype=float), block])
                self.fields[:block.shape[1], j] = block.T
                self.state[3, j] = np.array(xi_starts, dtype=float)[rows]
            else:
                self.fields[[kn.K1, kn.K2, kn.OFFSET_D], j] = np.array([(r.k1, r.k2, r.d) for r in column]).T
                self.offsets[:, j] = np.array([r.targets for r in column]).T - np.array(robot.targets)[:, None]
                self.d_max = np.maximum(self.d_max, self.fields[kn.OFFSET_D, j])
        self.robots = robots

    @property
    def copies(self) -> list[tuple[int, tuple[int, ...]]]:
        """(member, robot indices parents-first) of each copy (a new list: ``members`` and
        ``index`` are the arrays)."""
        return list(zip(self.members.tolist(), map(tuple, self.index.tolist())))

    def targets(self, times: np.ndarray) -> np.ndarray:
        """Follower targets at ``times`` (one row if none of them changes)."""
        if not any(isinstance(r, Follower) and r.changes for r in self.robots):
            times = times[:1]
        table = np.zeros((times.size, len(TABLE_COLUMNS), len(self.robots)))
        for j, robot in enumerate(self.robots):
            if isinstance(robot, Follower):
                table[:, :, j] = target_table(robot, times)
        return table

    def initial_branches(self) -> np.ndarray:
        """Each l–φ bearing at t = 0 on the 2π branch nearest its target φ_d(0)."""
        branch = np.zeros(self.state.shape[1:])
        first_targets = self.targets(np.zeros(1))[0]
        for j in np.flatnonzero(self.kinds == kn.SEPARATION_BEARING):
            p = self.parents[0, j]
            _, raw, _ = separation_bearing(self.state[:3, p], self.state[:3, j], self.fields[kn.OFFSET_D, j])
            target = first_targets[1, j] + self.offsets[1, j]
            branch[j] = target + wrap(raw - target)
        return branch


def _structure(robot, index: dict) -> tuple:
    """What copies integrated together must share, for one robot (parents as positions)."""
    if isinstance(robot, Robot):
        return ("root", robot.controller.law, robot.posture,
                robot.posture and robot.controller.controller.goal_relative)
    return (robot.law, tuple(index[p] for p in robot.leaders), repr(robot.changes), robot.targets if robot.changes else None)


def _check_batch(scenarios: list[Scenario]) -> None:
    first = scenarios[0]
    described: dict[int, str] = {}   # members usually share one reference object: describe it once

    def reference(s):
        if s.reference is None:
            return None
        if id(s.reference) not in described:
            described[id(s.reference)] = repr(s.reference.describe())
        return described[id(s.reference)]

    def key(s):
        index = {n: i for i, n in enumerate(s.names)}
        return (s.names, tuple(type(r).__name__ for r in s.robots), tuple(r.parents for r in s.robots),
                tuple(_structure(r, index) for r in s.robots), reference(s), s.duration, s.dt, s.method,
                s.control_period, s.substeps)

    if len(scenarios) == 1:
        return
    first_key = key(first)
    for other in scenarios[1:]:
        if key(other) != first_key:
            raise NonholoInputError(f"scenario {other.name!r} differs in structure from {first.name!r}: a batch "
                                    "shares robots, links, laws, changes, reference and time grid")


def check_network(scenarios: list[Scenario]) -> None:
    """A link model needs sampled-data control (states are passed at control instants)."""
    if scenarios[0].hold_every == 0 and any(s.network is not None and not s.network.ideal for s in scenarios):
        raise NonholoInputError("the link model ([network] delay, jitter, loss) needs sampled-data control: set "
                                "[simulation] control_period (a multiple of dt), or remove the delay, jitter and loss")


def _reference_survey(scenario: Scenario):
    """Peak |v_d|, |ω_d| of the reference, and its rows checked finite (None without one)."""
    if scenario.reference is None:
        return 0.0, 0.0
    configs = {id(r.controller): r.controller for r in scenario.roots}.values()   # (a batch shares a few)
    configs = [config for config in configs if config.controller.kind != "posture"]
    for config in configs:   # (refused before any table is computed)
        follows = config.direction_of()
        if follows and follows != scenario.reference.direction:
            way = "forward" if follows > 0 else "backward"
            gains = "" if not callable(config.controller.direction) else \
                " with " + ", ".join(f"{name} = {value:g}" for name, value in config.gains.items())
            raise InfeasibleReferenceError(
                f"the {config.name} controller{gains} follows {way} motion only ({config.controller.source}), and "
                f"this reference is driven {'backward' if follows > 0 else 'forward'}: see "
                f"docs/controllers/{config.name}.md")
    survey = scenario.reference.table(np.linspace(0.0, scenario.duration, SURVEY_POINTS))
    _check_finite(scenario, survey)
    for spec in {config.name: config.controller for config in configs}.values():
        if spec.needs_moving_reference:
            speed = np.abs(survey[:, REF_V])
            if speed.min() < 1e-3 * max(1.0, speed.max()):
                scenario.reference.check_speed(0.0, scenario.duration, who=f"the {spec.name} controller")
    return float(np.abs(survey[:, REF_V]).max()), float(np.abs(survey[:, REF_OMEGA]).max())


def _check_finite(scenario: Scenario, rows: np.ndarray) -> None:
    with np.errstate(invalid="ignore", over="ignore"):   # (inf − inf in the sum is what is looked for)
        if np.isfinite(rows.sum()):   # no inf or NaN in the sum: none in the rows (an overflow is checked below)
            return
    bad = ~np.isfinite(rows).all(axis=1)
    if bad.any():
        raise InfeasibleReferenceError(
            f"the {scenario.reference.kind} reference is not finite at t = {rows[np.argmax(bad), 0]:.6g} s "
            "(position or its first two derivatives): use a formula defined and smooth over the whole run")


def _prior_rate(robots, v_peak: float, omega_peak: float, known: dict) -> float:
    """The fastest rate known in advance: root laws' stiffness (and the reference's turn
    rate, for laws that track it), followers' gains. ``known`` caches it per configuration."""
    rate = 0.0
    for robot in robots:
        if isinstance(robot, Robot):
            config = robot.controller
            if id(config) not in known:
                known[id(config)] = max(config.stiffness(v_peak, omega_peak),
                                        omega_peak if config.controller.needs_moving_reference else 0.0)
            rate = max(rate, known[id(config)])
        else:
            rate = max(rate, robot.k1, robot.k2)
    return rate


SMALL_SET = 32   # ``first_seen`` numbers fewer values than this in Python


def first_seen(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct values of ``values`` in order of first appearance: the index of each one's
    first appearance, and the number of each element's value in that order."""
    if values.size < SMALL_SET:   # (numpy's calls would cost more than the loop)
        numbered: dict = {}
        first, at = [], []
        for i, value in enumerate(values.tolist()):
            if value not in numbered:
                numbered[value] = len(first)
                first.append(i)
            at.append(numbered[value])
        return np.array(first, dtype=np.intp), np.array(at, dtype=np.intp)
    _, first, inverse = np.unique(values, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return first[order], rank[inverse.ravel()]


def _groups(scenarios: list[Scenario], v_peak: float, omega_peak: float, v_d0: float) -> list[Group]:
    """The batch's copies (each component of each member) grouped by what must be integrated
    together: root laws, structure and the sub-step plan of their own rates known in advance.
    Groups and their copies come in the order of a member-by-member, component-by-component
    walk. Lone roots, the many robots of large batches, are keyed by their configuration
    object (a batch shares a few), all members at once, with arrays."""
    first = scenarios[0]
    poses = [s.initial_poses() for s in scenarios]
    known: dict = {}
    plans: dict[tuple, np.ndarray] = {}
    by_rate: dict[float, np.ndarray] = {}

    def shape(robots):
        """A component's root laws and structure (the same in every member: ``_check_batch``)."""
        laws = tuple(dict.fromkeys((r.controller.law, r.controller.controller.gain_tuple)
                                   for r in robots if isinstance(r, Robot)))
        if len(laws) > 2:
            raise NonholoInputError(f"robots {', '.join(r.name for r in robots if isinstance(r, Robot))} form one "
                                    "connected formation with more than two different root controllers (at most two)")
        local = {robot.name: j for j, robot in enumerate(robots)}   # (``Scenario.names`` is built per call)
        return laws, tuple(_structure(r, local) for r in robots)

    def plan_of(rate):
        if rate not in by_rate:   # (copies of one configuration share a rate)
            parts = prior_parts(first, rate)
            if parts not in plans:   # one plan object per distinct plan: copies of equal plans share a group
                plans[parts] = prior_plan(first, rate)
            by_rate[rate] = plans[parts]
        return by_rate[rate]

    keys: dict[tuple, int] = {}   # each group's key (laws, structure, id of its plan), numbered
    prior_of: dict[int, np.ndarray] = {}

    def number(laws_structure, robots) -> int:
        """The number of the group of a copy of shape ``laws_structure`` made of ``robots``."""
        prior = plan_of(_prior_rate(robots, v_peak, omega_peak, known))
        prior_of[id(prior)] = prior
        return keys.setdefault((*laws_structure, id(prior)), len(keys))

    components = first.components()
    if len(components) == len(first.robots):   # lone roots only (no links): component k is robot k
        lone, formations, lone_robots = range(len(components)), [], range(len(components))
    else:
        lone = [k for k, c in enumerate(components) if len(c) == 1 and isinstance(first.robots[c[0]], Robot)]
        formations = sorted(set(range(len(components))).difference(lone))
        lone_robots = [components[k][0] for k in lone]
    # A lone root's configuration object decides its shape (law, gains' names, goal kind: a
    # tracking law takes no goal, a posture law needs one), and a batch's roots share a few
    # objects: shapes are worked out once per object of the first member, by its positions.
    n_members, n_lone = len(scenarios), len(lone)
    configs = np.fromiter((id(s.robots[i].controller) for s in scenarios for i in lone_robots), np.int64,
                          n_members * n_lone)   # member by member
    config_first, config_at = first_seen(configs[:n_lone])   # (the first member's)
    shapes: dict[tuple, tuple] = {}
    config_shapes = []
    for b in config_first.tolist():
        robot = first.robots[lone_robots[b]]
        key = (robot.controller.controller.gain_tuple, _structure(robot, {}))
        if key not in shapes:
            shapes[key] = shape([robot])
        config_shapes.append(shapes[key])
    formation_shapes = [shape([first.robots[i] for i in components[k]]) for k in formations]
    # Each copy (a component of a member) gets the plan of its own rates known in advance, as
    # it would alone: members that differ in gains are grouped by their plans. Lone roots get
    # one number per distinct configuration object over all members; the numbers are handed
    # out in the walk's order (so that the first copy found too stiff is the walk's).
    pair_first, pair_at = first_seen(configs)
    width = len(components)   # (a copy's place in the walk: member · width + component)
    lone_todo = [(member * width + lone[b], config_shapes[config_at[b]], [scenarios[member].robots[lone_robots[b]]])
                 for member, b in zip(*(part.tolist() for part in np.divmod(pair_first, max(n_lone, 1))))]
    formation_todo = [(member * width + k, laws_structure, [scenario.robots[i] for i in components[k]])
                      for member, scenario in enumerate(scenarios)
                      for k, laws_structure in zip(formations, formation_shapes)]
    numbered = {at: number(laws_structure, robots)
                for at, laws_structure, robots in sorted(lone_todo + formation_todo, key=lambda item: item[0])}
    codes = np.empty((n_members, width), dtype=np.int64)
    lone_numbers = np.array([numbered[at] for at, _, _ in lone_todo], dtype=np.int64)
    codes[:, lone] = lone_numbers[pair_at].reshape(n_members, n_lone)
    for at, _, _ in formation_todo:
        codes.flat[at] = numbered[at]
    flat = codes.ravel()   # member by member, component by component
    walk = np.argsort(flat, kind="stable")   # each group's copies together, in walk order
    walked = flat[walk]
    bounds = [0, *(np.flatnonzero(walked[1:] != walked[:-1]) + 1).tolist(), flat.size]
    spans = sorted(zip(bounds[:-1], bounds[1:]), key=lambda span: walk[span[0]])
    key_of = {n: key for key, n in keys.items()}
    first_robots = np.arange(len(components)) if not formations else np.array([c[0] for c in components])
    groups = []
    for start, end in spans:   # (groups in the order of their first copies)
        copies = walk[start:end]
        members, at = np.divmod(copies, len(components))
        if len(components[at[0]]) == 1:
            index = first_robots[at][:, None]
        else:
            index = np.array([components[k] for k in at.tolist()], dtype=np.intp)
        key = key_of[int(flat[copies[0]])]
        groups.append(Group(scenarios, members, index, key[0], prior_of[key[-1]], v_d0, poses))
    return groups


ON_DIVERGENCE = ("raise", "report")

GroupRun = namedtuple("GroupRun", ("stats", "pair_stats", "records", "plan", "most", "rk4_steps"))
GroupRun.__doc__ = """What ``_run_rk4`` returns for a group: its statistics, pair statistics and record, the
plan of its last run, each copy's most sub-steps per output step, and the RK4 steps it
integrated over every robot and copy, runs again included."""


def simulate(scenario: Scenario | Sequence[Scenario], record: bool = True,
             progress: bool | None = None, on_divergence: str = "raise") -> SimulationResult:
    """Simulate every robot of ``scenario`` — or of a list of scenarios of one structure (a
    batch that differs in gains, offsets, targets, goals and starts). ``record`` keeps
    trajectories (else only the statistics, for large batches). ``progress``: show a
    progress bar (default: on a terminal, for long runs). ``on_divergence``: "raise" a
    ``SimulationError`` when a robot's state becomes non-finite, or "report" it — the run
    completes and ``diverged(result.stats)`` marks the robots of each member that did (their
    statistics are not finite), e.g. to count failures over a Monte-Carlo batch."""
    started = time.perf_counter()
    if on_divergence not in ON_DIVERGENCE:
        raise NonholoInputError(f"on_divergence must be one of {', '.join(ON_DIVERGENCE)}, got {on_divergence!r}")
    scenarios = list(scenario) if isinstance(scenario, (list, tuple)) else [scenario]
    if not scenarios or not all(isinstance(s, Scenario) for s in scenarios):
        raise NonholoInputError("simulate() takes a nonholo.Scenario or a list of them")
    _check_batch(scenarios)
    first = scenarios[0]
    check_network(scenarios)
    n_steps, n_robots, n_members = first.n_steps, len(first.robots), len(scenarios)
    _check_size(first, n_robots * n_members, record)
    grid = np.arange(n_steps + 1) * first.dt
    v_peak, omega_peak = _reference_survey(first)
    v_d0 = float(first.reference.table(grid[:1])[0, REF_V]) if first.reference is not None else 0.0
    stats = np.empty((kn.STAT_COUNT, n_robots, n_members))
    pair_stats = np.full((kn.PAIR_COUNT, len(first.components()), n_members), np.nan)
    rec_rows = kn.record_rows(bool(first.followers))   # no link rows without followers
    records = None if record else np.empty((rec_rows, 0, n_robots, n_members))
    substeps = np.zeros((n_robots, n_members), dtype=np.int64)   # each member's own
    component_of = np.arange(n_robots)   # by a component's first robot (robot k if all are alone)
    if len(first.components()) < n_robots:
        component_of[[c[0] for c in first.components()]] = np.arange(len(first.components()))
    reference_cache: dict[bytes, tuple] = {}
    rk4_steps = 0
    for group in _groups(scenarios, v_peak, omega_peak, v_d0):
        kernel = kernel_for(group.laws, group.followers)
        if first.method == "rk4":
            run = _run_rk4(kernel, first, group, record, progress, reference_cache)
            g_stats, g_pairs, g_record, most = run.stats, run.pair_stats, run.records, run.most
            rk4_steps += run.rk4_steps
        else:
            g_stats, g_pairs, g_record = _run_solve_ivp(kernel.evaluate, kernel.scorer(False), first, group, record,
                                                        grid)
            most = np.ones(group.members.size, dtype=np.int64)
        # a group whose record, as it lies in memory, is the run's hands it over without a copy
        view = _in_run_layout(group, g_record, rec_rows, n_robots, n_members) if record and records is None else None
        if view is not None:
            records = view
        elif record and records is None:
            records = np.empty((rec_rows, n_steps + 1, n_robots, n_members))
        members, index = group.members, group.index   # (copies,), (copies, robots of the graph)
        places = _places(index, members)
        for j, at in enumerate(places):
            stats[(slice(None), *at)] = g_stats[:, j, :]
            substeps[at] = most
        pair_stats[(slice(None), *_as_slices(component_of[index[:, 0]], members))] = g_pairs
        if record and view is None:
            _merge_record(records, g_record, places)
        if on_divergence == "raise":
            _check_diverged(group, g_stats)
    rows = None
    if first.reference is not None:   # every plan's stage rows include the output grid
        stage_rows, row_start, _ = next(iter(reference_cache.values()), (None, None, None))
        rows = _output_rows(stage_rows, row_start) if stage_rows is not None else first.reference.table(grid)
    return SimulationResult(scenarios=tuple(scenarios), t=grid, reference_rows=rows, stats=stats,
                            pair_stats=pair_stats, record=records if record else None,
                            substeps=substeps.max(axis=1), member_substeps=substeps,
                            elapsed_s=time.perf_counter() - started, rk4_steps=rk4_steps)


def _output_rows(stage_rows: np.ndarray, row_start: np.ndarray) -> np.ndarray:
    """The stage table's rows at the output instants. With one RK4 step per output step (the
    output instants are every other row) a view, which keeps twice the rows alive instead of
    copying half of them at every run; else a copy (a view would keep 2m times the rows)."""
    every_other = np.arange(0, stage_rows.shape[0], 2)
    if stage_rows.shape[0] == 2 * row_start.size - 1 and np.array_equal(row_start, every_other):
        return stage_rows[::2]
    return stage_rows[row_start]


def _merge_record(records: np.ndarray, g_record: np.ndarray, places: list[tuple]) -> None:
    """Copy a group's record (rows, N+1, robots of the graph, copies) into the run's at the
    ``places`` of its robots (``_places``); link rows that the group does not record (a
    graph without followers, in a run with some) are zeros."""
    rows = g_record.shape[0]
    for j, at in enumerate(places):   # each robot of the graph, in every copy
        records[(slice(None, rows), slice(None), *at)] = g_record[:, :, j, :]
        if records.shape[0] > rows:
            records[(slice(rows, None), slice(None), *at)] = 0.0


def _places(index: np.ndarray, members: np.ndarray) -> list[tuple]:
    """Where each robot j of a group's graph goes in the run's (robot, member) arrays, its
    copies at robots ``index[:, j]`` of ``members`` (``_as_slices``)."""
    return [_as_slices(index[:, j], members) for j in range(index.shape[1])]


def _as_slices(robots: np.ndarray, members: np.ndarray) -> tuple:
    """The positions (robot, member) of a group's copies in a run's arrays, as indices: a
    slice along one axis where the copies lie side by side there (a batch of lone robots, a
    batch of members), so that a record is copied as a block; else the two index arrays,
    whose element-by-element copy took 140 ms for a recorded batch of 10³ robots x 2 000
    steps (the kernel 56 ms)."""
    n = robots.size
    if n and (members == members[0]).all() and (robots == robots[0] + np.arange(n)).all():
        return slice(int(robots[0]), int(robots[0]) + n), int(members[0])
    if n and (robots == robots[0]).all() and (members == members[0] + np.arange(n)).all():
        return int(robots[0]), slice(int(members[0]), int(members[0]) + n)
    return robots, members


def _in_run_layout(group: Group, g_record: np.ndarray, rows: int, n_robots: int,
                   n_members: int) -> np.ndarray | None:
    """The group's record (rows, N+1, robots of the graph, copies) as the run's (``rows``,
    N+1, robots, members), a view of the same memory, where it has the run's rows and its
    copies hold every robot of every member in the run's order: robot j of copy b at the
    place of (robot ``index[b, j]``, member ``members[b]``) — a batch of whole members
    (j, b), or the lone robots of one scenario (0, b) as its robots (b, 0). Else None (the
    record is then copied, ``_merge_record``)."""
    index, members = group.index, group.members
    copies, robots = index.shape
    if g_record.shape[0] != rows or robots * copies != n_robots * n_members or not g_record.flags.c_contiguous:
        return None
    run_place = index * n_members + members[:, None]   # (copies, robots of the graph), C order of the run's
    own_place = np.arange(robots) * copies + np.arange(copies)[:, None]   # and of the group's own record
    if not np.array_equal(run_place, own_place):
        return None
    return g_record.reshape(g_record.shape[:2] + (n_robots, n_members))


class PlannedGroup:
    """A group of a sampled-data run with what ``simulate`` integrates it on: ``plan`` the RK4
    sub-steps of every output step, ``rows`` (N+1, 10) the reference and ``targets``
    (N+1, 6, R) the follower targets at the output instants, taken from the same stage
    tables (so a robot program that reads them computes bit for bit what the kernel does)."""

    def __init__(self, group: Group, plan: np.ndarray, rows: np.ndarray, targets: np.ndarray):
        self.group, self.plan, self.rows, self.targets = group, plan, rows, targets


def planned_groups(scenario: Scenario) -> list[PlannedGroup]:
    """The groups of a sampled-data scenario with their sub-step plans (planned as
    ``simulate`` plans them, by running it without recording): what each robot of a
    distributed lockstep run needs to reproduce the centralized run (spec fleet.md §6)."""
    if scenario.hold_every == 0 or scenario.method != "rk4":
        raise NonholoInputError("a distributed run needs sampled-data control: set control_period "
                                "(a multiple of dt) and method = \"rk4\"")
    _check_size(scenario, len(scenario.robots), True)   # (a fleet keeps every robot's states)
    grid = np.arange(scenario.n_steps + 1) * scenario.dt
    v_peak, omega_peak = _reference_survey(scenario)
    v_d0 = float(scenario.reference.table(grid[:1])[0, REF_V]) if scenario.reference is not None else 0.0
    cache_: dict[bytes, tuple] = {}
    planned = []
    for group in _groups([scenario], v_peak, omega_peak, v_d0):
        plan = _run_rk4(kernel_for(group.laws, group.followers), scenario, group, False, False, cache_).plan
        stage_rows, row_start, times = cache_[plan.tobytes()]
        table = group.targets(times)   # one row when no target changes
        targets = table[row_start] if table.shape[0] > 1 else np.repeat(table, row_start.size, axis=0)
        planned.append(PlannedGroup(group, plan, stage_rows[row_start], targets))
    return planned


def score_states(scenario: Scenario, planned: list[PlannedGroup], states: np.ndarray, helds: np.ndarray,
                 elapsed_s: float, watchdog: np.ndarray | None = None) -> SimulationResult:
    """The result of a sampled-data run whose trajectories were computed elsewhere (by the
    robots of a fleet): ``states`` (N+1, 4, robots) and the commands each robot held,
    ``helds`` (N+1, HELD_COUNT, robots), robots in scenario order; scored by the kernel's
    own statistics code, as ``simulate`` scores its runs. ``watchdog`` (2, robots): each
    follower's watchdog stops and stopped control instants, as the robots counted them."""
    n_steps, n_robots = scenario.n_steps, len(scenario.robots)
    stats = np.empty((kn.STAT_COUNT, n_robots, 1))
    pair_stats = np.full((kn.PAIR_COUNT, len(scenario.components()), 1), np.nan)
    records = np.empty((kn.record_rows(bool(scenario.followers)), n_steps + 1, n_robots, 1))
    substeps = np.empty(n_robots, dtype=np.int64)
    component_of = {c[0]: k for k, c in enumerate(scenario.components())}
    for item in planned:
        group = item.group
        score = kernel_for(group.laws, group.followers).scorer(True)
        columns = group.index.tolist()
        g_states = np.ascontiguousarray(np.stack([states[:, :, c] for c in columns], axis=-1))
        g_helds = np.ascontiguousarray(np.stack([helds[:, :, c] for c in columns], axis=-1))
        g_stats, g_pairs = kn.new_stats(*group.state.shape[1:])
        g_record = np.empty((kn.record_rows(group.followers), n_steps + 1, *group.state.shape[1:]))
        score(g_states, group.fields, group.limits, item.rows, item.targets, group.offsets, group.kinds, group.order,
              group.parents, group.initial_branches(), scenario.sin_floor, group.d_max, g_stats, g_pairs, g_record,
              scenario.hold_every, g_helds)
        member_0 = np.zeros(len(columns), dtype=np.int64)
        _merge_record(records, g_record, _places(np.array(columns), member_0))
        for b, indices in enumerate(columns):
            stats[:, indices, 0] = g_stats[:, :, b]
            pair_stats[:, component_of[indices[0]], 0] = g_pairs[:, b]
            substeps[indices] = item.plan.max()
        _check_diverged(group, g_stats)
    if watchdog is not None:
        stats[[kn.WATCHDOG_STOPS, kn.WATCHDOG_STOPPED], :, 0] = watchdog
    grid = np.arange(n_steps + 1) * scenario.dt
    rows = planned[0].rows if scenario.reference is not None else None
    rk4_steps = sum(int(item.plan.sum()) * item.group.state.shape[1] * item.group.state.shape[2] for item in planned)
    return SimulationResult(scenarios=(scenario,), t=grid, reference_rows=rows, stats=stats, pair_stats=pair_stats,
                            record=records, substeps=substeps, elapsed_s=elapsed_s, rk4_steps=rk4_steps)


def _check_size(scenario: Scenario, robots: int, record: bool) -> None:
    """Refuse, before allocating, a run whose arrays would not fit (an estimate)."""
    samples = scenario.n_steps + 1
    estimate = 8.0 * robots * ((kn.record_rows(bool(scenario.followers)) * samples if record else 0) + kn.STAT_COUNT
                               + 64)
    substeps = scenario.substeps or 1   # the reference rows at every stage time
    estimate += 8.0 * 10 * 2 * substeps * samples
    if scenario.hold_every and scenario.network is not None and not scenario.network.ideal:
        estimate += 8.0 * 2 * robots * (samples // scenario.hold_every + 1)   # the links' schedules
    if estimate > MAX_BYTES:
        raise NonholoInputError(
            f"this run would need about {estimate / 2**30:.3g} GiB ({robots} robots x {samples} samples"
            f"{', recorded' if record else ''}; at most {MAX_BYTES / 2**30:g} GiB): use a larger dt, a shorter "
            "duration, fewer robots or record=False")


def _reference_rows(scenario: Scenario, times: np.ndarray) -> np.ndarray:
    if scenario.reference is None:
        rows = np.zeros((times.size, 10))
        rows[:, 0] = times
        return rows
    rows = scenario.reference.table(times)
    _check_finite(scenario, rows)
    return rows


# Reference tables kept for groups that share a sub-step plan, at most this many bytes: the
# oldest go first (a 41-point gain sweep has 41 plans of ~32 MB each).
REFERENCE_CACHE_BYTES = 2**26


def trim_reference_cache(cache_: dict, keep: bytes) -> None:
    """Drop the oldest reference tables of ``cache_`` beyond ``REFERENCE_CACHE_BYTES``, never ``keep``."""
    total = sum(sum(part.nbytes for part in entry) for entry in cache_.values())
    for key in list(cache_):
        if total <= REFERENCE_CACHE_BYTES:
            break
        if key != keep:
            total -= sum(part.nbytes for part in cache_.pop(key))


def goal_origin(group: Group) -> tuple[list[int], np.ndarray] | None:
    """For a group whose roots are all posture roots under goal-relative laws (and so read
    no reference): the roots' positions in the graph and each copy's first goal (x, y),
    (2, copies), the origin it is integrated from. Near its goal a robot's pose is then
    resolved to the last bit: in world coordinates a goal 14 m from the origin leaves
    positions 2e-15 m apart, and the polar law's heading, which follows the direction to the
    goal at 1e-9 m, froze 0.002° off instead of < 1e-7° (spec follower-posture.md §6 (d))."""
    roots = [j for j, robot in enumerate(group.robots) if isinstance(robot, Robot)]
    if not all(group.robots[j].posture and group.robots[j].controller.controller.goal_relative for j in roots):
        return None
    return roots, group.fields[:2, roots[0]].copy()


def _run_rk4(kernel: kn.Kernel, scenario: Scenario, group: Group, record: bool, progress, cache_: dict):
    """Integrate a group, planning its sub-steps from the rates it meets (see the module
    docstring): groups with followers or posture roots window by window (``plan_windows``),
    tracking roots over the whole horizon (under continuous-time control), and only the copies
    whose own rates asked for more sub-steps (their statistic ``STEP_RATE``) run again: a
    batch's copies get the sub-steps they need, and those that need no more are not run again.
    Returns a ``GroupRun``. Under continuous-time control a
    group of posture roots (and their followers) is integrated with its first goal as origin
    (``goal_origin``); its record is in world coordinates. (Sampled-data runs stay in world
    coordinates, as the robot programs of a fleet do.)"""
    n_steps, dt = scenario.n_steps, scenario.dt
    plan = group.prior.copy()
    shift = goal_origin(group) if scenario.hold_every == 0 else None
    fields, start = group.fields, group.state
    if shift is not None:
        roots, origin = shift
        fields, start = group.fields.copy(), group.state.copy()
        for j in roots:
            fields[:2, j] -= origin
        start[:2] -= origin[:, None, :]
    # (tracking roots under sampled-data control hold their commands: no law's rate to meet)
    planning = (group.measured or scenario.hold_every == 0) and scenario.substeps is None
    attempts = PLAN_ATTEMPTS if planning else 1
    n_robots, n_batch = group.state.shape[1:]
    integrate = kernel.integrator(scenario.hold_every != 0, n_batch)
    work = float(plan.sum()) * n_robots * n_batch
    show = work > PROGRESS_WORK and sys.stderr.isatty() if progress is None else progress
    whole = linked(group)   # the link model runs the whole horizon at once (nonholo.sim.linkstep)
    # Formations and posture roots are planned window by window (``spans``); tracking roots
    # over the whole horizon, run again only in the rare run that a transient left
    # under-resolved (windows would cost a single run about 1 ms, and their rates are mostly
    # met). A progress bar moves piece by piece (``windows``) within a span: the numbers do
    # not depend on whether it is shown.
    per_window = group.measured and attempts > 1
    windows = plan_windows(n_steps) if (per_window or show) and not whole else [(0, n_steps)]
    spans = windows if per_window else [(0, n_steps)]

    # The first tables before the outputs: in this order glibc's malloc keeps reusing the same
    # memory from one run to the next (the other way round, a Test 1 run faulted in 2 200
    # fresh pages, 9.8 instead of 5.4 ms, without nonholo.cli.tune_memory's settings).
    full = _plan_tables(scenario, dt, plan, cache_)   # the first plan's, until a window is planned again
    rows, row_start, times, targets = _window_tables(scenario, group, dt, plan, full, *spans[0])

    def initial() -> tuple:
        """The run's state, bearings, statistics, pair statistics and held commands at t = 0."""
        return (start.copy(), group.initial_branches(), *kn.new_stats(n_robots, n_batch),
                np.zeros((kn.HELD_COUNT, n_robots, n_batch)))

    state, branch, stats, pair_stats, held = initial()
    records = np.empty((kn.record_rows(group.followers), n_steps + 1 if record else 0, n_robots, n_batch))
    step_rate = np.zeros(n_steps + 1)
    bar = _progress_bar(show and not whole, n_steps, scenario.name, n_robots * n_batch)
    kept = []   # each window's stage rows (reference, times), as integrated
    most = np.zeros(n_batch, dtype=np.int64)   # each copy's most sub-steps per output step
    rk4_steps = 0
    live = None   # the copies integrated: all, or (a tracking group's) those run again
    try:
        for w, (k0, k1) in enumerate(spans):
            # (what a run again puts back: a copy, or at t = 0 the initial values made again)
            saved = [array.copy() for array in (state, branch, stats, pair_stats, held)] if attempts > 1 and k0 else []
            replanned = w > 0   # (the first span's tables are made above)
            pieces = [(a, b) for a, b in windows if k0 <= a and b <= k1]
            for attempt in range(attempts):
                if replanned:
                    rows, row_start, times, targets = _window_tables(scenario, group, dt, plan, full, k0, k1)
                copies = (state, fields, group.limits, group.offsets, branch, group.d_max, stats, pair_stats, records,
                          held)
                n_live = n_batch if live is None else live.size
                if live is not None:   # (contiguous copies of the copies run again)
                    copies = [np.ascontiguousarray(array[..., live]) for array in copies]
                run_state, run_fields, run_limits, run_offsets, run_branch, run_d_max, *run_outputs = copies
                args = (run_state, run_fields, run_limits, rows, row_start, plan, targets, run_offsets, group.kinds,
                        group.order, group.parents, group.feeds, run_branch, scenario.sin_floor, run_d_max,
                        group.xi_speed, dt, scenario.hold_every)
                outputs = (*run_outputs, step_rate)
                replanned = False
                if whole:
                    integrate_linked(integrate, kernel.evaluate, args, scenario, group, outputs, show)
                else:
                    run = integrate if live is None else kernel.integrator(scenario.hold_every != 0, n_live)
                    for a, b in pieces:
                        run(*args, a, b, n_steps, *outputs, False)
                        if bar is not None:
                            bar.update(b - a)
                if live is not None:
                    for array, part in zip((state, branch, stats, pair_stats, records, held),
                                           (run_state, run_branch, *run_outputs)):
                        array[..., live] = part
                most[slice(None) if live is None else live] = plan.max()
                rk4_steps += int(plan[k0:k1].sum()) * n_robots * n_live
                if attempt == attempts - 1:   # the last run stands (its plan is the one returned)
                    break
                window = slice(k0, k1)
                if step_rate[max(k0 - 1, 0):k1 + 1].max() * dt / group.rate_factor <= plan[window].min():
                    break   # (every step has the sub-steps its rates ask for: the common case, quickly)
                needed = measured_plan(step_rate, group.prior, dt, k0, k1, group.rate_factor)   # (step_rate[k1]: 0)
                short = needed > plan[window]
                if not short.any():
                    break
                if not per_window:   # only the copies whose own rates asked for more run again
                    # (a copy that stood keeps the statistics of its accepted run: within its factor)
                    live = np.flatnonzero(stats[kn.STEP_RATE].max(axis=0)
                                          > group.rate_factor * (1.0 - OWN_RATE_MARGIN))
                    if not live.size:
                        break
                for array, copy in zip((state, branch, stats, pair_stats, held), saved or initial()):
                    if live is None:
                        array[...] = copy
                    else:
                        array[..., live] = copy[..., live]
                step_rate[k0:k1 + 1] = 0.0
                plan = plan.copy()   # (the plan of the copies that stand is kept)
                plan[window] = np.where(short, np.minimum(needed, PLAN_GROWTH * plan[window]), plan[window])
                replanned, full = True, None
                if bar is not None:   # (the span is run again)
                    bar.n -= k1 - k0
                    bar.refresh()
            kept.append((rows, times))
    finally:
        if bar is not None:
            bar.close()
    key = plan.tobytes()
    if key not in cache_:   # the whole plan's tables, for the result and the robots of a fleet (planned_groups)
        if len(kept) == 1:
            cache_[key] = (kept[0][0], plan_rows(plan), kept[0][1])
        else:
            cache_[key] = (np.concatenate([r[:-1] for r, _ in kept] + [kept[-1][0][-1:]]), plan_rows(plan),
                           np.concatenate([t[:-1] for _, t in kept] + [kept[-1][1][-1:]]))
        kept.clear()
        trim_reference_cache(cache_, key)
    if shift is not None and record:   # back to world coordinates (rounded there), the starts as given
        records[[kn.REC_X, kn.REC_Y]] += shift[1][:, None, None, :]
        records[[kn.REC_X, kn.REC_Y], 0] = group.state[:2]
    return GroupRun(stats, pair_stats, records, plan, most, rk4_steps)


def plan_windows(n_steps: int) -> list[tuple[int, int]]:
    """The output steps [k0, k1) of the windows a run is integrated in: ``PLAN_WINDOWS`` of
    them (fewer for short runs). A window of a formation or posture group whose own rates ask
    for more sub-steps than it ran is run again from its start (see ``_run_rk4``; tracking
    groups plan over the whole horizon, these windows only pieces for the progress bar); a
    progress bar moves window by window. The windows depend only on ``n_steps``, and a
    tracking group's plan not on them: a run gives the same numbers shown or not."""
    edges = np.unique(np.linspace(0, n_steps, min(PLAN_WINDOWS, n_steps) + 1).astype(np.int64))
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def _plan_tables(scenario: Scenario, dt: float, plan: np.ndarray, cache_: dict) -> tuple:
    """(reference rows at every RK4 stage time of ``plan``, the first row of each output step,
    the stage times), kept in ``cache_`` for groups that share the plan."""
    key = plan.tobytes()
    if key not in cache_:
        times, row_start = stage_times(dt, plan)
        cache_[key] = (_reference_rows(scenario, times), row_start, times)
        trim_reference_cache(cache_, key)
    return cache_[key]


def _window_tables(scenario: Scenario, group: Group, dt: float, plan: np.ndarray, full: tuple | None, k0: int,
                   k1: int) -> tuple:
    """The stage rows of output steps [k0, k1) and of the sample k1, numbered from the
    window's first (rows, row_start, times), and the followers' targets at those times: views
    of ``full`` (``_plan_tables`` of ``plan``), or built for the window alone if None (a plan
    changed by a window planned again)."""
    if full is not None:
        rows, row_start, times = full
        rows, times = rows[row_start[k0]:row_start[k1] + 1], times[row_start[k0]:row_start[k1] + 1]
    else:
        times, row_start = stage_times(dt, plan, k0, k1)
        rows = _reference_rows(scenario, times)
    targets = group.targets(times) if group.followers else np.zeros((1, len(TABLE_COLUMNS), group.state.shape[1]))
    return rows, row_start - row_start[k0] if k0 else row_start, times, targets


def _progress_bar(show: bool, n_steps: int, name: str, count: int):
    if not show:
        return None
    from tqdm import tqdm

    return tqdm(total=n_steps, unit="step", desc=f"{name}: {count} robots", file=sys.stderr)


# A robot whose error or speed passed this (m, m/s) diverged, as one whose state became
# non-finite: an unstable run grows without bound, and whether it overflows to inf within
# the horizon depends on rounding (1e149 m and still finite is not a result).
DIVERGED_BEYOND = 1e9


def diverged(stats: np.ndarray) -> np.ndarray:
    """(robots, members) booleans: the robots whose state became non-finite or whose error
    or speed passed ``DIVERGED_BEYOND``, from the statistics (STAT_COUNT, robots, members)
    of a run."""
    finite = np.isfinite(stats[[kn.E_MEAN, kn.E_M2, kn.V_SQ, kn.W_SQ]]).all(axis=0)
    return ~finite | (np.abs(stats[[kn.E_MAX, kn.V_PEAK]]) > DIVERGED_BEYOND).any(axis=0)


def _check_diverged(group: Group, stats: np.ndarray) -> None:
    bad = diverged(stats)   # (robots of the graph, copies)
    finite = ~bad.any(axis=1)
    if not finite.all():
        names = [robot.name for robot, ok in zip(group.robots, finite) if not ok]
        shown = ", ".join(repr(name) for name in names[:5]) + (" …" if len(names) > 5 else "")
        members = np.unique(group.members[bad.any(axis=0)]).tolist()
        batch = "" if (group.members == group.members[0]).all() else \
            f" in {len(members)} member(s) of the batch (the first: member {members[0]}; on_divergence=\"report\" " \
            "completes the batch and marks them)"
        raise SimulationError(
            f"the simulation of robot(s) {shown} diverged{batch} (state non-finite or beyond 1e9 m): reduce dt, set more "
            "substeps or check the gains, actuator limits and the formation's geometry")


def _run_solve_ivp(evaluate, score, scenario: Scenario, group: Group, record: bool, grid: np.ndarray):
    """scipy cross-check: DOP853 (Radau for stiff laws), rtol = atol = 1e-10, dense output
    sampled on the grid and scored by the same compiled code as the RK4 path."""
    from scipy.integrate import solve_ivp   # here: importing scipy.integrate costs every command 0.3 s
    shape = group.state.shape
    n_robots, n_batch = shape[1:]
    instant = np.zeros((kn.INSTANT_COUNT, n_robots, n_batch))
    live_branch = group.initial_branches()
    bearing_robots = np.flatnonzero(group.kinds == kn.SEPARATION_BEARING)
    slope = np.empty(shape)

    def rhs(t, y):
        state = y.reshape(shape)
        for j in bearing_robots:
            p = group.parents[0, j]
            _, raw, _ = separation_bearing(state[:3, p], state[:3, j], group.fields[kn.OFFSET_D, j])
            live_branch[j] += wrap(raw - live_branch[j])
        times = np.array([t])
        evaluate(state, group.fields, group.limits, tuple(_reference_rows(scenario, times)[0]), group.targets(times), 0,
                 group.offsets, group.kinds, group.order, group.parents, live_branch, scenario.sin_floor, instant)
        v, omega = instant[kn.I_V], instant[kn.I_OMEGA]
        slope[0], slope[1], slope[2] = v * np.cos(state[2]), v * np.sin(state[2]), omega
        slope[3] = instant[kn.I_XI_DOT]
        return slope.ravel().copy()

    v_peak = omega_peak = 0.0
    if scenario.reference is not None:
        rows = scenario.reference.table(grid)
        v_peak, omega_peak = np.abs(rows[:, REF_V]).max(), np.abs(rows[:, REF_OMEGA]).max()
    stiffness = max([r.controller.stiffness(v_peak, omega_peak) for r in group.robots if isinstance(r, Robot)]
                    + [max(r.k1, r.k2) for r in group.robots if isinstance(r, Follower)])
    method = "Radau" if stiffness > STIFF_RATE else "DOP853"
    try:
        solution = solve_ivp(rhs, (0.0, grid[-1]), group.state.ravel(), method=method, t_eval=grid,
                             rtol=SOLVE_IVP_TOLERANCE, atol=SOLVE_IVP_TOLERANCE)
    except (ValueError, OverflowError, FloatingPointError) as exc:
        raise SimulationError(f"solve_ivp failed: {exc}"[:300]) from None
    if not solution.success:
        raise SimulationError(f"solve_ivp failed: {solution.message}")
    states = np.ascontiguousarray(solution.y.T.reshape(-1, *shape))
    stats, pair_stats = kn.new_stats(n_robots, n_batch)
    records = np.empty((kn.record_rows(group.followers), grid.size if record else 0, n_robots, n_batch))
    score(states, group.fields, group.limits, _reference_rows(scenario, grid), group.targets(grid), group.offsets,
          group.kinds, group.order, group.parents, group.initial_branches(), scenario.sin_floor, group.d_max, stats,
          pair_stats, records, 0, np.zeros((0, kn.HELD_COUNT, n_robots, n_batch)))
    return stats, pair_stats, records
