"""Formation and posture scenario files: the core schema (``nonholo.sim.files``) extended
with followers and posture leaders. A file is a formation file when one of its
``[[robots]]`` has ``formation`` or ``goal``::

    name = "formation-circle"
    [simulation]
    duration = 125.66       # s (default: the reference's natural duration; required without one)
    dt = 0.01               # or steps = N
    substeps = 4            # optional; default: planned from a pilot run
    method = "rk4"          # or "solve_ivp"

    [formation]             # optional
    piconet = true          # one leader, at most 7 followers (Bluetooth piconet)
    sin_floor = 1e-6        # l-l guard on |sin(γ1 − γ2)|

    [reference]             # needed when a leader tracks a reference
    kind = "circle"

    [[robots]]              # a tracking leader: the core robot fields
    name = "leader"
    controller = "dynamic-feedback"
    start = [0, 0, "pi/2"]

    [[robots]]              # a posture leader instead: goal + posture controller
    name = "parker"
    goal = [0, 0, 0]
    controller = "polar"    # time-varying | polar | dynamic-feedback-posture
    gains = { k1 = 1, k2 = 3, k3 = 2 }

    [[robots]]              # an l-φ follower
    name = "f1"
    formation = "separation-bearing"
    leader = "leader"
    l = 2.0
    phi = "pi/3"            # angles: numbers (radians) or expressions of pi
    d = 1.0
    gains = { k1 = 1, k2 = 1 }
    start_relative = [-4, 0, 0]   # axle pose in the leader's body frame (or start = [x, y, θ])

    [[robots.changes]]      # run-time formation change (thesis Eq 5.9)
    at = 100
    phi = "4*pi/3"
    mode = "step"           # or "ramp" with duration = T
    direction = "counterclockwise"   # shortest | counterclockwise | clockwise

    [[robots]]              # an l-l follower
    name = "f2"
    formation = "separation-separation"
    leaders = ["leader", "f1"]
    l = [2.0, 2.0]
    start_relative = [-3, -2, 0]     # in the frame of the first leader
"""
from __future__ import annotations

import math

from nonholo.control.posture import POSTURE_CONTROLLERS
from nonholo.errors import ExpressionError, NonholoInputError
from nonholo.formation.model import (CHANGE_MODES, DIRECTIONS, FORMATION_LAWS, OUTPUTS, SEPARATION_BEARING, Change,
                                     Follower, Formation, FormationError, Leader)

FOLLOWER_FIELDS = {"name", "formation", "leader", "leaders", "l", "phi", "d", "gains", "start", "start_relative",
                   "changes", "v_max", "omega_max"}
POSTURE_FIELDS = {"name", "start", "controller", "gains", "goal", "v_max", "omega_max"}
CHANGE_FIELDS = {"at", "l", "phi", "l1", "l2", "mode", "duration", "direction"}
SIMULATION_FIELDS = {"duration", "dt", "steps", "substeps", "method"}
FORMATION_FIELDS = {"piconet", "sin_floor"}


def is_formation_data(data) -> bool:
    """True if a parsed scenario has followers or posture leaders."""
    robots = data.get("robots") if isinstance(data, dict) else None
    return isinstance(robots, list) and any(isinstance(r, dict) and ("formation" in r or "goal" in r) for r in robots)


class FormationReader:
    """Reads a formation file with the core reader's checks and one-line errors."""

    def __init__(self, reader):
        self.core = reader

    def fail(self, field: str, problem: str):
        self.core.fail(field, problem)

    def angle(self, value, field: str) -> float:
        """A number (radians) or an expression such as "4*pi/3"."""
        if isinstance(value, str):
            from nonholo.expressions import parse_expression

            try:
                number = float(parse_expression(value, {}))
            except (ExpressionError, TypeError) as exc:
                self.fail(field, f"expected a number or an expression of pi, got {value!r} ({exc})")
            if not math.isfinite(number):
                self.fail(field, f"expected a finite angle, got {value!r}")
            return number
        return self.core.number(value, field)

    def pose(self, value, field: str) -> tuple[float, float, float]:
        if not (isinstance(value, list) and len(value) == 3):
            self.fail(field, f"expected [x, y, theta], got {value!r}")
        return self.core.number(value[0], f"{field}[0]"), self.core.number(value[1], f"{field}[1]"), \
            self.angle(value[2], f"{field}[2]")

    def limits(self, data, where: str) -> dict:
        return {k: self.core.number(data[k], f"{where}.{k}", positive=True) for k in ("v_max", "omega_max") if k in data}

    def leader(self, data, index: int) -> Leader:
        where = f"robots[{index}]"
        if "goal" not in data:
            robot = self.core.robot({k: v for k, v in data.items() if k != "start"} | {"start": list(self.pose(data.get("start", [0, 0, 0]), f"{where}.start"))}, index)
            return Leader(robot.name, robot.controller, robot.start, None, robot.v_max, robot.omega_max)
        self.core.table(data, where, POSTURE_FIELDS)
        name = self.core.string(data.get("name", f"robot{index}"), f"{where}.name")
        controller_name = self.core.string(data.get("controller", "polar"), f"{where}.controller", tuple(POSTURE_CONTROLLERS))
        spec = POSTURE_CONTROLLERS[controller_name]
        gains = dict(self.core.table(data.get("gains", {}), f"{where}.gains"))
        for gain, value in gains.items():
            if gain not in spec.accepted_gains:
                self.fail(f"{where}.gains.{gain}", f"unknown gain for {controller_name} (gains: {', '.join(spec.accepted_gains)})")
            self.core.number(value, f"{where}.gains.{gain}")
        try:
            config = spec.configure(gains)
        except NonholoInputError as exc:
            self.fail(f"{where}.gains", str(exc))
        return Leader(name, config, self.pose(data.get("start", [0, 0, 0]), f"{where}.start"),
                      self.pose(data["goal"], f"{where}.goal"), **self.limits(data, where))

    def follower(self, data, index: int) -> Follower:
        where = f"robots[{index}]"
        self.core.table(data, where, FOLLOWER_FIELDS)
        name = self.core.string(data.get("name", f"robot{index}"), f"{where}.name")
        law = self.core.string(data["formation"], f"{where}.formation", FORMATION_LAWS)
        if law == SEPARATION_BEARING:
            for field in ("leader", "l", "phi"):
                if field not in data:
                    self.fail(f"{where}.{field}", "missing: a separation-bearing follower needs leader, l and phi")
            if "leaders" in data:
                self.fail(f"{where}.leaders", "a separation-bearing follower has one leader: use leader = \"name\"")
            leaders = (self.core.string(data["leader"], f"{where}.leader"),)
            targets = (self.core.number(data["l"], f"{where}.l"), self.angle(data["phi"], f"{where}.phi"))
        else:
            for field in ("leaders", "l"):
                if field not in data:
                    self.fail(f"{where}.{field}", "missing: a separation-separation follower needs leaders = [a, b] and l = [l1, l2]")
            for field in ("leader", "phi"):
                if field in data:
                    self.fail(f"{where}.{field}", "not a field of a separation-separation follower (it has leaders and l = [l1, l2])")
            value = data["leaders"]
            if not (isinstance(value, list) and len(value) == 2 and all(isinstance(v, str) for v in value)):
                self.fail(f"{where}.leaders", f"expected two robot names [a, b], got {value!r}")
            leaders = tuple(value)
            targets = self.core.numbers(data["l"], f"{where}.l", 2)
        gains = self.core.table(data.get("gains", {}), f"{where}.gains", {"k1", "k2"})
        k = {g: self.core.number(gains.get(g, 1.0), f"{where}.gains.{g}") for g in ("k1", "k2")}
        d = self.core.number(data.get("d", 1.0), f"{where}.d")
        if "start" in data and "start_relative" in data:
            self.fail(f"{where}.start_relative", "give start (world) or start_relative (leader frame), not both")
        start, frame = None, "world"
        if "start" in data:
            start = self.pose(data["start"], f"{where}.start")
        elif "start_relative" in data:
            start, frame = self.pose(data["start_relative"], f"{where}.start_relative"), "leader"
        changes_data = data.get("changes", [])
        if not isinstance(changes_data, list):
            self.fail(f"{where}.changes", "expected [[robots.changes]] tables")
        changes = tuple(self.change(c, f"{where}.changes[{j}]", OUTPUTS[law]) for j, c in enumerate(changes_data))
        return Follower(name, law, leaders, targets, d, k["k1"], k["k2"], start, frame, changes, **self.limits(data, where))

    def change(self, data, where: str, outputs) -> Change:
        self.core.table(data, where, CHANGE_FIELDS)
        if "at" not in data:
            self.fail(f"{where}.at", "missing: the time of the change (s)")
        targets = {}
        for name in ("l", "phi", "l1", "l2"):
            if name in data:
                if name not in outputs:
                    self.fail(f"{where}.{name}", f"not an output of this follower (outputs: {', '.join(outputs)})")
                targets[name] = self.angle(data[name], f"{where}.{name}") if name == "phi" else \
                    self.core.number(data[name], f"{where}.{name}")
        mode = self.core.string(data.get("mode", "step"), f"{where}.mode", CHANGE_MODES)
        duration = self.core.number(data["duration"], f"{where}.duration", positive=True) if "duration" in data else 0.0
        if mode == "ramp" and "duration" not in data:
            self.fail(f"{where}.duration", "missing: a ramp needs its duration (s)")
        if mode == "step" and "duration" in data:
            self.fail(f"{where}.duration", "only a ramp has a duration (mode = \"ramp\")")
        direction = self.core.string(data.get("direction", "shortest"), f"{where}.direction", DIRECTIONS)
        return Change(self.core.number(data["at"], f"{where}.at"), targets, mode, duration, direction)

    def formation(self, data, name: str) -> Formation:
        core = self.core
        core.table(data, "", {"simulation", "reference", "robots", "name", "formation"})
        simulation = core.table(data.get("simulation", {}), "simulation", SIMULATION_FIELDS)
        options = core.table(data.get("formation", {}), "formation", FORMATION_FIELDS)
        reference = core.reference(data["reference"]) if "reference" in data else None
        robots_data = data["robots"]
        robots = []
        for i, robot in enumerate(robots_data):
            robot = core.table(robot, f"robots[{i}]")
            robots.append(self.follower(robot, i) if "formation" in robot else self.leader(robot, i))
        kwargs = {}
        if "duration" in simulation:
            kwargs["duration"] = core.number(simulation["duration"], "simulation.duration", positive=True)
        elif reference is None or reference.default_duration is None:
            self.fail("simulation.duration", "missing: needed when no reference gives a natural duration")
        if "dt" in simulation and "steps" in simulation:
            self.fail("simulation.steps", "give dt or steps, not both")
        if "dt" in simulation:
            kwargs["dt"] = core.number(simulation["dt"], "simulation.dt", positive=True)
        for field in ("steps", "substeps"):
            value = simulation.get(field)
            if value is not None and not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
                self.fail(f"simulation.{field}", f"expected a positive integer, got {value!r}")
        if "steps" in simulation:
            duration = kwargs.get("duration", reference.default_duration if reference else None)
            kwargs["dt"] = duration / simulation["steps"]
        if "substeps" in simulation:
            kwargs["substeps"] = simulation["substeps"]
        if "method" in simulation:
            kwargs["method"] = core.string(simulation["method"], "simulation.method", ("rk4", "solve_ivp"))
        if "piconet" in options:
            if not isinstance(options["piconet"], bool):
                self.fail("formation.piconet", f"expected true or false, got {options['piconet']!r}")
            kwargs["piconet"] = options["piconet"]
        if "sin_floor" in options:
            kwargs["sin_floor"] = core.number(options["sin_floor"], "formation.sin_floor", positive=True)
        names = [r.name for r in robots]
        try:
            return Formation(robots, reference, name=core.string(data.get("name", name), "name"), **kwargs)
        except FormationError as exc:
            if exc.robot is not None and exc.robot in names:
                self.fail(f"robots[{names.index(exc.robot)}].{exc.field}", exc.problem)
            field = {"formation": "robots", "piconet": "formation.piconet", "robots": "robots"}.get(exc.field, f"simulation.{exc.field}")
            self.fail(field, exc.problem)


def read_formation(reader, data, name: str) -> Formation:
    """The Formation of a parsed file (``reader``: the core ``_Reader`` of the file)."""
    return FormationReader(reader).formation(data, name)
