"""``nonholo bench-study``: wall times of the whole study (with its helper processes and
without, interleaved) and of a 10⁴-point sweep (figures to report, not asserted anywhere)."""
from __future__ import annotations

import argparse
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

from nonholo.cli import EXIT_OK


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "bench-study", help="time the whole study (with and without helper processes) and a large gain sweep",
        description="Time `nonholo study` (all studies, in this process, reports written to a temporary folder) "
                    "with its default helper processes and with --processes 0, interleaved over ROUNDS rounds after "
                    "one untimed run of each (which also fills the JIT caches), and print the medians, the spread "
                    "and their ratio; then a POINTS-point two-gain sweep (zeta x b of approximate linearization) on "
                    "Test 1.")
    parser.add_argument("--rounds", type=int, default=3, help="timed rounds of the study (default: %(default)s)")
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

    from nonholo.sim.benchmark import interleaved
    from nonholo.studies.forking import PROCESSES

    with tempfile.TemporaryDirectory() as folder:
        starting(f"nonholo study, with {PROCESSES} helper processes and with none, {max(1, args.rounds)} rounds "
                 "(the untimed first runs also compile)")
        times = interleaved({
            f"--processes {p}": lambda p=p: run_studies(None, StudyOptions(Path(folder) / str(p), progress=False,
                                                                           processes=p))
            for p in (PROCESSES, 0)}, max(1, args.rounds))
    medians = {name: statistics.median(values) for name, values in times.items()}
    for name, values in times.items():
        print(f"nonholo study {name}: {medians[name]:.2f} s (wall, report included; spread {min(values):.2f}-"
              f"{max(values):.2f} s over {len(values)} rounds)", flush=True)
    baseline, subject = medians["--processes 0"], medians[f"--processes {PROCESSES}"]
    print(f"nonholo study: {baseline / subject:.2f}x faster with {PROCESSES} helper processes", flush=True)
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
