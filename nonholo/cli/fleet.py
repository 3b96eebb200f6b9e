"""``nonholo fleet SCENARIO``: run every robot of a scenario as its own program."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "fleet", help="run each robot of a scenario as its own program",
        description="Run every robot of a scenario as its own program exchanging FIPA-ACL states "
                    "(spec fleet.md) and gather one result, as `nonholo run` reports it, plus a network "
                    "section. Needs sampled-data control ([simulation] control_period).",
        epilog="Exit codes: 0 ok, 1 failure, 2 bad input.")
    parser.add_argument("scenario", help="a scenario .toml file, or the name of a bundled example")
    parser.add_argument("--transport", choices=("inproc",), default="inproc",
                        help="inproc: every robot in this process (TCP processes: not yet)")
    parser.add_argument("--mode", choices=("lockstep",), default="lockstep",
                        help="lockstep: logical time, equal to the centralized sampled-data run")
    parser.add_argument("--control-period", type=float, metavar="S",
                        help="override [simulation] control_period (a multiple of dt)")
    parser.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    parser.add_argument("--out", metavar="DIR", help="write result.json, trajectories.csv and plot.png to DIR")
    from nonholo.cli.view import add_fleet_view_arguments

    add_fleet_view_arguments(parser)
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    import dataclasses

    from nonholo import examples
    from nonholo.cli.run import format_summary, write_outputs
    from nonholo.cli.view import FleetViewing
    from nonholo.errors import NonholoInputError, SimulationError
    from nonholo.fleet.launch import run_fleet
    from nonholo.sim.files import load_scenario

    viewing = FleetViewing(args, "nonholo fleet")
    try:
        scenario = load_scenario(examples.resolve(args.scenario))
        if args.control_period is not None:
            scenario = dataclasses.replace(scenario, control_period=args.control_period, steps=None)
        viewing.start()
        run = run_fleet(scenario, transport=args.transport, mode=args.mode, observer=viewing.observer,
                        speed=viewing.speed)
    except NonholoInputError as exc:
        viewing.stop()
        print(f"nonholo fleet: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SimulationError as exc:
        viewing.stop()
        print(f"nonholo fleet: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except BaseException:
        viewing.stop()
        raise
    summary = run.to_dict()
    try:
        if args.out:
            for written in write_outputs(run.result, summary, Path(args.out)):
                print(f"wrote {written}", file=sys.stderr)
        viewing.finish(run, summary)
    except NonholoInputError as exc:
        viewing.stop()
        print(f"nonholo fleet: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (OSError, ValueError) as exc:
        viewing.stop()
        print(f"nonholo fleet: cannot write the outputs: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    if args.json:
        json.dump(summary, sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(format_summary(summary))
        network = summary["network"]
        print(f"network: {network['transport']} {network['mode']}, {network['control_steps']} control steps, "
              f"{network['control_steps_per_s']:.0f} steps/s")
    sys.stdout.flush()
    viewing.serve()
    return EXIT_OK
