"""``nonholo bench-montecarlo``: the Monte-Carlo targets of issue 13 as figures (not asserted
anywhere): SAMPLES draws of Test 1 at its full horizon (figure eight, 80π s, dynamic
feedback, dt = 0.01 s as in ``nonholo bench``), statistics only, in this process and on a
2-worker local Dask cluster, with the simulator's batch rate measured in the same run."""
from __future__ import annotations

import argparse
import json
import sys
import time

from nonholo.cli import EXIT_BAD_INPUT, EXIT_OK

TEST1 = """name = "test1-dfl"
[simulation]
dt = 0.01
[reference]
kind = "eight"
[[robots]]
name = "leader"
controller = "dynamic-feedback"
"""
VARY = ("leader.start.x=normal(0, 0.5)", "leader.start.y=normal(0, 0.5)", "leader.start.theta=normal(0, 0.5)")


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "bench-montecarlo", help="time a large Monte-Carlo study here and on a local Dask cluster",
        description="Time SAMPLES Monte-Carlo draws of Test 1 (figure eight, 80π s, dynamic feedback, dt = 0.01 s, "
                    "start x, y, θ ~ normal(0, 0.5)), statistics only: in this process (target: under a minute) "
                    "and on a local Dask cluster of 2 worker processes (target: within 20 % of the local time). "
                    "Also measures the simulator's plain batch rate in the same run, for the ratio.")
    parser.add_argument("--samples", type=int, default=100_000, help="draws (default: %(default)s)")
    parser.add_argument("--no-dask", action="store_true", help="skip the Dask run")
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from nonholo.sim.benchmark import batch_scenario
    from nonholo.sim.simulator import simulate
    from nonholo.studies.montecarlo import run_montecarlo

    if args.samples < 1:
        print("nonholo bench-montecarlo: --samples must be >= 1", file=sys.stderr)
        return EXIT_BAD_INPUT
    if not args.no_dask:   # before the first measurement, not after it
        from nonholo.errors import NonholoInputError
        from nonholo.studies.distributed import require_dask

        try:
            require_dask()
        except NonholoInputError as exc:
            print(f"nonholo bench-montecarlo: {exc}, or skip the Dask run with --no-dask", file=sys.stderr)
            return EXIT_BAD_INPUT
    say = (lambda m: None) if args.json else (lambda m: print(f"  measuring {m} …", file=sys.stderr, flush=True))
    run_montecarlo(TEST1, VARY, 50, seed=0, progress=False)   # warm the JIT cache
    say("the simulator's batch rate (10^4 robots, 20 s)")
    batch = batch_scenario()
    simulate(batch, record=False, progress=False)
    started = time.perf_counter()
    simulate(batch, record=False, progress=False)
    batch_rate = len(batch.robots) * batch.n_steps / (time.perf_counter() - started)
    figures = {"samples": args.samples, "batch_robot_steps_per_s": batch_rate}
    say(f"{args.samples} samples in this process")
    local = run_montecarlo(TEST1, VARY, args.samples, seed=0, progress=False)
    steps = local.steps
    figures.update(local_s=local.timing["total_s"], steps=steps, chunks=local.timing["chunks"],
                   local_robot_steps_per_s=args.samples * steps / local.timing["total_s"])
    figures["local_vs_batch_rate"] = figures["local_robot_steps_per_s"] / batch_rate
    if not args.no_dask:
        say(f"{args.samples} samples on a local Dask cluster (2 workers, start-up included)")
        remote = run_montecarlo(TEST1, VARY, args.samples, seed=0, progress=False, dask="local")
        figures["dask_s"] = remote.timing["total_s"]
        figures["dask_over_local"] = figures["dask_s"] / figures["local_s"]
        a, b = local.to_dict(), remote.to_dict()
        a.pop("timing"), b.pop("timing")
        figures["dask_identical"] = a == b
    if args.json:
        print(json.dumps(figures))
        return EXIT_OK
    print(f"Monte-Carlo, Test 1 full horizon ({steps} steps), {args.samples} samples, statistics only")
    print(f"  this process: {figures['local_s']:.1f} s ({figures['chunks']} chunks; target < 60 s); "
          f"{figures['local_robot_steps_per_s']:.3g} robot-steps/s")
    print(f"  = {figures['local_vs_batch_rate']:.2f} x the plain batch rate measured now "
          f"({batch_rate:.3g} robot-steps/s)")
    if not args.no_dask:
        print(f"  local Dask cluster, 2 workers: {figures['dask_s']:.1f} s = {figures['dask_over_local']:.2f} x "
              f"this process (target <= 1.2); same --json: {figures['dask_identical']}")
    return EXIT_OK
