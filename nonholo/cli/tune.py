"""``nonholo tune SCENARIO --gains kp,kd [--bounds ...] [--objective ...]``: gains that minimise
an objective, by differential evolution over batches (``nonholo.studies.tune``)."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK, wrap
from nonholo.cli.montecarlo import add_dask_option


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "tune", help="find gains minimising an objective (differential evolution, populations as batches)",
        description="Tune some gains of one robot by scipy's differential evolution, each generation simulated as "
                    "one batch, optionally robust over a Monte-Carlo set of starts; report the optimum and its "
                    "metrics beside the thesis's Table 5.1 gains, and a convergence plot.",
        epilog="Example: nonholo tune test2-line --robot dynamic-feedback --gains kp,kd --bounds kp=0.1:5 "
               "--bounds kd=0.1:5 --objective 'rms + 0.001*effort' --steps 5000. Objective terms: mean, rms, max, "
               "final, ise, effort, saturation, heading. Exit codes: 0 ok, 1 failure, 2 bad input.")
    parser.add_argument("scenario", help="a scenario .toml file, or the name of a bundled example")
    parser.add_argument("--gains", required=True, metavar="NAME,NAME", help="the gains to tune, comma-separated")
    parser.add_argument("--bounds", action="append", default=[], metavar="NAME=LOW:HIGH",
                        help="search interval of a gain (default: a tenth to ten times its value); repeatable")
    parser.add_argument("--objective", default="rms", metavar="EXPR",
                        help="weighted sum of terms, e.g. 'rms + 0.01*effort + 10*saturation' (default: %(default)s)")
    parser.add_argument("--robot", help="the robot to tune (needed if several have those gains)")
    parser.add_argument("--steps", type=int, help="override the scenario's number of output steps N")
    parser.add_argument("--start", action="append", default=[], metavar="FIELD=DIST",
                        help="robust tuning: a start (any montecarlo --vary field) drawn --start-samples times; "
                             "the objective is the mean over that set; repeatable")
    parser.add_argument("--start-samples", type=int, default=16, metavar="M", help="size of the set (default: "
                                                                                  "%(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")
    parser.add_argument("--maxiter", type=int, default=30, help="generations at most (default: %(default)s)")
    parser.add_argument("--popsize", type=int, default=10, help="population per gain (default: %(default)s)")
    parser.add_argument("--out", metavar="DIR", help="write tune.json and convergence.png to DIR")
    parser.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_dask_option(parser)
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from nonholo import examples
    from nonholo.errors import NonholoInputError, SimulationError
    from nonholo.studies.tune import run_tune

    try:
        if args.maxiter < 1 or args.popsize < 1:
            raise NonholoInputError("--maxiter and --popsize must be >= 1")
        path = examples.resolve(args.scenario)
        try:
            text = Path(path).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise NonholoInputError(f"{path}: cannot read: {exc}") from None
        result = run_tune(text, args.gains.split(","), args.bounds, args.objective, source=str(path),
                          robot=args.robot, steps=args.steps, starts=args.start,
                          start_samples=args.start_samples if args.start else 0, seed=args.seed,
                          maxiter=args.maxiter, popsize=args.popsize, dask=args.dask,
                          progress=False if args.quiet else None)
    except NonholoInputError as exc:
        print(f"nonholo tune: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (SimulationError, RuntimeError, OSError) as exc:
        print(f"nonholo tune: failed: {exc}"[:300], file=sys.stderr)
        return EXIT_FAILURE
    if args.out:
        out = Path(args.out)
        try:
            out.mkdir(parents=True, exist_ok=True)
            (out / "tune.json").write_text(json.dumps(result.to_dict(), indent=2, allow_nan=False))
            result.plot(out / "convergence.png")
        except OSError as exc:
            print(f"nonholo tune: cannot write the outputs: {exc}", file=sys.stderr)
            return EXIT_FAILURE
    if args.json:
        json.dump(result.to_dict(), sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(describe(result))
    if result.bound_warning():
        print(wrap(f"nonholo tune: {result.bound_warning()}"), file=sys.stderr)
    return EXIT_OK


def describe(result) -> str:
    """The optimum beside the Table 5.1 gains (lines of at most 100 columns; gains too long for
    their column go on lines of their own, never cut)."""
    rows = [("optimum", result.gains, result.objective, result.metrics),
            ("Table 5.1", result.baseline, result.baseline_objective, result.baseline_metrics)]
    shown = [", ".join(f"{k} = {v:.4g}" for k, v in gains.items()) for _, gains, _, _ in rows]
    width = max(len("gains"), *map(len, shown)) + 2
    inline = 14 + width + 42 <= 100
    lines = [f"{result.scenario}, robot {result.robot} ({result.controller}): objective {result.objective_text}, "
             f"{result.generations} generations, {result.evaluations} evaluations"
             + (f", mean over {result.starts} starts" if result.starts > 1 else ""),
             f"{'':<14}{'gains' if inline else '':<{width if inline else 0}}{'objective':>12}{'err mean':>10}"
             f"{'err rms':>10}{'effort':>10}"]
    for (label, _, value, metrics), gains in zip(rows, shown):
        lines.append(f"{label:<14}{gains if inline else '':<{width if inline else 0}}{value:>12.5g}"
                     f"{metrics['error_mean']:>10.4g}{metrics['error_rms']:>10.4g}{metrics['effort']:>10.4g}")
    if not inline:
        lines += [f"{label} gains: {gains}" for (label, _, _, _), gains in zip(rows, shown)]
    return "\n".join(wrap(line) for line in lines)
