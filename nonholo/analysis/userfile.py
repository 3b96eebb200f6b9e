"""Driftless or control-affine systems written by users in TOML.

    states = ["z1", "z2", "z3", "z4"]
    inputs = ["u1", "u2"]
    [fields]                  # one vector field per input, components in the order of states
    u1 = ["1", "0", "z2", "z3"]
    u2 = ["0", "1", "0", "0"]
    # optional: drift = [...], outputs = ["z1", "z4"], name = "...", description = "..."
    [parameters]              # numbers, substituted exactly (0.5 becomes 1/2)
    L = 0.5

Every problem is reported as one ``SystemFileError`` whose message names the file and the
offending entry, because the CLI prints it as a single line. The file is read within the
limits of ``nonholo.tomlfile`` and every formula within those of ``nonholo.expressions``;
a system has at most ``MAX_DIMENSION`` states, inputs and outputs.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import sympy as sp

from nonholo.errors import ExpressionError, InputFileError, NonholoInputError
from nonholo.expressions import check_name, exact_number, parse_expression
from nonholo.tomlfile import describe_value, read_toml
from .system import ControlSystem

_KNOWN_KEYS = frozenset({"name", "description", "states", "inputs", "fields", "drift",
                         "outputs", "parameters"})
MAX_DIMENSION = 32
"""States, inputs or outputs of one user system (symbolic analysis of more is hopeless)."""


class SystemFileError(NonholoInputError):
    """A user system file that cannot be read as a control system."""


def load_system_file(path: str | Path) -> ControlSystem:
    """The ControlSystem described by the TOML file at ``path``."""
    path = Path(path)
    try:
        data = read_toml(path)
    except InputFileError as error:
        raise SystemFileError(str(error)) from None
    try:
        return system_from_mapping(data, default_name=path.stem)
    except SystemFileError as error:
        raise SystemFileError(f"{path}: {error}") from None


def system_from_mapping(data: Mapping, default_name: str) -> ControlSystem:
    """Validate the parsed TOML table and build the system."""
    unknown = sorted(set(data) - _KNOWN_KEYS)
    if unknown:
        raise SystemFileError(f"unknown key {describe_value(unknown[0], typed=False)} "
                              f"(allowed: {', '.join(sorted(_KNOWN_KEYS))})")
    state_names = _names(data, "states")
    input_names = _names(data, "inputs")
    parameters = _parameters(data.get("parameters", {}))
    _check_distinct(state_names, input_names, parameters)
    states = tuple(sp.Symbol(name, real=True) for name in state_names)
    inputs = tuple(sp.Symbol(name, real=True) for name in input_names)
    scope = {str(s): s for s in states} | parameters
    fields = _fields(data.get("fields"), input_names, state_names, scope)
    drift = (_vector(data["drift"], "drift", state_names, scope) if "drift" in data else None)
    outputs = tuple(_expressions(data.get("outputs", []), "outputs", scope))
    return ControlSystem(
        name=_text(data, "name", default_name), description=_text(data, "description", "user system"),
        states=states, inputs=inputs, fields=fields,
        drift=None if drift is None or drift.is_zero_matrix else drift,
        outputs=outputs, parameters=dict(parameters))


def _text(data: Mapping, key: str, default: str) -> str:
    value = data.get(key, default)
    if not isinstance(value, str):
        raise SystemFileError(f"{key}: expected a string, got {describe_value(value)}")
    return value


def _names(data: Mapping, key: str) -> list[str]:
    names = data.get(key)
    if not isinstance(names, list) or not names:
        raise SystemFileError(f"{key}: expected a non-empty list of names, got {describe_value(names)}")
    if len(names) > MAX_DIMENSION:
        raise SystemFileError(f"{key}: {len(names):,} names, at most {MAX_DIMENSION}")
    for index, name in enumerate(names, start=1):
        problem = check_name(name)
        if problem:
            raise SystemFileError(f"{key}[{index}]: {problem}")
    return names


def _parameters(table) -> dict[str, sp.Expr]:
    if not isinstance(table, Mapping):
        raise SystemFileError(f"parameters: expected a table of name = number, got {describe_value(table)}")
    values = {}
    for name, value in table.items():
        problem = check_name(name)
        if problem:
            raise SystemFileError(f"parameters: {problem}")
        try:  # exact: 0.1 becomes 1/10
            values[name] = exact_number(value)
        except ExpressionError as error:
            raise SystemFileError(f"parameters.{name}: {error}") from None
    return values


def _check_distinct(*groups: Sequence[str]) -> None:
    seen: set[str] = set()
    for name in (name for group in groups for name in group):
        if name in seen:
            raise SystemFileError(f"name {name!r} is declared twice")
        seen.add(name)


def _fields(table, input_names: Sequence[str], state_names: Sequence[str],
            scope: Mapping[str, sp.Expr]) -> tuple[sp.Matrix, ...]:
    if not isinstance(table, Mapping):
        raise SystemFileError(f"fields: expected a table with one vector field per input, got {describe_value(table)}")
    extra = sorted(set(table) - set(input_names))
    if extra:
        shown = describe_value(extra[0], typed=False)
        raise SystemFileError(f"fields: {shown} is not a declared input (inputs: {', '.join(input_names)})")
    missing = [name for name in input_names if name not in table]
    if missing:
        raise SystemFileError(f"fields: no vector field for input {missing[0]!r}")
    return tuple(_vector(table[name], f"fields.{name}", state_names, scope)
                 for name in input_names)


def _vector(components, where: str, state_names: Sequence[str],
            scope: Mapping[str, sp.Expr]) -> sp.Matrix:
    if not isinstance(components, list):
        raise SystemFileError(f"{where}: expected a list of {len(state_names)} expressions, got "
                              f"{describe_value(components)}")
    if len(components) != len(state_names):
        raise SystemFileError(f"{where}: has {len(components)} components but there are "
                              f"{len(state_names)} states ({', '.join(state_names)})")
    return sp.Matrix(_expressions(components, where, scope))


def _expressions(items, where: str, scope: Mapping[str, sp.Expr]) -> list[sp.Expr]:
    if not isinstance(items, list):
        raise SystemFileError(f"{where}: expected a list of expressions, got {describe_value(items)}")
    if len(items) > MAX_DIMENSION:
        raise SystemFileError(f"{where}: {len(items):,} expressions, at most {MAX_DIMENSION}")
    expressions = []
    for index, item in enumerate(items, start=1):
        text = str(item) if isinstance(item, (int, float)) and not isinstance(item, bool) else item
        try:
            expressions.append(parse_expression(text, scope))
        except ExpressionError as error:
            raise SystemFileError(f"{where}[{index}]: {error}") from None
    return expressions
