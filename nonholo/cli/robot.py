"""``nonholo robot SCENARIO --name NAME``: run one robot of a scenario as its own program."""
from __future__ import annotations

import argparse
import sys

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK


def add_simulation_overrides(parser: argparse.ArgumentParser) -> None:
    """--duration, --dt, --control-period: override the scenario's [simulation] values."""
    parser.add_argument("--duration", type=float, metavar="S", help="override [simulation] duration")
    parser.add_argument("--dt", type=float, metavar="S", help="override [simulation] dt")
    parser.add_argument("--control-period", type=float, metavar="S",
                        help="override [simulation] control_period (a multiple of dt)")


def simulation_overrides(args: argparse.Namespace) -> dict:
    """The values of the options ``add_simulation_overrides`` adds (None where not given)."""
    return {"duration": args.duration, "dt": args.dt, "control_period": args.control_period}


def add_mode_option(parser: argparse.ArgumentParser) -> None:
    """--mode lockstep|realtime (default lockstep), for `nonholo robot` and `nonholo fleet`."""
    from nonholo.fleet.config import MODES

    parser.add_argument("--mode", choices=MODES, default=MODES[0],
                        help="lockstep: logical time, equal to the centralized sampled-data run; "
                             "realtime: the wall clock at the control rate, with the watchdog")


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "robot", help="run one robot of a scenario as its own program (TCP)",
        description="Run robot NAME of a scenario: its simulated plant, its control law at the control "
                    "instants, its state published to its followers and subscriptions to its parents, "
                    "over authenticated TCP links or Zenoh, in lockstep (logical time) or realtime (the wall "
                    "clock, with the watchdog). Addresses and the key file "
                    "come from the options or the scenario's [network] table; a robot with followers "
                    "listens, a follower connects to its parents and reconnects when a link drops. "
                    "`nonholo fleet` starts one such process per robot.",
        epilog="Exit codes: 0 ok, 1 failure, 2 bad input. Example (two machines): "
               "nonholo robot chain.toml --name leader --listen 0.0.0.0:7400 --keys fleet.keys; "
               "nonholo robot chain.toml --name f1 --connect leader=192.168.1.10:7400 --keys fleet.keys")
    parser.add_argument("scenario", help="a scenario .toml file, or the name of a bundled example")
    parser.add_argument("--name", required=True, help="the robot to run (a [[robots]] name)")
    parser.add_argument("--listen", metavar="HOST:PORT",
                        help="where to accept the followers (port 0: any free port, printed on stdout)")
    parser.add_argument("--listen-fd", type=int, metavar="FD",
                        help="accept the followers on this inherited listening socket (used by `nonholo fleet`)")
    parser.add_argument("--connect", action="append", default=[], metavar="PARENT=HOST:PORT",
                        help="a parent's address (repeat per parent); default [network.addresses]")
    parser.add_argument("--keys", metavar="FILE", help="key file (mode 0600; key id i+1 is robot i); "
                                                       "default [network] keys")
    parser.add_argument("--transport", choices=("tcp", "zenoh"),
                        help="tcp (default, or [network] transport); zenoh: addresses are Zenoh endpoints "
                             "such as tcp/192.168.1.10:7447")
    add_mode_option(parser)
    parser.add_argument("--wait", type=float, default=20.0, metavar="S",
                        help="longest wait for a peer before giving up (default 20)")
    parser.add_argument("--trace", metavar="FILE", help="write states, commands and the report (.npz)")
    parser.add_argument("--observe", metavar="HOST:PORT",
                        help="stream this robot's status to a viewer attached there (nonholo view SCENARIO "
                             "--attach HOST:PORT --keys FILE); authenticated with the robot's key")
    parser.add_argument("--speed", type=float, metavar="X",
                        help="lockstep: pace logical time at X times wall time (default: unpaced)")
    add_simulation_overrides(parser)
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from nonholo import examples
    from nonholo.comm.errors import CommError
    from nonholo.errors import NonholoInputError, SimulationError
    from nonholo.fleet.config import load_fleet
    from nonholo.fleet.process import RobotOptions, robot_main

    def announce(port):
        if port is not None:
            print(f"listening {port}", flush=True)

    try:
        scenario, config = load_fleet(examples.resolve(args.scenario), simulation_overrides(args))
        connect = []
        for item in args.connect:
            parent, sep, address = item.partition("=")
            if not sep:
                raise NonholoInputError(f"--connect: expected PARENT=HOST:PORT, got {item[:80]!r}")
            connect.append((parent, address))
        keys = args.keys or (str(config.keys) if config.keys else None)
        if keys is None:
            raise NonholoInputError("network.keys: no key file (give --keys FILE or [network] keys)")
        if not 0 < args.wait <= 3600:
            raise NonholoInputError(f"--wait: expected seconds in (0, 3600], got {args.wait:g}")
        transport = args.transport or ("zenoh" if config.transport == "zenoh" else "tcp")
        check_watching(args)
        options = RobotOptions(args.name, keys, args.listen, tuple(connect), args.wait, args.listen_fd, args.mode,
                               transport, observe=args.observe, speed=args.speed)
        program = robot_main(scenario, config, options, args.trace, announce)
    except NonholoInputError as exc:
        print(f"nonholo robot: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (SimulationError, CommError, OSError) as exc:   # OSError: e.g. the listen address is taken
        print(f"nonholo robot: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    print(f"robot {args.name}: {len(program.setup.control_steps)} control steps in {program.elapsed_s:.3f} s",
          file=sys.stderr)
    return EXIT_OK


# The slowest pace --speed takes: a thousandth of wall time (a run of 1e-300 would never end).
MIN_SPEED = 1e-3


def check_watching(args: argparse.Namespace) -> None:
    """--observe HOST:PORT and --speed X (>= MIN_SPEED), or NonholoInputError naming the option."""
    from nonholo.errors import NonholoInputError
    from nonholo.fleet.mesh import split_address

    if args.observe is not None:
        split_address(args.observe, "--observe")
    if args.speed is not None and not MIN_SPEED <= args.speed < float("inf"):
        raise NonholoInputError(f"--speed must be a number >= {MIN_SPEED:g} (times wall time), got {args.speed:g}")
