"""``nonholo bench-fleet``: latency, loss and control rate of a fleet of processes over TCP,
and lockstep steps per second (figures to report, asserted nowhere)."""
from __future__ import annotations

import argparse
import json
import sys

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK, signals_interrupt


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "bench-fleet", help="measure a fleet of robot processes over TCP",
        description="A leader and 7 followers, one process each, over authenticated TCP on this machine in "
                    "realtime at each RATE: one-way latency p50/p99/max, states lost, control period, watchdog "
                    "stops, and the highest rate sustained (no loss, no stop, mean period within 5 %, p99 "
                    "under twice the period), each next to the machine's floor (7 minimal processes receiving "
                    "stamps at the same rate right after); then lockstep steps/s of the 7-follower chain (in "
                    "process and TCP), Zenoh at 100 Hz and the fault figures.",
        epilog="Exit codes: 0 ok, 1 failure, 2 bad input. Figures only: nothing is asserted.")
    parser.add_argument("--rates", type=float, nargs="+", default=[100, 200, 400, 800], metavar="HZ",
                        help="control rates to try (default: 100 200 400 800)")
    parser.add_argument("--duration", type=float, default=3.0, metavar="S", help="seconds per rate (default 3)")
    parser.add_argument("--no-faults", action="store_true",
                        help="skip the fault figures (leader SIGKILL and SIGSTOP: time to the followers' stop)")
    parser.add_argument("--latency-only", action="store_true",
                        help="only the realtime TCP figures at each rate and their floors (no lockstep, Zenoh, "
                             "faults)")
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from nonholo.errors import NonholoInputError
    from nonholo.fleet.bench import format_bench, run_bench

    if not all(1 <= r <= 5000 for r in args.rates) or not 0.5 <= args.duration <= 600:
        print("nonholo bench-fleet: --rates must be in 1..5000 Hz and --duration in 0.5..600 s", file=sys.stderr)
        return EXIT_BAD_INPUT
    progress = None if args.json else (lambda message: print(f"  {message}", file=sys.stderr, flush=True))
    try:
        with signals_interrupt():   # SIGTERM, SIGHUP: every process reaped, as on Ctrl-C
            figures = run_bench(tuple(args.rates), args.duration, progress, not args.no_faults, args.latency_only)
    except NonholoInputError as exc:
        print(f"nonholo bench-fleet: {' '.join(str(exc).split())}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as exc:   # a failed run is one line, whatever failed (a robot, a socket, a floor process)
        print(f"nonholo bench-fleet: {type(exc).__name__}: {' '.join(str(exc).split())}"[:300], file=sys.stderr)
        return EXIT_FAILURE
    print(json.dumps(figures) if args.json else format_bench(figures))
    return EXIT_OK
