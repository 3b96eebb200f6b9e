"""``nonholo bench-study``: wall times of the leader study and of a 10⁴-point sweep (figures
to report, not asserted anywhere)."""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

from nonholo.cli import EXIT_OK


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "bench-study", help="time the leader study and a large gain sweep",
        description="Time `nonholo study leader` (in process, report written to a temporary folder) and a "
                    "POINTS-point two-gain sweep (zeta x b of approximate linearization) on Test 1. Run twice: the "
                    "first run also fills the JIT caches.")
    parser.add_argument("--points", type=int, default=10_000, help="sweep grid points (default: %(default)s)")
    parser.add_argument("--steps", type=int, nargs="*", default=[100_000, 10_000],
                        help="output steps N of the sweep runs (default: 100000 10000)")
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from nonholo import examples
    from nonholo.sim.files import load_scenario
    from nonholo.studies import StudyOptions, run_studies
    from nonholo.studies.sweep import GainAxis, run_sweep

    def starting(what: str) -> None:
        """Say what is being timed (stderr, so that stdout keeps only the figures)."""
        print(f"bench-study: timing {what} …", file=sys.stderr, flush=True)

    with tempfile.TemporaryDirectory() as folder:
        starting("nonholo study leader (the first run also compiles)")
        started = time.perf_counter()
        run_studies(["leader"], StudyOptions(Path(folder), progress=False))
        print(f"nonholo study leader: {time.perf_counter() - started:.2f} s (wall, report included)", flush=True)
    side = max(1, round(math.sqrt(args.points)))
    axes = [GainAxis.linear("zeta", 0.05, 0.95, side), GainAxis.linear("b", 0.2, 20.0, side)]
    scenario = load_scenario(examples.path("test1-eight"))
    for steps in args.steps:
        starting(f"a {side * side}-point sweep, N = {steps}")
        started = time.perf_counter()
        result = run_sweep(scenario, axes, robot="approximate-linearization", steps=steps, progress=False)
        elapsed = time.perf_counter() - started
        print(f"sweep test1-eight zeta x b, {result.points} points, N = {steps}: {elapsed:.2f} s "
              f"({elapsed / result.points * 1e3:.2f} ms per point)", flush=True)
    return EXIT_OK
