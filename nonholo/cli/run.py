"""``nonholo run SCENARIO``: simulate a scenario file or a bundled example."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK


def register(subparsers) -> None:
    from nonholo import examples

    parser = subparsers.add_parser(
        "run", help="simulate a scenario file",
        description="Simulate the robots of a scenario (TOML file or bundled example) and report error "
                    "statistics on the uniform grid t_k = k*dt.",
        epilog=f"bundled examples: {', '.join(examples.names())}. Exit codes: 0 ok, 1 failure, 2 bad input.")
    parser.add_argument("scenario", help="a scenario .toml file, or the name of a bundled example")
    parser.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    parser.add_argument("--plot", metavar="FILE", help="write a figure (path, error, v, omega) to FILE")
    parser.add_argument("--out", metavar="DIR", help="write result.json, trajectories.csv and plot.png to DIR")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from nonholo import examples
    from nonholo.errors import NonholoInputError, SimulationError
    from nonholo.sim.files import load_scenario

    try:
        scenario = load_scenario(examples.resolve(args.scenario))
        if _is_formation(scenario):
            from nonholo.formation import simulate_formation
            from nonholo.formation.report import format_formation_summary

            result, formatter = simulate_formation(scenario), format_formation_summary
        else:
            from nonholo.sim.simulator import simulate

            result = simulate(scenario, record=bool(args.plot or args.out or not args.json),
                              progress=False if args.quiet else None)
            formatter = format_summary
    except NonholoInputError as exc:
        print(f"nonholo run: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SimulationError as exc:
        print(f"nonholo run: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    summary = result.to_dict()
    try:
        if args.plot:
            result.plot(path=args.plot)
        if args.out:
            write_outputs(result, summary, Path(args.out))
            if _is_formation(scenario):
                result.write_gif(Path(args.out) / "formation.gif")
    except (OSError, ValueError) as exc:  # unwritable place, unknown image format
        print(f"nonholo run: cannot write the outputs: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    if args.json:
        json.dump(summary, sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(formatter(summary))
    return EXIT_OK


def _is_formation(scenario) -> bool:
    from nonholo.formation.model import Formation

    return isinstance(scenario, Formation)


def write_outputs(result, summary: dict, out: Path) -> None:
    import numpy as np

    out.mkdir(parents=True, exist_ok=True)
    (out / "result.json").write_text(json.dumps(summary, indent=2, allow_nan=False))
    columns, header = [result.t], ["t"]
    for i, name in enumerate(result.names):
        for field in ("x", "y", "theta", "xi", "v", "omega"):
            columns.append(result.trajectory(field)[i])
            header.append(f"{name}.{field}")
    np.savetxt(out / "trajectories.csv", np.column_stack(columns), delimiter=",", header=",".join(header),
               comments="", fmt="%.9g")
    result.plot(path=out / "plot.png")


def format_summary(summary: dict) -> str:
    sim = summary["simulation"]
    lines = [f"{summary['scenario']}: {summary['reference']['kind']} reference, {sim['duration']:.6g} s, "
             f"{sim['steps']} steps of {sim['dt']:.4g} s ({sim['method']}), {sim['elapsed_s']:.3f} s",
             f"{'robot':<26} {'controller':<26} {'mean':>9} {'std':>9} {'max':>9} {'final':>9} "
             f"{'peak v':>8} {'peak w':>8}  events"]
    for name, robot in summary["robots"].items():
        e, c, ev = robot["error"], robot["control"], robot["events"]
        events = []
        if ev["saturated_v_samples"] or ev["saturated_omega_samples"]:
            events.append(f"saturated {100 * ev['saturated_fraction']:.1f}%")
        if ev["singular_samples"]:
            events.append(f"singular x{ev['singular_samples']} from t={ev['first_singular_time']:.3g}s")
        lines.append(f"{name:<26} {robot['controller']:<26} {e['mean']:9.4g} {e['std']:9.4g} {e['max']:9.4g} "
                     f"{e['final']:9.3g} {c['peak_v']:8.3g} {c['peak_omega']:8.3g}  {', '.join(events) or '-'}")
    lines.append("errors in metres on the uniform output grid; peak v in m/s, peak w in rad/s")
    return "\n".join(lines)
