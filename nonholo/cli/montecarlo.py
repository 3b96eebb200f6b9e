"""``nonholo montecarlo SCENARIO --samples N --vary ROBOT.FIELD=DIST [...]``: robustness over
draws of a scenario's numbers (``nonholo.studies.montecarlo``)."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK


def add_dask_option(parser) -> None:
    """``--dask ADDRESS`` (one wording for sweep, montecarlo and tune)."""
    parser.add_argument("--dask", metavar="ADDRESS",
                        help="spread chunks over a Dask cluster: 'local' (2 worker processes on this machine) or "
                             "a scheduler address such as tcp://10.0.0.5:8786 (needs pip install 'nonholo[dask]'); "
                             "the results are the same as without it")


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "montecarlo", help="draw a scenario's numbers from distributions; metric distributions and failure rates",
        description="Simulate SAMPLES draws of some numbers of a scenario (statistics only, in batches) and report "
                    "the distribution of every metric (mean with a 95% interval, quantiles), failure probabilities "
                    "with 95% intervals (diverged, singular, saturated, collision closer than 2d) and the worst "
                    "samples. FIELD: ROBOT.start.x|y|theta, ROBOT.gains.NAME, ROBOT.goal.x|y|theta, ROBOT.l, "
                    "ROBOT.phi, ROBOT.l1, ROBOT.l2, ROBOT.d, ROBOT.v_max, ROBOT.omega_max. DIST: normal(MU, SIGMA) "
                    "or uniform(A, B), absolute values.",
        epilog="Example: nonholo montecarlo test1-eight --samples 1000 --vary dynamic-feedback.start.x='normal(0, "
               "0.5)' --vary dynamic-feedback.gains.kp='uniform(0.5, 1.5)' --out mc. Exit codes: 0 ok, 1 failure, "
               "2 bad input.")
    parser.add_argument("scenario", help="a scenario .toml file, or the name of a bundled example")
    parser.add_argument("--samples", type=int, required=True, metavar="N", help="number of draws")
    parser.add_argument("--vary", action="append", required=True, metavar="FIELD=DIST",
                        help="a number and its distribution, e.g. leader.start.x='normal(0, 0.5)', or the link "
                             "model's network.delay|jitter|loss='uniform(0, 0.1)'; repeatable")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")
    parser.add_argument("--steps", type=int, help="override the scenario's number of output steps N")
    parser.add_argument("--saturation-share", type=float, default=0.05, metavar="SHARE",
                        help="a sample counts as saturated when a command is clipped on more than this share of "
                             "the samples (default: %(default)s)")
    parser.add_argument("--worst", type=int, default=5, metavar="K", help="worst samples to report and write "
                                                                          "(default: %(default)s)")
    parser.add_argument("--worst-by", metavar="METRIC",
                        help="column that ranks the worst samples (default: the first varied robot's error_max)")
    parser.add_argument("--out", metavar="DIR", help="write samples.csv (streamed chunk by chunk), summary.json, "
                                                     "histograms.png and worst-K.toml to DIR")
    parser.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_dask_option(parser)
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from nonholo import examples
    from nonholo.errors import NonholoInputError, SimulationError
    from nonholo.studies.montecarlo import run_montecarlo

    try:
        path = examples.resolve(args.scenario)
        try:
            text = Path(path).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise NonholoInputError(f"{path}: cannot read: {exc}") from None
        announce = None
        if not args.quiet and not sys.stderr.isatty():   # once the inputs are checked (a bad one: one line)
            def announce():
                print(f"nonholo montecarlo: simulating {args.samples} samples of {args.scenario} …",
                      file=sys.stderr, flush=True)
        result = run_montecarlo(text, args.vary, args.samples, seed=args.seed, source=str(path), steps=args.steps,
                                saturation_share=args.saturation_share, worst=args.worst, worst_by=args.worst_by,
                                out=Path(args.out) if args.out else None, dask=args.dask,
                                progress=False if args.quiet else None, on_start=announce)
    except NonholoInputError as exc:
        print(f"nonholo montecarlo: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (SimulationError, RuntimeError, OSError) as exc:
        print(f"nonholo montecarlo: failed: {exc}"[:300], file=sys.stderr)
        return EXIT_FAILURE
    if args.json:
        json.dump(result.to_dict(), sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(describe(result))
    return EXIT_OK


def describe(result) -> str:
    """A short text summary (at most 100 columns)."""
    out = result.to_dict()
    timing = out["timing"]
    lines = [f"{result.scenario}: {result.samples} samples (seed {result.seed}) in {timing['simulate_s']:.2f} s, "
             f"{timing['chunks']} chunk(s)",
             "varied: " + ", ".join(f"{k} ~ {v}" for k, v in out["vary"].items()),
             f"{'metric':<40} {'mean':>10} {'q05':>10} {'q50':>10} {'q95':>10} {'n':>7}"]
    varied = {field.split(".", 1)[0] for field in out["vary"]}   # (their heading: a follower's second output)
    for name, s in out["metrics"].items():
        robot, metric = name.rsplit(".", 1)
        if s["n"] and (metric in ("error_mean", "error_rms", "error_max", "effort", "peak_omega", "min_distance")
                       or robot in varied and metric in ("heading_rms", "heading_max")):
            q = s["quantiles"]
            cells = [s["mean"], q["q05"], q["q50"], q["q95"]]
            lines.append(f"{name[:40]:<40} " + " ".join("      null" if v is None else f"{v:>10.4g}" for v in cells)
                         + f" {s['n']:>7}")
    lines.append("failures (95 % Wilson interval):")
    for name, f in out["failures"].items():
        lines.append(f"  {name:<10} {f['count']:>7}  p = {f['probability']:.4f}  "
                     f"[{f['ci95'][0]:.4f}, {f['ci95'][1]:.4f}]")
    for entry in out["worst"]:
        values = ", ".join(f"{k.rsplit('.', 2)[-2]}.{k.rsplit('.', 1)[1]} = {v:.4g}" for k, v in entry["values"].items())
        score = entry[result.worst_by]
        shown = "diverged" if score is None else f"{score:.4g}"
        line = f"  worst {entry['rank']}: sample {entry['sample']}, {result.worst_by.rsplit('.', 1)[1]} {shown} ({values})"
        lines.append(line[:100])
    return "\n".join(lines)
