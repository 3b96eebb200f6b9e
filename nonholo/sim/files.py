"""Scenario files (TOML): parsing and validation with one-line errors.

Schema (every field optional unless marked)::

    [simulation]
    duration = 251.327     # s (default: the reference's natural duration)
    dt = 0.01              # s, output grid and integration step (or steps = N)
    substeps = 2           # RK4 sub-steps per step (default: automatic)
    control_period = 0.05  # s, sampled-data control with zero-order hold (multiple of dt)
    method = "rk4"         # or "solve_ivp"

    [reference]            # required
    kind = "eight"         # eight | line | sinusoid | circle | expression | waypoints
    direction = "forward"  # or "backward"
    ...                    # kind parameters (see REFERENCE_PARAMETERS)

    [[robots]]             # at least one
    name = "leader"
    start = [0.0, 0.0, 0.0]
    controller = "dynamic-feedback"
    gains = { kp = 1.0, kd = 0.7 }
    variant = "linear"     # cascaded only: "linear" (Eq 4.24) or "sine" (Eq 4.25)
    v_max = 2.0            # optional actuator limits
    omega_max = 3.0

The same reader reads followers, posture roots and formation options (one schema; angles
are numbers in radians or expressions of pi)::

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

    [network]               # the link model of a sampled-data run (needs control_period)
    seed = 7                # draws of each link's delays and losses (spec fleet.md §3-4)
    delay = 0.02            # s, fixed; jitter (s) uniform on top; loss probability
    jitter = 0.01
    loss = 0.05
    stale_after = 0.1       # follower watchdog (§5): stop beyond this age, resume after
    resume_after = 3        # this many fresh states; decel_v, decel_omega the ramp
    [[network.links]]       # per-link overrides
    parent = "leader"
    child = "f1"
    delay = 0.04

(The fleet reads the rest of ``[network]``: transport, keys, addresses, failover; see
``nonholo.fleet.config``.)
"""
from __future__ import annotations

import math
from pathlib import Path

from nonholo import references
from nonholo.control.posture import POSTURE_CONTROLLERS
from nonholo.control.registry import CONTROLLERS
from nonholo.errors import NonholoInputError, ScenarioError
from nonholo.errors import ExpressionError, FormationError
from nonholo.tomlfile import describe_value
from nonholo.sim.links import read_link_settings
from nonholo.sim.scenario import (CHANGE_MODES, DIRECTIONS, FORMATION_LAWS, METHODS, OUTPUTS, SEPARATION_BEARING,
                                  Change, Follower, Robot, Scenario)

REFERENCE_PARAMETERS = {
    "eight": {"amplitude_x": "number", "amplitude_y": "number", "period_x": "number", "period_y": "number"},
    "line": {"speed": "number", "heading": "number", "start": "pair"},
    "sinusoid": {"speed": "number", "amplitude": "number", "period": "number"},
    "circle": {"radius": "number", "period": "number", "center": "pair"},
    "expression": {"x": "formula", "y": "formula", "parameters": "table"},
    "waypoints": {"points": "points", "boundary": "string"},
}
REQUIRED_REFERENCE_PARAMETERS = {"expression": ("x", "y"), "waypoints": ("points",)}
SIMULATION_FIELDS = {"duration", "dt", "steps", "substeps", "control_period", "method"}
ROBOT_FIELDS = {"name", "start", "controller", "gains", "variant", "v_max", "omega_max", "goal"}
FOLLOWER_FIELDS = {"name", "formation", "leader", "leaders", "l", "phi", "d", "gains", "start", "start_relative",
                   "changes", "v_max", "omega_max"}
CHANGE_FIELDS = {"at", "l", "phi", "l1", "l2", "mode", "duration", "direction"}
FORMATION_FIELDS = {"piconet", "sin_floor"}


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


KEY_LIMIT = 40


def _key(name: str) -> str:
    """A field name from the file, shortened for an error line."""
    return name if len(name) <= KEY_LIMIT else name[:KEY_LIMIT - 3] + "..."


class _Reader:
    """Validates one parsed file; every error names the file and the field."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, field: str, problem: str):
        raise ScenarioError(self.source, field, problem)

    def table(self, data, field: str, allowed: set[str] | None = None) -> dict:
        if not isinstance(data, dict):
            self.fail(field, f"expected a table, got {describe_value(data)}")
        if allowed is not None:
            unknown = sorted(set(data) - allowed)
            if unknown:
                key = _key(unknown[0])
                self.fail(f"{field}.{key}" if field else key,
                          f"unknown field (expected one of: {', '.join(sorted(allowed))})")
        return data

    def number(self, value, field: str, positive: bool = False) -> float:
        if not _is_number(value):
            self.fail(field, f"expected a finite number, got {describe_value(value)}")
        if positive and value <= 0:
            self.fail(field, f"expected a positive number, got {describe_value(value, typed=False)}")
        return float(value)

    def numbers(self, value, field: str, count: int) -> tuple[float, ...]:
        if not (isinstance(value, list) and len(value) == count and all(_is_number(v) for v in value)):
            self.fail(field, f"expected a list of {count} finite numbers, got {describe_value(value)}")
        return tuple(float(v) for v in value)

    def string(self, value, field: str, choices=None) -> str:
        if not isinstance(value, str):
            self.fail(field, f"expected a string, got {describe_value(value)}")
        if choices is not None and value not in choices:
            self.fail(field, f"unknown value {describe_value(value, typed=False)} (valid: {', '.join(choices)})")
        return value

    def reference(self, data) -> references.Reference:
        data = dict(self.table(data, "reference"))
        if "kind" not in data:
            self.fail("reference.kind", f"missing (valid: {', '.join(references.KINDS)})")
        kind = self.string(data.pop("kind"), "reference.kind", references.KINDS)
        direction = references.DIRECTIONS[self.string(data.pop("direction", "forward"), "reference.direction",
                                                      tuple(references.DIRECTIONS))]
        spec = REFERENCE_PARAMETERS[kind]
        self.table(data, "reference", set(spec))
        for name in REQUIRED_REFERENCE_PARAMETERS.get(kind, ()):
            if name not in data:
                self.fail(f"reference.{name}", f"missing: a {kind} reference needs {' and '.join(REQUIRED_REFERENCE_PARAMETERS[kind])}")
        params = {name: self._parameter(value, f"reference.{name}", spec[name]) for name, value in data.items()}
        try:
            if kind == "expression":
                return references.expression(params["x"], params["y"], direction=direction,
                                             parameters=params.get("parameters"))
            if kind == "waypoints":
                return references.waypoints(params["points"], params.get("boundary", "not-a-knot"), direction)
            return references.THESIS_TESTS[kind](direction=direction, **params)
        except ScenarioError as exc:   # the reference names its own field: point to it in the file
            self.fail(f"reference.{exc.field}" if exc.field else "reference", exc.problem)
        except ValueError as exc:   # NonholoInputError included; a formula's own error names it
            formula = getattr(exc, "formula", None)
            self.fail(f"reference.{formula}" if formula in data else "reference", str(exc))

    def _parameter(self, value, field: str, kind: str):
        if kind == "number":
            return self.number(value, field)
        if kind == "pair":
            return self.numbers(value, field, 2)
        if kind == "formula" or kind == "string":
            return self.string(value, field)
        if kind == "table":
            table = self.table(value, field)
            return {name: self.number(v, f"{field}.{name}") for name, v in table.items()}
        if not (isinstance(value, list) and len(value) >= 2):
            self.fail(field, f"expected a list of at least two [t, x, y] points, got {describe_value(value)}")
        return [self.numbers(p, f"{field}[{i}]", 3) for i, p in enumerate(value)]

    def angle(self, value, field: str) -> float:
        """A number (radians) or an expression such as "4*pi/3"."""
        if isinstance(value, str):
            from nonholo.expressions import parse_expression

            try:
                number = float(parse_expression(value, {}))
            except (ExpressionError, TypeError) as exc:
                self.fail(field, f"expected a number or an expression of pi, got {describe_value(value)} ({exc})")
            if not math.isfinite(number):
                self.fail(field, f"expected a finite angle, got {describe_value(value)}")
            return number
        return self.number(value, field)

    def pose(self, value, field: str) -> tuple[float, float, float]:
        if not (isinstance(value, list) and len(value) == 3):
            self.fail(field, f"expected a list of 3 finite numbers [x, y, theta], got {describe_value(value)}")
        return self.number(value[0], f"{field}[0]"), self.number(value[1], f"{field}[1]"), \
            self.angle(value[2], f"{field}[2]")

    def limits(self, data, where: str) -> dict:
        return {k: self.number(data[k], f"{where}.{k}", positive=True) for k in ("v_max", "omega_max") if k in data}

    def robot(self, data, index: int) -> Robot:
        """A root: tracking (``controller``, ``gains``, ``variant``) or, with ``goal``, posture."""
        where = f"robots[{index}]"
        data = self.table(data, where, ROBOT_FIELDS)
        name = self.string(data.get("name", f"robot{index}"), f"{where}.name")
        posture = "goal" in data
        family = {**CONTROLLERS, **POSTURE_CONTROLLERS}   # (a law without its goal, or the reverse: ``Robot`` says)
        controller_name = self.string(data.get("controller", "polar" if posture else "dynamic-feedback"),
                                      f"{where}.controller", tuple(family))
        spec = family[controller_name]
        gains = dict(self.table(data.get("gains", {}), f"{where}.gains"))
        variant = gains.pop("variant", None) if isinstance(gains.get("variant"), str) else None
        variant = self.string(data.get("variant", variant or spec.variants[0]), f"{where}.variant", spec.variants)
        for gain, value in gains.items():
            if gain not in spec.accepted_gains:
                self.fail(f"{where}.gains.{_key(gain)}",
                          f"unknown gain for {controller_name} (gains: {', '.join(spec.accepted_gains)})")
            self.number(value, f"{where}.gains.{_key(gain)}")
        try:
            config = spec.configure(gains, variant)
        except NonholoInputError as exc:
            self.fail(f"{where}.gains", str(exc))
        goal = self.pose(data["goal"], f"{where}.goal") if posture else None
        try:
            return Robot(name, config, self.pose(data.get("start", [0.0, 0.0, 0.0]), f"{where}.start"),
                         goal=goal, **self.limits(data, where))
        except FormationError as exc:
            self.fail(f"{where}.{exc.field}", exc.problem)

    def follower(self, data, index: int) -> Follower:
        where = f"robots[{index}]"
        self.table(data, where, FOLLOWER_FIELDS)
        name = self.string(data.get("name", f"robot{index}"), f"{where}.name")
        law = self.string(data["formation"], f"{where}.formation", FORMATION_LAWS)
        if law == SEPARATION_BEARING:
            for field in ("leader", "l", "phi"):
                if field not in data:
                    self.fail(f"{where}.{field}", "missing: a separation-bearing follower needs leader, l and phi")
            if "leaders" in data:
                self.fail(f"{where}.leaders", "a separation-bearing follower has one leader: use leader = \"name\"")
            leaders = (self.string(data["leader"], f"{where}.leader"),)
            targets = (self.number(data["l"], f"{where}.l"), self.angle(data["phi"], f"{where}.phi"))
        else:
            for field in ("leaders", "l"):
                if field not in data:
                    self.fail(f"{where}.{field}", "missing: a separation-separation follower needs leaders = [a, b] and l = [l1, l2]")
            for field in ("leader", "phi"):
                if field in data:
                    self.fail(f"{where}.{field}", "not a field of a separation-separation follower (it has leaders and l = [l1, l2])")
            value = data["leaders"]
            if not (isinstance(value, list) and len(value) == 2 and all(isinstance(v, str) for v in value)):
                self.fail(f"{where}.leaders", f"expected two robot names [a, b], got {describe_value(value)}")
            leaders = tuple(value)
            targets = self.numbers(data["l"], f"{where}.l", 2)
        gains = self.table(data.get("gains", {}), f"{where}.gains", {"k1", "k2"})
        k = {g: self.number(gains.get(g, 1.0), f"{where}.gains.{g}") for g in ("k1", "k2")}
        d = self.number(data.get("d", 1.0), f"{where}.d")
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
        self.table(data, where, CHANGE_FIELDS)
        if "at" not in data:
            self.fail(f"{where}.at", "missing: the time of the change (s)")
        targets = {}
        for name in ("l", "phi", "l1", "l2"):
            if name in data:
                if name not in outputs:
                    self.fail(f"{where}.{name}", f"not an output of this follower (outputs: {', '.join(outputs)})")
                targets[name] = self.angle(data[name], f"{where}.{name}") if name == "phi" else \
                    self.number(data[name], f"{where}.{name}")
        mode = self.string(data.get("mode", "step"), f"{where}.mode", CHANGE_MODES)
        duration = self.number(data["duration"], f"{where}.duration", positive=True) if "duration" in data else 0.0
        if mode == "ramp" and "duration" not in data:
            self.fail(f"{where}.duration", "missing: a ramp needs its duration (s)")
        if mode == "step" and "duration" in data:
            self.fail(f"{where}.duration", "only a ramp has a duration (mode = \"ramp\")")
        direction = self.string(data.get("direction", "shortest"), f"{where}.direction", DIRECTIONS)
        return Change(self.number(data["at"], f"{where}.at"), targets, mode, duration, direction)

    def scenario(self, data, name: str) -> Scenario:
        # [network]: the simulator reads its link model (nonholo.sim.links.FIELDS), the fleet all
        # of it (nonholo.fleet.config).
        data = self.table(data, "", {"simulation", "reference", "robots", "name", "formation", "network"})
        simulation = self.table(data.get("simulation", {}), "simulation", SIMULATION_FIELDS)
        options = self.table(data.get("formation", {}), "formation", FORMATION_FIELDS)
        reference = self.reference(data["reference"]) if "reference" in data else None
        robots_data = data.get("robots")
        if not isinstance(robots_data, list) or not robots_data:
            self.fail("robots", "expected at least one [[robots]] table")
        robots = []
        for i, robot in enumerate(robots_data):
            robot = self.table(robot, f"robots[{i}]")
            robots.append(self.follower(robot, i) if "formation" in robot else self.robot(robot, i))
            first = next(j for j, other in enumerate(robots) if other.name == robots[-1].name)
            if first < i:
                self.fail(f"robots[{i}].name", f"{robots[-1].name!r} is already the name of robots[{first}]: "
                                               "robot names must be unique")
        if reference is None and any(isinstance(r, Robot) and not r.posture for r in robots):
            self.fail("reference", "missing table [reference] (a robot tracks it)")
        kwargs = {}
        if "duration" in simulation:
            kwargs["duration"] = self.number(simulation["duration"], "simulation.duration", positive=True)
        elif reference is None or reference.default_duration is None:
            self.fail("simulation.duration", "missing: needed when no reference gives a natural duration")
        for field_name in ("dt", "control_period"):
            if field_name in simulation:
                kwargs[field_name] = self.number(simulation[field_name], f"simulation.{field_name}", positive=True)
        for field_name in ("steps", "substeps"):
            if field_name in simulation:
                value = simulation[field_name]
                if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
                    self.fail(f"simulation.{field_name}", f"expected a positive integer, got {describe_value(value)}")
                kwargs[field_name] = value
        if "dt" in simulation and "steps" in simulation:
            self.fail("simulation.steps", "give dt or steps, not both")
        if "method" in simulation:
            kwargs["method"] = self.string(simulation["method"], "simulation.method", METHODS)
        if "piconet" in options:
            if not isinstance(options["piconet"], bool):
                self.fail("formation.piconet", f"expected true or false, got {describe_value(options['piconet'])}")
            kwargs["piconet"] = options["piconet"]
        if "sin_floor" in options:
            kwargs["sin_floor"] = self.number(options["sin_floor"], "formation.sin_floor", positive=True)
        names = [r.name for r in robots]
        network = read_link_settings(self.table(data.get("network", {}), "network"),
                                     {(p, r.name) for r in robots for p in r.parents}, self.fail)
        # kept when given even without delay or loss: its seed and watchdog are the run's
        # (a Monte-Carlo over network.delay draws with them); ideal links simulate as none
        kwargs["network"] = network if "network" in data else None
        try:
            return Scenario(reference, robots, name=self.string(data.get("name", name), "name"), **kwargs)
        except FormationError as exc:
            if exc.robot is not None and exc.robot in names:
                self.fail(f"robots[{names.index(exc.robot)}].{exc.field}", exc.problem)
            field = {"formation": "robots", "piconet": "formation.piconet", "robots": "robots",
                     "sin_floor": "formation.sin_floor", "network": "network"}.get(exc.field, f"simulation.{exc.field}")
            self.fail(field, exc.problem)
        except NonholoInputError as exc:
            self.fail("simulation", str(exc))


def parse_scenario(text: str, source: str = "<scenario>", name: str = "scenario") -> Scenario:
    """A Scenario from TOML text; ``ScenarioError`` (one line) on any problem."""
    from nonholo.errors import InputFileError
    from nonholo.tomlfile import parse_toml

    try:
        data = parse_toml(text, source)
    except InputFileError as exc:
        raise ScenarioError(source, "", exc.problem) from None
    return _Reader(source).scenario(data, name)


def load_scenario(path) -> Scenario:
    """A Scenario from a TOML file, read within the limits of ``nonholo.tomlfile``."""
    from nonholo.errors import InputFileError
    from nonholo.tomlfile import read_toml

    path = Path(path)
    try:
        data = read_toml(path)
    except InputFileError as exc:
        raise ScenarioError(str(path), "", exc.problem) from None
    return _Reader(str(path)).scenario(data, path.stem)
