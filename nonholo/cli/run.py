"""``nonholo run SCENARIO``: simulate a scenario file or a bundled example."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK, wrap


def register(subparsers) -> None:
    from nonholo import examples

    parser = subparsers.add_parser(
        "run", help="simulate a scenario file",
        description="Simulate the robots of a scenario (TOML file or bundled example) and report error "
                    "statistics on the uniform grid t_k = k*dt. A [network] link model (delay, jitter, loss, "
                    "seed, watchdog) applies to sampled-data runs as in `nonholo fleet --mode lockstep`, which "
                    "this run then equals.",
        epilog=f"bundled examples: {', '.join(examples.names())}. Exit codes: 0 ok, 1 failure, 2 bad input.")
    parser.add_argument("scenario", help="a scenario .toml file, or the name of a bundled example")
    parser.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
    parser.add_argument("--plot", metavar="FILE", help="write a figure (path, error, v, omega) to FILE")
    parser.add_argument("--out", metavar="DIR",
                        help="write result.json, trajectories.csv (tidy: a row per robot and sample, units in the "
                             "header), plot.png and, for formations and posture runs, formation.gif to DIR")
    parser.add_argument("--every", type=int, default=1, metavar="N",
                        help="keep every N-th sample in trajectories.csv (default: all)")
    parser.add_argument("--animate", metavar="FILE", help="write an animation of the run: FILE.gif, or FILE.mp4 "
                                                           "when ffmpeg is installed")
    parser.add_argument("--record", metavar="FILE.mcap",
                        help="write an MCAP recording (poses, commands, reference, formation errors, links) that "
                             "Foxglove opens and `nonholo view` replays: at most 100 samples per simulated second, "
                             "and every N-th with --every N")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from nonholo import examples
    from nonholo.errors import NonholoInputError, SimulationError
    from nonholo.sim.files import load_scenario

    try:
        source = examples.resolve(args.scenario)
        scenario = load_scenario(source)
        from nonholo.sim.simulator import check_network, simulate

        # [network]: its link model applies here as in a lockstep fleet (it needs control_period);
        # the whole table is checked as `nonholo fleet` checks it (a misspelt field is not ignored).
        try:
            check_network([scenario])
        except NonholoInputError as exc:   # a problem of the file: name it, as the reader does
            raise NonholoInputError(f"{source}: network: {exc}") from None
        from nonholo.fleet.config import load_fleet

        load_fleet(source)

        if args.every < 1:
            raise NonholoInputError(f"--every must be a positive integer, got {args.every}")
        check_output_names(args.plot, args.animate)
        if args.record:   # an optional dependency: say so before the run, not after it
            from nonholo.view import require

            require("mcap")
        recorded = bool(args.plot or args.out or args.animate or args.record or not args.json
                        or any(getattr(robot, "changes", ()) for robot in scenario.robots))   # (settling)
        try:
            result = simulate(scenario, record=recorded, progress=False if args.quiet else None)
        except NonholoInputError as exc:   # found while simulating (an infeasible reference, too stiff a law)
            raise NonholoInputError(f"{source}: {exc}") from None
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
            for written in write_outputs(result, summary, Path(args.out), args.every, progress=not args.quiet):
                print(f"wrote {written}", file=sys.stderr)
        if args.animate:
            result.write_gif(args.animate, progress=not args.quiet and sys.stderr.isatty())
            print(f"wrote {args.animate}", file=sys.stderr)
        if args.record:
            from nonholo.view.data import from_result
            from nonholo.view.record import record_every, write_recording

            write_recording(from_result(result, record_every(result.scenario.dt, args.every), summary), args.record)
            print(f"wrote {args.record}", file=sys.stderr)
    except (OSError, ValueError) as exc:  # unwritable place, unknown image format
        print(f"nonholo run: cannot write the outputs: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    if args.json:
        json.dump(summary, sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print(format_summary(summary))
    return EXIT_OK


def check_output_names(plot: str | None, animate: str | None) -> None:
    """Before the run: a figure's format from its name (matplotlib's), an animation .gif or
    .mp4 (ffmpeg installed); NonholoInputError naming the option."""
    from nonholo.errors import NonholoInputError

    if plot:
        from matplotlib.figure import Figure

        formats = Figure().canvas.get_supported_filetypes()
        suffix = Path(plot).suffix.lstrip(".").lower()
        if suffix not in formats:
            raise NonholoInputError(f"--plot {plot}: {'unknown image format ' + repr(suffix) if suffix else 'no format'}"
                                    " (name it .png, .pdf, .svg or another of matplotlib's formats)")
    if animate:
        suffix = Path(animate).suffix.lower()
        if suffix not in (".gif", ".mp4"):
            raise NonholoInputError(f"--animate {animate}: name it .gif (or .mp4, with ffmpeg)")
        if suffix == ".mp4":
            from matplotlib.animation import FFMpegWriter

            if not FFMpegWriter.isAvailable():
                raise NonholoInputError(f"--animate {animate}: MP4 needs ffmpeg, which is not installed: "
                                        "write a .gif instead")


def write_outputs(result, summary: dict, out: Path, every: int = 1, progress: bool = False) -> list[Path]:
    """result.json, trajectories.csv (tidy: one row per robot and sample, units in the
    header), plot.png and, for formations and posture runs, formation.gif."""
    out.mkdir(parents=True, exist_ok=True)
    written = [out / "result.json", out / "trajectories.csv", out / "plot.png"]
    written[0].write_text(json.dumps(summary, indent=2, allow_nan=False))
    result.write_csv(written[1], every=every)
    result.plot(path=written[2])
    scenario = result.scenario
    if scenario.followers or any(r.posture for r in scenario.roots):
        written.append(result.write_gif(out / "formation.gif", progress=progress and sys.stderr.isatty()))
    return written


def _g(value, width: int = 9) -> str:
    return f"{'-':>{width}}" if value is None else f"{value:{width}.3g}"


def _fit(value: float, width: int = 7) -> str:
    """``value`` in at most ``width`` characters, as many digits as fit (the table stays within 100 columns)."""
    for text in (f"{value:.3g}", f"{value:.2g}", f"{value:.0e}"):
        if len(text) <= width:
            return f"{text:>{width}}"
    return f"{value:>{width}.0e}"


def _labelled(name: str, law: str, rows: list[str]) -> list[str]:
    """Table lines of one robot: its name and law in the first columns of its first row, or,
    when either is longer than its column, on a line of their own above rows that leave those
    columns blank (a name is never cut: two robots must not look alike)."""
    if len(name) <= 16 and len(law) <= 26:
        return [f"{name:<16} {law:<26} {rows[0]}".rstrip()] + [f"{'':<43} {row}".rstrip() for row in rows[1:]]
    return [f"{name}: {law}"] + [f"{'':<43} {row}".rstrip() for row in rows]


def format_summary(summary: dict) -> str:
    """A terminal summary (at most 100 columns): a line per robot, then safety."""
    sim = summary["simulation"]
    reference = summary["reference"]["kind"] + " reference" if summary["reference"] else "no reference"
    lines = [f"{summary['scenario']}: {reference}, {sim['duration']:.6g} s, {sim['steps']} steps of {sim['dt']:.4g} s "
             f"({sim['method']}, up to {sim['max_substeps']} sub-step{'s' if sim['max_substeps'] != 1 else ''}), "
             f"run in {sim['elapsed_s']:.2f} s",
             f"{'robot':<16} {'law':<26} {'what':<10} {'mean':>9} {'max':>9} {'final':>9} {'peak v':>7} {'peak w':>7}"]
    notes = []
    for name, robot in summary["robots"].items():
        c, ev = robot["control"], robot["events"]
        peaks = f"{_fit(c['peak_v'])} {_fit(c['peak_omega'])}"
        if robot["role"] == "follower":
            f = robot["formation"]
            law = f"{'l-phi' if f['law'] == 'separation-bearing' else 'l-l'} of {', '.join(f['leaders'])}"
            rows = [f"{key[:-6] + (' (rad)' if key == 'phi_error' else ' (m)'):<10} {_g(e['mean'])} {_g(e['max'])} "
                    f"{_g(e['final'])} {peaks if j == 0 else ''}"
                    for j, (key, e) in enumerate((k, v) for k, v in f.items() if k.endswith("_error"))]
            lines += _labelled(name, law, rows)
            s = f["safety"]
            extra = f", min |sin(g1-g2)| {s['min_abs_sin_gamma_difference']:.3g}" if "min_abs_sin_gamma_difference" in s \
                else ""
            if s.get("sin_gamma_sign_changes"):   # the singular configuration passed between two samples
                extra += (f", sin(g1-g2) changed sign {s['sin_gamma_sign_changes']} time(s) between samples: the "
                          "l-l singularity was crossed, results after it depend on the step")
            notes.append(f"{name}: closest robot {_g(s['min_distance'], 0)} m at t = {_g(s['min_distance_time'], 0)} s, "
                         f"{s['time_below_2d']:.3g} s below 2d{extra}")
            for change in f["settling"] or []:
                parts = [f"{k.replace('_settling_time', '')} settles in {_g(v, 0)} s" for k, v in change.items()
                         if k.endswith("_settling_time")]
                parts += [f"{k.replace('_disturbance', '')} deviates at most {_g(v, 0)}" for k, v in change.items()
                          if k.endswith("_disturbance")]
                notes.append(f"{name}: change at {change['at']:g} s ({change['mode']}): {', '.join(parts)}")
        elif "posture" in robot:
            p = robot["posture"]
            lines += _labelled(name, robot["controller"], [f"{'goal (m)':<10} {'':>9} {_g(p['position_error']['max'])} "
                                                          f"{_g(p['position_error']['final'])} {peaks}"])
            notes.append(f"{name}: goal distance final {p['position_error']['final']:.3g} m, heading error final "
                         f"{p['heading_error']['final']:.3g} rad" + (f" ({p['note']})" if "note" in p else ""))
        else:
            e = robot["error"]
            lines += _labelled(name, robot["controller"], [f"{'error (m)':<10} {_g(e['mean'])} {_g(e['max'])} "
                                                          f"{_g(e['final'])} {peaks}"])
        events = []
        if ev["saturated_v_samples"] or ev["saturated_omega_samples"]:
            events.append(f"saturated {100 * ev['saturated_fraction']:.1f}% of samples")
        if ev["singular_samples"]:
            events.append(f"singular x{ev['singular_samples']} from t = {ev['first_singular_time']:.3g} s")
        if ev.get("watchdog_stops"):
            events.append(f"its watchdog stopped it {ev['watchdog_stops']} time(s), "
                          f"{ev['watchdog_stopped_s']:.4g} s stopping or stopped")
        if events:
            notes.append(f"{name}: {', '.join(events)}")
    safety = summary["safety"]
    if safety.get("min_distance") is not None:
        notes.append(f"closest pair {' / '.join(safety['min_distance_pair'])}: {safety['min_distance']:.4g} m at "
                     f"t = {safety['min_distance_time']:.4g} s; {safety['time_below_2d']:.4g} s closer than "
                     f"2d = {safety['two_d']:g} m")
    links = sim.get("link_model")
    if links:
        w = links["watchdog"]
        overrides = f", {len(links['links'])} link(s) overridden" if links["links"] else ""
        notes.append(f"link model (seed {links['seed']}): delay {links['delay']:g} s + jitter up to {links['jitter']:g} "
                     f"s, loss {links['loss']:g}{overrides}; watchdog stops a follower beyond {w['stale_after']:g} s"
                     + ("; parents' states predicted over their age" if links.get("predict") else ""))
    lines += notes
    lines.append("errors on the uniform output grid; peak v in m/s, peak w in rad/s")
    # long names and notes wrap (continuation lines indented): the terminal output fits 100 columns
    return "\n".join(wrap(line) for line in lines)

