"""``nonholo fleet SCENARIO``: run every robot of a scenario as its own program."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK, signals_interrupt
from nonholo.cli.robot import add_mode_option, add_simulation_overrides


def register(subparsers) -> None:
    from nonholo.fleet.config import TRANSPORTS

    parser = subparsers.add_parser(
        "fleet", help="run each robot of a scenario as its own program",
        description="Run every robot of a scenario as its own program exchanging FIPA-ACL states "
                    "(spec fleet.md) and gather one result, as `nonholo run` reports it, plus a network "
                    "section. Needs sampled-data control ([simulation] control_period).",
        epilog="Exit codes: 0 ok, 1 failure, 2 bad input.")
    parser.add_argument("scenario", help="a scenario .toml file, or the name of a bundled example")
    parser.add_argument("--transport", choices=TRANSPORTS,
                        help="tcp: one process per robot over authenticated TCP (default, or [network] "
                             "transport); zenoh: one process per robot, Zenoh peers; inproc: every robot in "
                             "this process")
    add_mode_option(parser)
    add_simulation_overrides(parser)
    parser.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    parser.add_argument("--out", metavar="DIR",
                        help="write result.json, trajectories.csv, plot.png and network.png (link health) to DIR")
    from nonholo.cli.view import add_fleet_view_arguments

    add_fleet_view_arguments(parser)
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from nonholo.cli.view import FleetViewing

    viewing = FleetViewing(args, "nonholo fleet")
    try:
        return run_and_report(args, viewing)
    finally:
        viewing.stop()   # the page and the Foxglove bridge, whatever happened (stopping twice is harmless)


def run_and_report(args: argparse.Namespace, viewing) -> int:
    """Run the fleet, write and print its result, serve the page to the end if asked."""
    from nonholo import examples
    from nonholo.cli.run import format_summary, write_outputs
    from nonholo.cli.robot import simulation_overrides
    from nonholo.errors import NonholoInputError, SimulationError
    from nonholo.fleet.launch import run_fleet
    from nonholo.fleet.report import format_network, plot_link_health
    from nonholo.fleet.config import load_fleet

    try:
        source = examples.resolve(args.scenario)
        overrides = simulation_overrides(args)
        scenario, config = load_fleet(source, overrides)
        config = viewing.network(config, scenario.names)      # --keys, --observe
        transport = args.transport or config.transport
        viewing.start()
        with signals_interrupt():   # SIGTERM, SIGHUP: every robot process reaped, as on Ctrl-C
            run = run_fleet(scenario, transport=transport, mode=args.mode, config=config, source=source,
                            overrides=overrides, observer=viewing.observer, speed=viewing.speed,
                            observe=viewing.observe)
    except NonholoInputError as exc:
        print(f"nonholo fleet: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SimulationError as exc:
        print(f"nonholo fleet: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    summary = run.to_dict()
    try:
        if args.out:
            for written in write_outputs(run.result, summary, Path(args.out)):
                print(f"wrote {written}", file=sys.stderr)
            plot_link_health(run.timelines, summary["network"], Path(args.out) / "network.png")
            print(f"wrote {Path(args.out) / 'network.png'}", file=sys.stderr)
        viewing.finish(run, summary)
    except NonholoInputError as exc:
        print(f"nonholo fleet: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (OSError, ValueError) as exc:
        print(f"nonholo fleet: cannot write the outputs: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    if args.json:
        json.dump(summary, sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(format_summary(summary))
        print(format_network(summary["network"]))
    sys.stdout.flush()
    viewing.serve()
    return EXIT_OK
