"""``nonholo analyze``: symbolic control analysis of a built-in system or a TOML file.

sympy is imported inside the handler so that other sub-commands start fast.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK

FORMATS = ("text", "markdown", "latex", "json")
MAX_DEPTH = 8  # the bracket tree grows like m^(depth-1); deeper trees take minutes


class BadInput(ValueError):
    """A user mistake on the command line or in a system file: one line, exit 2."""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "analyze",
        help="symbolic control analysis (Lie brackets, controllability, observability, "
             "chained form, flatness)",
        description="Analyse a driftless/control-affine system exactly with sympy, as in "
                    "thesis Chapter 3, and explain each result. SYSTEM is a built-in name "
                    "(see --list) or a TOML file (see docs/analysis.md).",
    )
    parser.add_argument("system", nargs="?", metavar="SYSTEM|FILE",
                        help="built-in system name or path to a TOML system file")
    parser.add_argument("--list", action="store_true", help="list the built-in systems and exit")
    parser.add_argument("--depth", type=int, default=3, metavar="N",
                        help="longest Lie bracket (number of fields) to compute (default 3)")
    parser.add_argument("--at", default="", metavar='"x=0,theta=pi/4"',
                        help="values of states, inputs or symbolic parameters for the "
                             "point-wise results")
    parser.add_argument("--format", choices=FORMATS, default="text",
                        help="report format (default text)")
    parser.add_argument("--json", dest="format", action="store_const", const="json",
                        help="same as --format json")
    parser.set_defaults(handler=run_analyze)


def run_analyze(args: argparse.Namespace) -> int:
    from nonholo.analysis import BUILTIN_SYSTEMS

    if args.list:
        for name, make in BUILTIN_SYSTEMS.items():
            print(f"{name:24s}{make().description}")
        return EXIT_OK
    try:
        system = _load(args.system)
        if not 1 <= args.depth <= MAX_DEPTH:
            raise BadInput(f"--depth must be between 1 and {MAX_DEPTH}, got {args.depth}")
        at = parse_point(args.at, system.names())
    except BadInput as error:
        print(f"nonholo analyze: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return _report(system, args.depth, at, args.format)


def _load(name: str | None):
    from nonholo.analysis import BUILTIN_SYSTEMS, SystemFileError, load_system_file

    if name is None:
        raise BadInput("give a SYSTEM name or FILE (or --list)")
    if name in BUILTIN_SYSTEMS:
        return BUILTIN_SYSTEMS[name]()
    if not Path(name).is_file():
        raise BadInput(f"{name!r} is neither a built-in system "
                       f"({', '.join(BUILTIN_SYSTEMS)}) nor a file")
    try:
        return load_system_file(name)
    except SystemFileError as error:
        raise BadInput(str(error)) from None


def parse_point(text: str, names: dict) -> dict:
    """'x=0, theta=pi/4' → {x: 0, theta: pi/4}; values are numbers or expressions of pi, E."""
    from nonholo.analysis import ExpressionError, parse_expression

    point = {}
    for assignment in _split_top_level(text):
        name, equals, value = assignment.partition("=")
        name = name.strip()
        if not equals or not name:
            raise BadInput(f"--at: expected name=value, got {assignment.strip()!r}")
        if name not in names:
            raise BadInput(f"--at: unknown name {name!r} (known: {', '.join(names)})")
        try:
            point[names[name]] = parse_expression(value, {})
        except ExpressionError as error:
            raise BadInput(f"--at {name}: {error}") from None
    return point


def _split_top_level(text: str) -> list[str]:
    """Split on commas outside parentheses, so that atan2(1, 2) stays one value."""
    parts, depth, current = [], 0, []
    for character in text:
        depth += {"(": 1, ")": -1}.get(character, 0)
        if character == "," and depth == 0:
            parts.append("".join(current))
            current = []
        else:
            current.append(character)
    parts.append("".join(current))
    return [part for part in parts if part.strip()]


def _report(system, depth: int, at: dict, output_format: str) -> int:
    from nonholo.analysis import RENDERERS, summarize

    try:
        text = RENDERERS[output_format](summarize(system, depth=depth, at=at))
    except Exception as error:  # a symbolic failure is a run-time failure, not bad input
        print(f"nonholo analyze: analysis failed: {type(error).__name__}: {error}",
              file=sys.stderr)
        return EXIT_FAILURE
    print(text)
    return EXIT_OK
