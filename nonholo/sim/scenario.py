"""The one model of a fleet: a scenario is a DAG of robots, as plain immutable data.

* A **root** (``Robot``) either tracks the scenario's reference with a tracking law or, with
  ``goal`` set, stabilises to that pose with a posture law. A lone tracking robot is a root
  with no followers. Every root has its own controller and gains.
* A **follower** (``Follower``) keeps a separation–bearing link (l–φ) to one parent or a
  separation–separation link (l–l) to two parents (spec follower-posture.md §2–4). A parent
  may itself be a follower. ``Change`` is a run-time change of a follower's targets.

The simulator evaluates robots parents first (``topological_order``) and passes each
parent's computed (saturated) command down the graph. ``piconet=True`` enforces the
Bluetooth piconet of the thesis: one master (a single root) and at most 7 slaves.
"""
from __future__ import annotations

import heapq
import math
import numbers
from collections import Counter
from dataclasses import dataclass, field
from functools import cached_property

from nonholo.control.registry import CONTROLLERS, POSTURE_CONTROLLERS, ControllerConfig, controller, follower_gains
from nonholo.errors import FormationError, NonholoInputError
from nonholo.models import formation_geometry as geometry
from nonholo.models.formation_geometry import place_follower, pose_in_frame
from nonholo.numerics import is_real
from nonholo.references.base import Reference
from nonholo.sim.links import LinkSettings
from nonholo.sim.targets import target_segments

METHODS = ("rk4", "solve_ivp")
MAX_STEPS = 1e8
MAX_POSITION_M = 1.0e7   # |x|, |y| of a start or goal (and of a state a robot program sends)
MAX_ANGLE_RAD = 1.0e6    # |θ| of a start or goal
SEPARATION_BEARING = "separation-bearing"
SEPARATION_SEPARATION = "separation-separation"
FORMATION_LAWS = (SEPARATION_BEARING, SEPARATION_SEPARATION)
OUTPUTS = {SEPARATION_BEARING: ("l", "phi"), SEPARATION_SEPARATION: ("l1", "l2")}
SECOND_OUTPUT_PARAMETERS = frozenset({"k2", "phi", "l2"})   # a follower's parameters that drive its second output
CHANGE_MODES = ("step", "ramp")
DIRECTIONS = ("shortest", "counterclockwise", "clockwise")
PICONET_SLAVES = 7


def is_count(value) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool) and value >= 1


def _pose(value, robot: str, name: str) -> tuple[float, float, float]:
    try:
        pose = tuple(value)
    except TypeError:
        pose = ()
    if len(pose) != 3 or not all(is_real(s) for s in pose):
        raise FormationError(robot, name, f"must be three finite numbers [x, y, theta], got {value!r}"[:200])
    x, y, theta = (float(s) for s in pose)
    if max(abs(x), abs(y)) > MAX_POSITION_M or abs(theta) > MAX_ANGLE_RAD:
        raise FormationError(robot, name, f"x and y must be within ±{MAX_POSITION_M:g} m and theta within "
                                          f"±{MAX_ANGLE_RAD:g} rad, got {value!r}"[:200])
    return x, y, theta


def _limits(robot) -> None:
    for limit in ("v_max", "omega_max"):
        value = getattr(robot, limit)
        number = type(value) is float or (isinstance(value, numbers.Real) and not isinstance(value, bool))
        if not (number and value > 0):   # (inf: no limit)
            raise FormationError(robot.name, limit, f"must be a number > 0, got {value!r}")
        object.__setattr__(robot, limit, float(value))


@dataclass(frozen=True)
class Robot:
    """A root robot: tracks the reference, or with ``goal`` = (x, y, θ) stabilises to that
    pose (``controller`` then a posture law, e.g. ``nonholo.controller("polar")``).

    ``start`` is (x, y, θ) in metres and radians; ``v_max``/``omega_max`` are actuator
    limits (saturation, counted in the results); infinite by default.
    """

    name: str
    controller: ControllerConfig = field(default_factory=lambda: controller("dynamic-feedback"))
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    v_max: float = math.inf
    omega_max: float = math.inf
    goal: tuple[float, float, float] | None = None

    def __post_init__(self):
        if not isinstance(self.controller, ControllerConfig):
            raise FormationError(self.name, "controller", f"must come from nonholo.controller(...), got "
                                                          f"{self.controller!r}"[:200])
        object.__setattr__(self, "start", _pose(self.start, self.name, "start"))
        posture = self.controller.controller.kind == "posture"
        if self.goal is not None:
            object.__setattr__(self, "goal", _pose(self.goal, self.name, "goal"))
            if not posture:
                raise FormationError(self.name, "controller", f"{self.controller.name} is a tracking law; a robot "
                                                              "with a goal needs a posture law "
                                                              f"({', '.join(POSTURE_CONTROLLERS)})")
        elif posture:
            raise FormationError(self.name, "goal", f"missing: the posture law {self.controller.name} stabilises to a "
                                                    "goal [x, y, theta] (a tracking root follows the reference with "
                                                    f"one of {', '.join(CONTROLLERS)})")
        _limits(self)

    @property
    def posture(self) -> bool:
        return self.goal is not None

    def __repr__(self) -> str:
        goal = f", goal={self.goal}" if self.goal is not None else ""
        limits = "".join(f", {k}={getattr(self, k):g}" for k in ("v_max", "omega_max") if math.isfinite(getattr(self, k)))
        return f"Robot({self.name!r}, {self.controller!r}, start={self.start}{goal}{limits})"

    @property
    def parents(self) -> tuple[str, ...]:
        return ()


@dataclass(frozen=True)
class Change:
    """A run-time change of a follower's targets (thesis Eq 5.9; spec §2.5).

    ``targets`` maps output names (``l``, ``phi`` for l–φ; ``l1``, ``l2`` for l–l) to new
    values. ``mode`` "step" switches at ``at`` (the sample at t = at still has the old
    target); "ramp" moves along a quintic smoothstep over ``duration`` seconds and feeds
    the target's rate forward. ``direction`` picks the 2π branch of a bearing change:
    "shortest" (ambiguous, hence an error, for changes of ±π), "counterclockwise"
    (φ_d increases: for φ ≈ π/3 → 4π/3 the castor point swings behind the leader) or
    "clockwise".
    """

    at: float
    targets: dict
    mode: str = "step"
    duration: float = 0.0
    direction: str = "shortest"


@dataclass(frozen=True)
class Follower:
    """An l–φ (``law`` = "separation-bearing", one parent, targets (l_d, φ_d)) or l–l
    ("separation-separation", two parents, targets (l1_d, l2_d)) follower with castor
    offset ``d`` and gains k1, k2.

    Start: ``start`` as an axle pose (x, y, θ) in the world (``start_frame`` "world") or
    in the body frame of its (first) parent at t = 0 ("leader"); ``None`` places an l–φ
    follower exactly in formation with its parent's heading.
    """

    name: str
    law: str
    leaders: tuple[str, ...]
    targets: tuple[float, float]
    d: float = 1.0
    k1: float = 1.0
    k2: float = 1.0
    start: tuple[float, float, float] | None = None
    start_frame: str = "world"
    changes: tuple[Change, ...] = ()
    v_max: float = math.inf
    omega_max: float = math.inf

    @property
    def outputs(self) -> tuple[str, str]:
        return OUTPUTS[self.law]

    def __repr__(self) -> str:
        targets = ", ".join(f"{n}={v:g}" for n, v in zip(self.outputs, self.targets))
        changes = f", {len(self.changes)} change(s)" if self.changes else ""
        return (f"Follower({self.name!r}, {self.law} of {', '.join(self.leaders)}: {targets}, d={self.d:g}, "
                f"k1={self.k1:g}, k2={self.k2:g}{changes})")

    @property
    def parents(self) -> tuple[str, ...]:
        return self.leaders


def separation_bearing(name, leader, l, phi, d=1.0, k1=1.0, k2=1.0, **options) -> Follower:
    """An l–φ follower of ``leader`` with targets l_d = ``l``, φ_d = ``phi``."""
    return Follower(name, SEPARATION_BEARING, (leader,), (float(l), float(phi)), d, k1, k2, **options)


def separation_separation(name, leaders, l, d=1.0, k1=1.0, k2=1.0, **options) -> Follower:
    """An l–l follower of ``leaders`` = (a, b) with targets ``l`` = (l1_d, l2_d)."""
    return Follower(name, SEPARATION_SEPARATION, tuple(leaders), (float(l[0]), float(l[1])), d, k1, k2, **options)


@dataclass(frozen=True)
class Scenario:
    """Robots (roots and followers) over ``duration`` seconds.

    Output grid t_k = k·dt, k = 0…N, N = round(duration/dt) (or give ``steps`` = N and
    dt = duration/N). ``reference`` is needed when a root tracks one. ``substeps``: RK4
    sub-steps per output step (None = automatic, see ``nonholo.sim.simulator``).
    ``control_period``: if set, every law runs as sampled-data control with a zero-order
    hold at that period (a multiple of dt; spec fleet.md); otherwise it is evaluated at
    every RK4 stage (continuous-time law). ``method``: "rk4" (compiled, batch) or
    "solve_ivp" (scipy, tight tolerances, for cross-checks). ``piconet``: one root and at
    most 7 followers. ``sin_floor``: the l–l guard on |sin(γ1 − γ2)|. ``network``: the link
    model of a sampled-data run (``nonholo.sim.links.LinkSettings``: per-link delay, jitter,
    loss, seed, the followers' watchdog and prediction; spec fleet.md §3–5), applied to the states
    passed from parent to child as a fleet's links do; None (or ideal links): every state is
    used at its own instant.
    """

    reference: Reference | None
    robots: tuple
    duration: float | None = None
    dt: float | None = None
    steps: int | None = None
    substeps: int | None = None
    control_period: float | None = None
    method: str = "rk4"
    name: str = "scenario"
    piconet: bool = False
    sin_floor: float = 1e-6
    network: LinkSettings | None = None

    def __post_init__(self):
        if self.reference is not None and not isinstance(self.reference, Reference):
            raise NonholoInputError(f"reference must be a nonholo reference, got {self.reference!r}"[:200])
        try:
            object.__setattr__(self, "robots", tuple(self.robots))
        except TypeError:
            raise NonholoInputError(f"robots must be a list of Robot and Follower, got {self.robots!r}"[:200]) from None
        if not self.robots:
            raise NonholoInputError("a scenario needs at least one robot")
        if not all(isinstance(r, (Robot, Follower)) for r in self.robots):
            raise NonholoInputError("robots must be nonholo.Robot or nonholo.Follower objects")
        names = [r.name for r in self.robots]
        duplicates = sorted(n for n, k in Counter(names).items() if k > 1)
        if duplicates:
            raise NonholoInputError(f"robot names must be unique, repeated: {', '.join(duplicates)}"[:300])
        tracking = next((r for r in self.robots if isinstance(r, Robot) and not r.posture), None)
        if tracking is not None and self.reference is None:
            raise FormationError(tracking.name, "controller", "a tracking root needs a [reference]")
        self._check_grid()
        check_graph(self)
        if any(isinstance(r, Follower) and r.start is not None for r in self.robots):
            self._check_starts()

    def _check_starts(self) -> None:
        """A follower may not start with its castor point on a parent's axle centre: l = 0,
        where the bearing and the link laws are undefined (spec follower-posture.md §2.4)."""
        poses = dict(zip(self.names, self.initial_poses()))
        for robot in self.followers:
            for parent in robot.leaders:
                l, _, _ = geometry.separation_bearing(poses[parent], poses[robot.name], robot.d)
                if l <= 1e-9 * max(1.0, robot.d):
                    raise FormationError(robot.name, "start", f"its castor point (d = {robot.d:g} m ahead of its "
                                                              f"axle) starts on {parent}'s axle centre: l = 0, where "
                                                              "the bearing and the formation laws are undefined; "
                                                              "start it elsewhere")

    def _check_grid(self) -> None:
        duration = self.duration
        if duration is None and self.reference is not None:
            duration = self.reference.default_duration
        if duration is None:
            what = f"the {self.reference.kind} reference has no natural one" if self.reference is not None else \
                "posture roots have no natural duration"
            raise FormationError(None, "duration", f"a duration is needed: {what}")
        if not (is_real(duration) and duration > 0):
            raise FormationError(None, "duration", f"duration must be a positive number of seconds, got {duration!r}")
        object.__setattr__(self, "duration", float(duration))
        if self.steps is not None:
            if not is_count(self.steps):
                raise FormationError(None, "steps", f"steps must be a positive integer, got {self.steps!r}")
            object.__setattr__(self, "steps", int(self.steps))
            dt_of_steps = self.duration / self.steps
            # A scenario built with steps carries the derived dt (dataclasses.replace passes both).
            if self.dt is not None and not math.isclose(self.dt, dt_of_steps, rel_tol=1e-12):
                raise FormationError(None, "steps", "give dt or steps, not both")
            object.__setattr__(self, "dt", dt_of_steps)
        dt = 0.01 if self.dt is None else self.dt
        if not (is_real(dt) and dt > 0):
            raise FormationError(None, "dt", f"dt must be a positive number of seconds, got {dt!r}")
        if dt > self.duration:
            raise FormationError(None, "dt", f"dt = {dt:g} s is longer than the duration {self.duration:g} s")
        object.__setattr__(self, "dt", float(dt))
        if self.substeps is not None:
            if not is_count(self.substeps):
                raise FormationError(None, "substeps", f"substeps must be a positive integer, got {self.substeps!r}")
            object.__setattr__(self, "substeps", int(self.substeps))
        if self.method not in METHODS:
            raise FormationError(None, "method", f"unknown method {self.method!r} (valid: {', '.join(METHODS)})")
        if self.duration / self.dt > MAX_STEPS:
            raise FormationError(None, "dt", f"dt = {self.dt:g} s gives {self.duration / self.dt:.3g} steps over "
                                             f"{self.duration:g} s (at most {MAX_STEPS:g}): use a larger dt")
        span = getattr(self.reference, "time_span", None)   # references defined on a bounded time span
        if span is not None:
            end, slack = self.duration, 1e-9 * max(1.0, abs(span[0]), abs(span[1]))
            if span[0] > slack or end > span[1] + slack:
                raise FormationError(None, "duration", f"the run covers t = 0 to {end:g} s but the {self.reference.kind} "
                                                       f"reference covers t = {span[0]:g} to {span[1]:g} s: extend the "
                                                       "reference or shorten the run")
        if self.control_period is not None:
            if not (is_real(self.control_period) and 0 < self.control_period <= self.duration):
                raise FormationError(None, "control_period", "control_period must be a positive number of seconds up "
                                                             f"to the duration, got {self.control_period!r}")
            ratio = self.control_period / self.dt
            if not (abs(ratio - round(ratio)) < 1e-6 and round(ratio) >= 1):
                raise FormationError(None, "control_period", f"control_period must be a positive multiple of dt = "
                                                             f"{self.dt:g} s, got {self.control_period!r}")
            if self.method != "rk4":
                raise FormationError(None, "control_period",
                                     "sampled-data control (control_period) needs method = \"rk4\"")
        if not (is_real(self.sin_floor) and self.sin_floor > 0):
            raise FormationError(None, "sin_floor", f"must be a number > 0, got {self.sin_floor!r}")
        if not isinstance(self.piconet, bool):
            raise FormationError(None, "piconet", f"expected true or false, got {self.piconet!r}")
        self._check_network()

    def _check_network(self) -> None:
        if self.network is None:
            return
        if not isinstance(self.network, LinkSettings):
            raise NonholoInputError(f"network must be a nonholo.sim.links.LinkSettings, got {self.network!r}"[:200])
        edges = {(p, r.name) for r in self.robots for p in r.parents}
        for edge, _ in self.network.links:
            if edge not in edges:
                raise FormationError(None, "network", f"no link {edge[0]} -> {edge[1]} in the formation (parent and "
                                                      "child must name a robot and one of its followers)"[:200])

    @property
    def n_steps(self) -> int:
        return max(1, round(self.duration / self.dt))

    def __repr__(self) -> str:
        reference = f"{self.reference.kind} reference" if self.reference is not None else "no reference"
        control = f", control every {self.control_period:g} s" if self.control_period else ""
        return (f"<Scenario {self.name!r}: {reference}, {len(self.roots)} root(s), {len(self.followers)} follower(s), "
                f"{self.duration:g} s in steps of {self.dt:g} s{control}, {self.method}>")

    @property
    def hold_every(self) -> int:
        """Output steps between control updates (0 = continuous-time law)."""
        return 0 if self.control_period is None else round(self.control_period / self.dt)

    @property
    def held_period(self) -> float | None:
        """The period commands are held for: ``hold_every``·dt (``control_period`` is taken to
        within 1e-6 of a multiple of dt), to 12 digits (3 × 0.1 is 0.3), None for continuous-time laws."""
        return None if self.control_period is None else float(f"{self.hold_every * self.dt:.12g}")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.robots)

    @cached_property   # (kept in the instance's __dict__: a scenario and its robots do not change)
    def roots(self) -> tuple[Robot, ...]:
        return tuple(r for r in self.robots if isinstance(r, Robot))

    @property
    def leaders(self) -> tuple[Robot, ...]:
        """The thesis's word for the roots."""
        return self.roots

    @cached_property
    def followers(self) -> tuple[Follower, ...]:
        return tuple(r for r in self.robots if isinstance(r, Follower))

    def robot(self, name: str):
        try:
            return self.robots[self.names.index(name)]
        except ValueError:
            raise KeyError(f"no robot named {name!r} (robots: {', '.join(self.names)})"[:300]) from None

    def order(self) -> tuple[int, ...]:
        """Robot indices parents-first (stable: file order among ready robots)."""
        if "_order" not in self.__dict__:
            object.__setattr__(self, "_order", topological_order(self.robots))
        return self.__dict__["_order"]

    def initial_poses(self) -> list[tuple[float, float, float]]:
        """Axle poses at t = 0, resolving leader-frame and in-formation starts parents-first."""
        if not self.followers:
            return [r.start for r in self.robots]
        poses: dict[str, tuple[float, float, float]] = {}
        for i in self.order():
            robot = self.robots[i]
            if isinstance(robot, Robot):
                poses[robot.name] = tuple(robot.start)
            elif robot.start is None:
                parent = poses[robot.leaders[0]]
                poses[robot.name] = place_follower(parent, robot.targets[0], robot.targets[1], parent[2], robot.d)
            elif robot.start_frame == "leader":
                poses[robot.name] = pose_in_frame(poses[robot.leaders[0]], robot.start)
            else:
                poses[robot.name] = tuple(robot.start)
        return [poses[name] for name in self.names]

    def components(self) -> list[tuple[int, ...]]:
        if "_components" not in self.__dict__:
            object.__setattr__(self, "_components", self._find_components())
        return self.__dict__["_components"]

    def _find_components(self) -> list[tuple[int, ...]]:
        """The connected formations (weakly connected parts of the graph), each as robot
        indices parents-first; a lone robot is a component of its own."""
        names = self.names
        group = list(range(len(names)))

        def find(i):
            while group[i] != i:
                group[i] = group[group[i]]
                i = group[i]
            return i

        index = {name: i for i, name in enumerate(names)}
        for i, robot in enumerate(self.robots):
            for parent in robot.parents:
                group[find(i)] = find(index[parent])
        parts: dict[int, list[int]] = {}
        for i in self.order():
            parts.setdefault(find(i), []).append(i)
        return [tuple(p) for p in parts.values()]


def topological_order(robots) -> tuple[int, ...]:
    """Kahn's algorithm over the parent links, the lowest index first among the robots ready
    (so file order where links allow); ``FormationError`` names a cycle."""
    index = {r.name: i for i, r in enumerate(robots)}
    waiting = [0] * len(robots)
    children: dict[int, list[int]] = {}
    for i, robot in enumerate(robots):
        for parent in robot.parents:
            if parent in index:
                waiting[i] += 1
                children.setdefault(index[parent], []).append(i)
    ready = [i for i, count in enumerate(waiting) if count == 0]
    heapq.heapify(ready)
    done: list[int] = []
    while ready:
        i = heapq.heappop(ready)
        done.append(i)
        for child in children.get(i, ()):
            waiting[child] -= 1
            if waiting[child] == 0:
                heapq.heappush(ready, child)
    if len(done) < len(robots):
        placed = {robots[i].name for i in done}
        parents = {r.name: r.parents for r in robots}
        raise FormationError(None, "formation", f"the leader links form a cycle: {_find_cycle(parents, placed)}")
    return tuple(done)


def _find_cycle(parents: dict, placed: set) -> str:
    start = next(n for n in parents if n not in placed)
    path = [start]
    while True:
        nxt = next(p for p in parents[path[-1]] if p not in placed)
        if nxt in path:
            cycle = path[path.index(nxt):] + [nxt]
            return " -> ".join(cycle) + " (each follows the next)"
        path.append(nxt)


def check_graph(scenario: Scenario) -> None:
    """Every rule a simulable graph obeys; the first violation as ``FormationError``."""
    robots = scenario.robots
    names = [r.name for r in robots]
    for robot in robots:
        if isinstance(robot, Follower):
            _check_follower(robot, names, scenario)
    topological_order(robots)
    roots = scenario.roots
    if not roots:
        raise FormationError(None, "robots", "no leader: every robot follows another, so the links form a cycle")
    if scenario.piconet:
        if len(roots) != 1:
            raise FormationError(roots[1].name, "formation", f"piconet mode allows one leader (the master), got "
                                                             f"{len(roots)}: {', '.join(r.name for r in roots)}"[:300])
        count = len(robots) - 1
        if count > PICONET_SLAVES:
            raise FormationError(None, "piconet", f"a Bluetooth piconet allows at most {PICONET_SLAVES} followers "
                                                  f"(1 master + 7 active slaves), got {count}")


def _check_follower(robot: Follower, names: list[str], scenario: Scenario) -> None:
    if robot.law not in FORMATION_LAWS:
        raise FormationError(robot.name, "formation", f"unknown formation law {robot.law!r} "
                                                      f"(valid: {', '.join(FORMATION_LAWS)})")
    expected = 1 if robot.law == SEPARATION_BEARING else 2
    where = "leader" if expected == 1 else "leaders"
    if len(robot.leaders) != expected:
        raise FormationError(robot.name, where, f"{robot.law} needs {expected} leader(s), got {len(robot.leaders)}")
    for parent in robot.leaders:
        if parent == robot.name:
            raise FormationError(robot.name, where, "a robot cannot follow itself")
        if parent not in names:
            raise FormationError(robot.name, where, f"unknown robot {parent!r} (robots: {', '.join(names)})"[:300])
    if expected == 2 and robot.leaders[0] == robot.leaders[1]:
        raise FormationError(robot.name, where, f"the two leaders must differ, got {robot.leaders[0]!r} twice")
    if not (is_real(robot.d) and robot.d > 0):
        raise FormationError(robot.name, "d", f"the castor offset must be > 0 (G is singular at d = 0), got {robot.d!r}")
    try:
        follower_gains({"k1": robot.k1, "k2": robot.k2}, robot.law)
    except NonholoInputError as exc:
        raise FormationError(robot.name, "gains", str(exc)) from None
    if not all(is_real(v) for v in robot.targets):
        raise FormationError(robot.name, "l", f"targets must be finite numbers, got {robot.targets!r}")
    separations = robot.targets if robot.law == SEPARATION_SEPARATION else robot.targets[:1]
    for name, value in zip(robot.outputs, separations):
        if not value > 0:
            raise FormationError(robot.name, "l", f"separation {name} must be > 0 (the bearing is undefined at l = 0), "
                                                  f"got {value!r}")
    if robot.start is None and robot.law == SEPARATION_SEPARATION:
        raise FormationError(robot.name, "start", "an l-l follower needs a start pose (start or start_relative)")
    if robot.start is not None:
        object.__setattr__(robot, "start", _pose(robot.start, robot.name, "start"))
    if robot.start_frame not in ("world", "leader"):
        raise FormationError(robot.name, "start_frame", f"must be 'world' or 'leader', got {robot.start_frame!r}")
    _limits(robot)
    _check_changes(robot, scenario.duration)
    target_segments(robot)  # resolves bearing branches; ambiguous ±π changes are errors (spec §2.5)


def _check_changes(robot: Follower, duration: float) -> None:
    busy_until = -math.inf
    for j, change in enumerate(robot.changes):
        where = f"changes[{j}]"
        if not (is_real(change.at) and 0 <= change.at < duration):
            raise FormationError(robot.name, f"{where}.at", f"must be in [0, {duration:g}) s, got {change.at!r}")
        if change.at < busy_until:
            raise FormationError(robot.name, f"{where}.at", f"overlaps the previous change (busy until {busy_until:g} "
                                                            "s); list changes in time order, ramps finished")
        if change.mode not in CHANGE_MODES:
            raise FormationError(robot.name, f"{where}.mode", f"unknown mode {change.mode!r} (valid: step, ramp)")
        if change.direction not in DIRECTIONS:
            raise FormationError(robot.name, f"{where}.direction",
                                 f"unknown direction {change.direction!r} (valid: {', '.join(DIRECTIONS)})")
        if change.mode == "ramp" and not (is_real(change.duration) and change.duration > 0):
            raise FormationError(robot.name, f"{where}.duration", f"a ramp needs a duration > 0 s, got {change.duration!r}")
        if not change.targets:
            raise FormationError(robot.name, where, f"no new target (give one of: {', '.join(robot.outputs)})")
        for name, value in change.targets.items():
            if name not in robot.outputs:
                raise FormationError(robot.name, f"{where}.{name}",
                                     f"not an output of {robot.law} (outputs: {', '.join(robot.outputs)})")
            if not is_real(value) or (name != "phi" and value <= 0):
                raise FormationError(robot.name, f"{where}.{name}",
                                     f"must be a {'finite number' if name == 'phi' else 'separation > 0'}, got {value!r}")
        busy_until = change.at + (change.duration if change.mode == "ramp" else 0.0)
