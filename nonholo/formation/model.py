"""Formations as plain immutable data: leaders, followers, run-time changes, the graph.

A formation is a DAG of robots. *Leaders* (roots) track the scenario reference with one
of the tracking laws, or stabilise to a goal pose with a posture law. *Followers* keep
either a separation–bearing link (l–φ) to one parent or a separation–separation link
(l–l) to two parents (spec follower-posture.md §2–4). A parent may itself be a follower;
the simulator evaluates robots parents-first (``topological_order``) at every integrator
stage and passes each parent's actual computed (v, ω) down the graph (spec §4).

``piconet=True`` enforces the Bluetooth piconet limits of the thesis: one master (a
single leader) and at most 7 active slaves (followers).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from nonholo.sim.scenario import MAX_STEPS
from nonholo.control.registry import ControllerConfig
from nonholo.errors import NonholoInputError
from nonholo.formation.geometry import place_follower, pose_in_frame
from nonholo.references.base import Reference

SEPARATION_BEARING = "separation-bearing"
SEPARATION_SEPARATION = "separation-separation"
FORMATION_LAWS = (SEPARATION_BEARING, SEPARATION_SEPARATION)
OUTPUTS = {SEPARATION_BEARING: ("l", "phi"), SEPARATION_SEPARATION: ("l1", "l2")}
CHANGE_MODES = ("step", "ramp")
DIRECTIONS = ("shortest", "counterclockwise", "clockwise")
PICONET_SLAVES = 7
# |Δφ| this close to π is ambiguous under "shortest" (spec §2.5): the turn is decided by round-off.
AMBIGUOUS_TURN = 1e-6


class FormationError(NonholoInputError):
    """A formation that cannot be simulated; ``robot`` and ``field`` locate the problem
    (the scenario reader turns them into ``robots[i].field``)."""

    def __init__(self, robot: str | None, field: str, problem: str):
        self.robot, self.field, self.problem = robot, field, problem
        where = f"robot {robot!r}: {field}: " if robot is not None else (f"{field}: " if field else "")
        super().__init__(f"{where}{problem}")


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
class Leader:
    """A root robot: tracks the reference (tracking ``controller``) or, with ``goal`` set,
    stabilises to the goal pose (posture controller from ``nonholo.control.posture``)."""

    name: str
    controller: ControllerConfig
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    goal: tuple[float, float, float] | None = None
    v_max: float = math.inf
    omega_max: float = math.inf

    @property
    def posture(self) -> bool:
        return self.goal is not None


@dataclass(frozen=True)
class Follower:
    """An l–φ (``law`` = "separation-bearing", one leader, targets (l_d, φ_d)) or l–l
    ("separation-separation", two leaders, targets (l1_d, l2_d)) follower with castor
    offset ``d`` and gains k1, k2.

    Start: ``start`` as an axle pose (x, y, θ) in the world (``start_frame`` "world") or
    in the body frame of its (first) leader at t = 0 ("leader"); ``None`` places an l–φ
    follower exactly in formation with the leader's heading.
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


def separation_bearing(name, leader, l, phi, d=1.0, k1=1.0, k2=1.0, **options) -> Follower:
    """An l–φ follower of ``leader`` with targets l_d = ``l``, φ_d = ``phi``."""
    return Follower(name, SEPARATION_BEARING, (leader,), (float(l), float(phi)), d, k1, k2, **options)


def separation_separation(name, leaders, l, d=1.0, k1=1.0, k2=1.0, **options) -> Follower:
    """An l–l follower of ``leaders`` = (a, b) with targets ``l`` = (l1_d, l2_d)."""
    return Follower(name, SEPARATION_SEPARATION, tuple(leaders), (float(l[0]), float(l[1])), d, k1, k2, **options)


@dataclass(frozen=True)
class Formation:
    """Robots (leaders and followers) over ``duration`` seconds on the grid t_k = k·dt.

    ``reference`` is needed when a leader tracks one. ``substeps``: RK4 sub-steps per
    output step (None: automatic, from a pilot run's turn rates). ``method``: "rk4"
    (compiled, batch) or "solve_ivp" (scipy cross-check). ``sin_floor``: the l–l guard
    on |sin(γ1 − γ2)|.
    """

    robots: tuple
    reference: Reference | None = None
    duration: float | None = None
    dt: float = 0.01
    substeps: int | None = None
    method: str = "rk4"
    piconet: bool = False
    name: str = "formation"
    sin_floor: float = 1e-6

    def __post_init__(self):
        object.__setattr__(self, "robots", tuple(self.robots))
        duration = self.duration
        if duration is None and self.reference is not None:
            duration = self.reference.default_duration
        if duration is None:
            raise FormationError(None, "duration", "needed: posture leaders have no natural duration")
        if not (math.isfinite(duration) and duration > 0):
            raise FormationError(None, "duration", f"must be a positive number of seconds, got {duration!r}")
        object.__setattr__(self, "duration", float(duration))
        if not (math.isfinite(self.dt) and 0 < self.dt <= self.duration):
            raise FormationError(None, "dt", f"must be in (0, duration], got {self.dt!r}")
        if self.duration / self.dt > MAX_STEPS:
            raise FormationError(None, "dt", f"{self.dt:g} s gives {self.duration / self.dt:.3g} steps (at most "
                                 f"{MAX_STEPS:g}): use a larger dt")
        if self.method not in ("rk4", "solve_ivp"):
            raise FormationError(None, "method", f"unknown method {self.method!r} (valid: rk4, solve_ivp)")
        if self.substeps is not None and not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise FormationError(None, "substeps", f"must be a positive integer, got {self.substeps!r}")
        check_formation(self)
        from nonholo.formation.schedule import target_segments  # bearing branches of changes (spec §2.5)

        for follower in self.followers:
            target_segments(follower)

    @property
    def n_steps(self) -> int:
        return max(1, round(self.duration / self.dt))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.robots)

    @property
    def leaders(self) -> tuple[Leader, ...]:
        return tuple(r for r in self.robots if isinstance(r, Leader))

    @property
    def followers(self) -> tuple[Follower, ...]:
        return tuple(r for r in self.robots if isinstance(r, Follower))

    def robot(self, name: str):
        return self.robots[self.names.index(name)]

    def order(self) -> tuple[int, ...]:
        """Robot indices parents-first (stable: file order among ready robots)."""
        return topological_order(self.robots)

    def initial_poses(self) -> list[tuple[float, float, float]]:
        """Axle poses at t = 0, resolving leader-frame and in-formation starts parents-first."""
        poses: dict[str, tuple[float, float, float]] = {}
        for i in self.order():
            robot = self.robots[i]
            if isinstance(robot, Leader):
                poses[robot.name] = tuple(robot.start)
            elif robot.start is None:
                parent = poses[robot.leaders[0]]
                poses[robot.name] = place_follower(parent, robot.targets[0], robot.targets[1], parent[2], robot.d)
            elif robot.start_frame == "leader":
                poses[robot.name] = pose_in_frame(poses[robot.leaders[0]], robot.start)
            else:
                poses[robot.name] = tuple(robot.start)
        return [poses[name] for name in self.names]

    def structure(self) -> tuple:
        """What formations batched together must share (graph, laws, targets, grid)."""
        return (self.names, tuple(type(r).__name__ for r in self.robots),
                tuple((r.law, r.leaders, r.targets, r.changes) if isinstance(r, Follower)
                      else (r.controller.law, r.goal is not None) for r in self.robots),
                repr(self.reference.describe()) if self.reference is not None else None, self.duration, self.dt,
                self.method)


def topological_order(robots) -> tuple[int, ...]:
    """Kahn's algorithm over the leader links; ``FormationError`` names a cycle."""
    names = [r.name for r in robots]
    parents = {r.name: (r.leaders if isinstance(r, Follower) else ()) for r in robots}
    done: list[int] = []
    placed: set[str] = set()
    while len(done) < len(robots):
        ready = [i for i, name in enumerate(names) if name not in placed and all(p in placed for p in parents[name])]
        if not ready:
            raise FormationError(None, "formation", f"the leader links form a cycle: {_find_cycle(parents, placed)}")
        done.append(ready[0])
        placed.add(names[ready[0]])
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


def check_formation(formation: Formation) -> None:
    """Every rule a simulable formation obeys; the first violation as ``FormationError``."""
    robots = formation.robots
    names = [r.name for r in robots]
    if not robots:
        raise FormationError(None, "robots", "a formation needs at least one robot")
    for robot in robots:
        if names.count(robot.name) > 1:
            raise FormationError(robot.name, "name", "robot names must be unique")
    for robot in robots:
        if isinstance(robot, Follower):
            _check_follower(robot, names, formation)
    topological_order(robots)
    leaders = [r for r in robots if isinstance(r, Leader)]
    if not leaders:
        raise FormationError(None, "robots", "no leader: every robot follows another, so the links form a cycle")
    laws = {r.controller.law for r in leaders}
    if len(laws) > 1:
        raise FormationError(leaders[1].name, "controller",
                             f"all leaders of one formation must use the same controller; "
                             f"{leaders[0].name!r} uses {leaders[0].controller.name!r}")
    if any(not r.posture for r in leaders) and formation.reference is None:
        tracking = next(r for r in leaders if not r.posture)
        raise FormationError(tracking.name, "controller", "a tracking leader needs a [reference]")
    if formation.piconet:
        if len(leaders) != 1:
            raise FormationError(leaders[1].name, "formation",
                                 f"piconet mode allows one leader (the master), got {len(leaders)}: "
                                 f"{', '.join(r.name for r in leaders)}")
        count = len(robots) - 1
        if count > PICONET_SLAVES:
            raise FormationError(None, "piconet",
                                 f"a Bluetooth piconet allows at most {PICONET_SLAVES} followers "
                                 f"(1 master + 7 active slaves), got {count}")


def _check_follower(robot: Follower, names: list[str], formation: Formation) -> None:
    if robot.law not in FORMATION_LAWS:
        raise FormationError(robot.name, "formation", f"unknown formation law {robot.law!r} "
                                                      f"(valid: {', '.join(FORMATION_LAWS)})")
    expected = 1 if robot.law == SEPARATION_BEARING else 2
    field = "leader" if expected == 1 else "leaders"
    if len(robot.leaders) != expected:
        raise FormationError(robot.name, field, f"{robot.law} needs {expected} leader(s), got {len(robot.leaders)}")
    for parent in robot.leaders:
        if parent == robot.name:
            raise FormationError(robot.name, field, "a robot cannot follow itself")
        if parent not in names:
            raise FormationError(robot.name, field, f"unknown robot {parent!r} (robots: {', '.join(names)})")
    if expected == 2 and robot.leaders[0] == robot.leaders[1]:
        raise FormationError(robot.name, field, f"the two leaders must differ, got {robot.leaders[0]!r} twice")
    if not (math.isfinite(robot.d) and robot.d > 0):
        raise FormationError(robot.name, "d", f"the castor offset must be > 0 (G is singular at d = 0), got {robot.d!r}")
    for gain in ("k1", "k2"):
        value = getattr(robot, gain)
        if not (math.isfinite(value) and value > 0):
            raise FormationError(robot.name, f"gains.{gain}", f"must be > 0, got {value!r}")
    separations = robot.targets if robot.law == SEPARATION_SEPARATION else robot.targets[:1]
    for name, value in zip(robot.outputs, separations):
        if not (math.isfinite(value) and value > 0):
            raise FormationError(robot.name, "l", f"separation {name} must be > 0 (the bearing is undefined at l = 0), "
                                                  f"got {value!r}")
    if robot.start is None and robot.law == SEPARATION_SEPARATION:
        raise FormationError(robot.name, "start", "an l-l follower needs a start pose (start or start_relative)")
    if robot.start_frame not in ("world", "leader"):
        raise FormationError(robot.name, "start_frame", f"must be 'world' or 'leader', got {robot.start_frame!r}")
    _check_changes(robot, formation.duration)


def _check_changes(robot: Follower, duration: float) -> None:
    busy_until = -math.inf
    for j, change in enumerate(robot.changes):
        where = f"changes[{j}]"
        if not (math.isfinite(change.at) and 0 <= change.at < duration):
            raise FormationError(robot.name, f"{where}.at", f"must be in [0, {duration:g}) s, got {change.at!r}")
        if change.at < busy_until:
            raise FormationError(robot.name, f"{where}.at", f"overlaps the previous change (busy until {busy_until:g} s); "
                                                            "list changes in time order, ramps finished")
        if change.mode not in CHANGE_MODES:
            raise FormationError(robot.name, f"{where}.mode", f"unknown mode {change.mode!r} (valid: step, ramp)")
        if change.direction not in DIRECTIONS:
            raise FormationError(robot.name, f"{where}.direction",
                                 f"unknown direction {change.direction!r} (valid: {', '.join(DIRECTIONS)})")
        if change.mode == "ramp" and not (math.isfinite(change.duration) and change.duration > 0):
            raise FormationError(robot.name, f"{where}.duration", f"a ramp needs a duration > 0 s, got {change.duration!r}")
        if not change.targets:
            raise FormationError(robot.name, where, f"no new target (give one of: {', '.join(robot.outputs)})")
        for name, value in change.targets.items():
            if name not in robot.outputs:
                raise FormationError(robot.name, f"{where}.{name}",
                                     f"not an output of {robot.law} (outputs: {', '.join(robot.outputs)})")
            if not math.isfinite(value) or (name != "phi" and value <= 0):
                raise FormationError(robot.name, f"{where}.{name}", f"must be a {'finite number' if name == 'phi' else 'separation > 0'}, got {value!r}")
        busy_until = change.at + (change.duration if change.mode == "ramp" else 0.0)
