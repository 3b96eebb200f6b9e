"""The ``nonholo`` command line.

Each sub-command lives in its own module of this package and exposes
``register(subparsers)``; modules are discovered here so that adding a command never
edits this file. Exit codes: 0 success, 1 run-time failure, 2 bad input.
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_BAD_INPUT = 2


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="nonholo",
        description="Collaborative nonholonomic robots: simulate, analyse and network "
        "unicycle leader-follower formations.",
    )
    from nonholo import __version__

    parser.add_argument("--version", action="version", version=f"nonholo {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module_info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if module_info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{module_info.name}")
        register = getattr(module, "register", None)
        if register is not None:
            register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "handler", None) is None:
        parser.print_help()
        return EXIT_BAD_INPUT
    return int(args.handler(args) or EXIT_OK)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
