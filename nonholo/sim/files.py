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

A file whose robots include followers (``formation = ...``) or posture leaders
(``goal = [x, y, theta]``) is a formation file: see ``nonholo.formation.files`` for the
extended schema; ``parse_scenario`` then returns a ``nonholo.formation.Formation``.
"""
from __future__ import annotations

import math
import tomllib
from pathlib import Path

from nonholo import references
from nonholo.control.registry import CONTROLLERS
from nonholo.errors import NonholoInputError, ScenarioError
from nonholo.sim.scenario import METHODS, Robot, Scenario

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
ROBOT_FIELDS = {"name", "start", "controller", "gains", "variant", "v_max", "omega_max"}


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _describe(value) -> str:
    return f"{type(value).__name__} {value!r}" if not isinstance(value, (dict, list)) else type(value).__name__


class _Reader:
    """Validates one parsed file; every error names the file and the field."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, field: str, problem: str):
        raise ScenarioError(self.source, field, problem)

    def table(self, data, field: str, allowed: set[str] | None = None) -> dict:
        if not isinstance(data, dict):
            self.fail(field, f"expected a table, got {_describe(data)}")
        if allowed is not None:
            unknown = sorted(set(data) - allowed)
            if unknown:
                self.fail(f"{field}.{unknown[0]}" if field else unknown[0],
                          f"unknown field (expected one of: {', '.join(sorted(allowed))})")
        return data

    def number(self, value, field: str, positive: bool = False) -> float:
        if not _is_number(value):
            self.fail(field, f"expected a finite number, got {_describe(value)}")
        if positive and value <= 0:
            self.fail(field, f"expected a positive number, got {value!r}")
        return float(value)

    def numbers(self, value, field: str, count: int) -> tuple[float, ...]:
        if not (isinstance(value, list) and len(value) == count and all(_is_number(v) for v in value)):
            self.fail(field, f"expected a list of {count} finite numbers, got {value!r}")
        return tuple(float(v) for v in value)

    def string(self, value, field: str, choices=None) -> str:
        if not isinstance(value, str):
            self.fail(field, f"expected a string, got {_describe(value)}")
        if choices is not None and value not in choices:
            self.fail(field, f"unknown value {value!r} (valid: {', '.join(choices)})")
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
        except NonholoInputError as exc:
            self.fail("reference", str(exc))
        except ValueError as exc:
            self.fail("reference", str(exc))

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
            self.fail(field, f"expected a list of at least two [t, x, y] points, got {_describe(value)}")
        return [self.numbers(p, f"{field}[{i}]", 3) for i, p in enumerate(value)]

    def robot(self, data, index: int) -> Robot:
        where = f"robots[{index}]"
        data = self.table(data, where, ROBOT_FIELDS)
        name = self.string(data.get("name", f"robot{index}"), f"{where}.name")
        start = self.numbers(data.get("start", [0.0, 0.0, 0.0]), f"{where}.start", 3)
        controller_name = self.string(data.get("controller", "dynamic-feedback"), f"{where}.controller",
                                      tuple(CONTROLLERS))
        spec = CONTROLLERS[controller_name]
        gains = dict(self.table(data.get("gains", {}), f"{where}.gains"))
        variant = gains.pop("variant", None) if isinstance(gains.get("variant"), str) else None
        variant = self.string(data.get("variant", variant or spec.variants[0]), f"{where}.variant", spec.variants)
        for gain, value in gains.items():
            if gain not in spec.accepted_gains:
                self.fail(f"{where}.gains.{gain}",
                          f"unknown gain for {controller_name} (gains: {', '.join(spec.accepted_gains)})")
            self.number(value, f"{where}.gains.{gain}")
        limits = {k: self.number(data[k], f"{where}.{k}", positive=True) for k in ("v_max", "omega_max") if k in data}
        try:
            config = spec.configure(gains, variant)
        except NonholoInputError as exc:
            self.fail(f"{where}.gains", str(exc))
        return Robot(name, config, start, **limits)

    def scenario(self, data, name: str) -> Scenario:
        from nonholo.formation.files import is_formation_data, read_formation

        if is_formation_data(data):  # followers or posture leaders: nonholo.formation.files
            return read_formation(self, data, name)
        data = self.table(data, "", {"simulation", "reference", "robots", "name"})
        simulation = self.table(data.get("simulation", {}), "simulation", SIMULATION_FIELDS)
        if "reference" not in data:
            self.fail("reference", "missing table [reference]")
        reference = self.reference(data["reference"])
        robots_data = data.get("robots")
        if not isinstance(robots_data, list) or not robots_data:
            self.fail("robots", "expected at least one [[robots]] table")
        robots = [self.robot(r, i) for i, r in enumerate(robots_data)]
        kwargs = {}
        for field_name in ("duration", "dt", "control_period"):
            if field_name in simulation:
                kwargs[field_name] = self.number(simulation[field_name], f"simulation.{field_name}", positive=True)
        for field_name in ("steps", "substeps"):
            if field_name in simulation:
                value = simulation[field_name]
                if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
                    self.fail(f"simulation.{field_name}", f"expected a positive integer, got {_describe(value)}")
                kwargs[field_name] = value
        if "method" in simulation:
            kwargs["method"] = self.string(simulation["method"], "simulation.method", METHODS)
        try:
            return Scenario(reference, robots, name=self.string(data.get("name", name), "name"), **kwargs)
        except NonholoInputError as exc:
            self.fail("simulation", str(exc))


def parse_scenario(text: str, source: str = "<scenario>", name: str = "scenario") -> Scenario:
    """A Scenario (a ``nonholo.formation.Formation`` for formation files) from TOML text;
    ``ScenarioError`` (one line) on any problem."""
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
