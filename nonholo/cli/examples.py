"""``nonholo examples``: the bundled scenarios, a line each."""
from __future__ import annotations

import argparse
import json
import sys

from nonholo.cli import EXIT_BAD_INPUT, EXIT_OK


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "examples", help="list the bundled example scenarios (run one with: nonholo run NAME)",
        description="List the bundled example scenarios with a line each, or print one's file (--show NAME) or "
                    "its path (--path NAME). Run one with `nonholo run NAME`; copy one to start your own.",
        epilog="Exit codes: 0 ok, 2 bad input (unknown example).")
    parser.add_argument("--show", metavar="NAME", help="print the example's TOML file")
    parser.add_argument("--path", metavar="NAME", help="print the example file's path")
    parser.add_argument("--json", action="store_true", help="print {name: {description, path}} as JSON")
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from nonholo import examples
    from nonholo.studies.framework import wrap

    wanted = args.show or args.path
    if wanted:
        if wanted not in examples.names():
            print(f"nonholo examples: no bundled example {wanted!r} (examples: {', '.join(examples.names())})",
                  file=sys.stderr)
            return EXIT_BAD_INPUT
        file = examples.path(wanted)
        print(file.read_text(encoding="utf-8"), end="") if args.show else print(file)
        return EXIT_OK
    if args.json:
        json.dump({name: {"description": examples.describe(name), "path": str(examples.path(name))}
                   for name in examples.names()}, sys.stdout, indent=1)
        sys.stdout.write("\n")
        return EXIT_OK
    width = max(len(name) for name in examples.names())
    for name in examples.names():
        print(wrap(examples.describe(name), 100, f"{name.ljust(width)}  ", " " * (width + 2)))
    print("\nRun one: nonholo run NAME [--json] [--plot FILE]; see its file: nonholo examples --show NAME")
    return EXIT_OK
