"""``nonholo sweep SCENARIO --gain NAME=START:STOP:COUNT [--gain …]``: a gain grid as one batch."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK
from nonholo.cli.montecarlo import add_dask_option


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "sweep", help="vary one or two gains over a grid (one batch) and write a CSV and a plot",
        description="Simulate one robot of a scenario for every point of a grid of one or two of its gains "
                    "(the other gains as in the scenario), all as one batch, and report an error metric per point.",
        epilog="Example: nonholo sweep test1-eight --robot kanayama --gain kx=1:20:40 --gain ky=0.001:0.03:40. "
               "Exit codes: 0 ok, 1 failure, 2 bad input.")
    parser.add_argument("scenario", help="a scenario .toml file, or the name of a bundled example")
    parser.add_argument("--gain", action="append", required=True, metavar="NAME=START:STOP:COUNT",
                        help="a gain (a follower's k1, k2, d, l, phi, l1, l2 too) and its grid (COUNT values, START "
                             "and STOP included); once or twice")
    parser.add_argument("--metric", choices=("mean", "rms", "max", "final"), default="mean",
                        help="error-norm statistic to report and plot (default: %(default)s)")
    parser.add_argument("--robot", help="the robot whose gains are varied (needed if several have those gains)")
    parser.add_argument("--steps", type=int, help="override the scenario's number of output steps N")
    parser.add_argument("--out", metavar="DIR", help="write sweep.csv, sweep.json and sweep.png to DIR")
    parser.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_dask_option(parser)
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from nonholo import examples
    from nonholo.errors import NonholoInputError
    from nonholo.sim.files import load_scenario
    from nonholo.studies.sweep import GainAxis, run_sweep

    try:
        axes = [GainAxis.parse(text) for text in args.gain]
        if args.steps is not None and args.steps < 1:
            raise NonholoInputError(f"--steps must be a positive integer, got {args.steps}")
        path = examples.resolve(args.scenario)
        scenario = load_scenario(path)
        text = path.read_text(encoding="utf-8") if args.dask else None
        announce = None
        if not args.quiet and not sys.stderr.isatty():  # a terminal gets the simulator's progress bar instead
            points = 1
            for axis in axes:
                points *= axis.values.size

            def announce():   # once the robot and gains are checked (a bad one: one line)
                print(f"nonholo sweep: simulating {points} grid points of {args.scenario} as one batch …",
                      file=sys.stderr, flush=True)
        result = run_sweep(scenario, axes, robot=args.robot, metric=args.metric,
                           steps=args.steps, progress=False if args.quiet else None, dask=args.dask, text=text,
                           source=str(path), on_start=announce)
    except NonholoInputError as exc:
        print(f"nonholo sweep: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (RuntimeError, OSError) as exc:
        print(f"nonholo sweep: failed: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    if args.out:
        out = Path(args.out)
        try:
            out.mkdir(parents=True, exist_ok=True)
            result.write_csv(out / "sweep.csv")
            result.write_json(out / "sweep.json")
            result.plot(out / "sweep.png")
        except OSError as exc:
            print(f"nonholo sweep: cannot write the outputs: {exc}", file=sys.stderr)
            return EXIT_FAILURE
    if args.json:
        # (``dumps``, not ``dump``: only a whole document goes through json's C encoder,
        # 5x faster for a 10^4-point grid)
        sys.stdout.write(json.dumps(result.to_dict(), allow_nan=False) + "\n")
        if result.edge_warning() and not args.quiet:
            print(f"nonholo sweep: {result.edge_warning()}", file=sys.stderr)
    else:
        print(describe(result))
    return EXIT_OK


def describe(result) -> str:
    """A short text summary (lines of at most 100 columns): the best point, a warning if it
    lies on the grid's edge and, for one gain, the trend and every value."""
    from nonholo.studies.framework import wrap

    values = result.values
    where = ", ".join(f"{name} = {value:g}" for name, value in result.best().items())
    whose = "" if result.output == "position" else f" {result.output}"
    lines = [wrap(f"{result.scenario}, robot {result.robot} ({result.controller}): {result.points} points simulated "
                  f"in {result.elapsed_s:.2f} s (one batch, wall time); lowest {result.metric}{whose} error "
                  f"{values.min():.4g} {result.unit} at {where}", 100)]
    warning = result.edge_warning()
    if warning:
        lines.append(wrap(warning, 100))
    if len(result.axes) == 1:
        axis = result.axes[0]
        lines.append(f"trend of the {result.metric}{whose} error as {axis.name} increases: {result.trend().word}")
        if axis.values.size <= 50:
            lines += [f"  {axis.name} = {g:<10.4g} {result.metric} = {v:.6g} {result.unit}"
                      for g, v in zip(axis.values, values)]
    return "\n".join(lines)
