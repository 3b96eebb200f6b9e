"""``nonholo fleet SCENARIO``: run every robot of a scenario as its own program."""
from __future__ import annotations

import argparse
import json
import sys
import threading
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
    parser.add_argument("--quiet", action="store_true", help="no progress bar, no start line")
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
        if scenario.hold_every == 0:
            raise NonholoInputError(f"{args.scenario}: a fleet needs sampled-data control: add --control-period S "
                                    "(a multiple of dt, e.g. 0.02) or set [simulation] control_period")
        config = viewing.network(config, scenario.names)      # --keys, --observe
        transport = args.transport or config.transport
        viewing.start()
        observer = viewing.observer
        if not args.quiet and observer is None and args.observe is None and sys.stderr.isatty():
            observer = FleetProgress(scenario)   # a bar of the robot time the slowest robot has reached

        def announce():   # once the inputs are checked (a bad one: one line), what starts
            if not args.quiet:
                print(f"nonholo fleet: {len(scenario.names)} robot programs ({transport}, {args.mode}), "
                      f"{scenario.duration:g} s of robot time", file=sys.stderr)
            if isinstance(observer, FleetProgress):
                observer.open()
        try:
            with signals_interrupt():   # SIGTERM, SIGHUP: every robot process reaped, as on Ctrl-C
                run = run_fleet(scenario, transport=transport, mode=args.mode, config=config, source=source,
                                overrides=overrides, observer=observer, speed=viewing.speed,
                                observe=viewing.observe, on_start=announce)
        finally:
            if isinstance(observer, FleetProgress):
                observer.close()
    except NonholoInputError as exc:
        print(f"nonholo fleet: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SimulationError as exc:
        print(f"nonholo fleet: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except OSError as exc:   # no local endpoint, no processes: the machine's limits, said on one line
        print(f"nonholo fleet: cannot run the fleet: {exc}", file=sys.stderr)
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


class FleetProgress:
    """An observer of a fleet run (as ``nonholo.view.feed.FleetObserver``) that shows a
    progress bar: the robot time the slowest robot has reached, from the robots' statuses
    (robot processes) or from the programs themselves (in process)."""

    period_s = 0.2

    def __init__(self, scenario) -> None:
        self.scenario = scenario
        self.reached = dict.fromkeys(scenario.names, 0.0)
        self._lock = threading.Lock()
        self.bar = None

    def open(self) -> None:
        """Show the bar (once the run starts)."""
        from tqdm import tqdm

        s = self.scenario
        with self._lock:
            self.bar = tqdm(total=s.duration, unit="s", file=sys.stderr, desc=f"{s.name}: {len(s.names)} robots",
                            bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.2f}/{total:g} s of robot time "
                                       "[{elapsed}<{remaining}]")

    def _show(self) -> None:
        if self.bar is not None:
            self.bar.n = min(self.reached.values())
            self.bar.refresh()

    def __call__(self, programs) -> None:
        from nonholo.fleet.telemetry import program_step

        for program in programs:
            self.reached[program.setup.name] = max(program_step(program), 0) * program.setup.dt
        self._show()

    def status(self, name: str, status: dict) -> None:
        with self._lock:   # (from the observer endpoint's thread)
            self.reached[name] = status["t"] or 0.0
            self._show()

    def close(self) -> None:
        with self._lock:
            if self.bar is not None:
                self.bar.close()
