"""``nonholo bench``: simulator speed against baselines measured in the same run."""
from __future__ import annotations

import argparse
import json
import sys

TARGETS = (
    ("single_ms", "single simulation (Test 1, DFL, dt = 0.01 s)", "ms", "<= 4.5"),
    ("single_cold_s", "first call, fresh process (JIT cache on disk)", "s", ""),
    ("batch_robot_steps_per_s", "batch of 10^4 robots", "robot-steps/s", ">= 1.1e8"),
    ("formation_robot_steps_per_s", "batch of 10^3 chains (leader + 7 followers)", "robot-steps/s", ""),
    ("batch_rk4_steps_per_robot_step", "RK4 steps per robot-step, batch of 10^4", "x", ""),
    ("formation_rk4_steps_per_robot_step", "RK4 steps per robot-step, chains", "x", ""),
    ("baseline_python_ms", "baseline: plain-Python RK4 loop", "ms", ""),
    ("baseline_solve_ivp_ms", "baseline: solve_ivp (RK45, default tolerances)", "ms", ""),
    ("baseline_numpy_batch_robot_steps_per_s", "baseline: numpy-vectorized batch", "robot-steps/s", ""),
    ("speedup_vs_python", "single vs plain Python", "x", ">= 15"),
    ("speedup_vs_solve_ivp", "single vs solve_ivp", "x", ">= 10"),
    ("batch_speedup_vs_numpy", "batch vs numpy batch", "x", ">= 12"),
)


def register(subparsers) -> None:
    parser = subparsers.add_parser("bench", help="measure simulator speed against baselines",
                                   description="Measure the simulator on the thesis's Test 1 (single run and a "
                                               "batch of 10^4 robots) against plain-Python, solve_ivp and numpy "
                                               "baselines measured in the same run.")
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    parser.add_argument("--repeats", type=positive, default=15,
                        help="interleaved rounds of the single run and its baselines (default: %(default)s)")
    parser.add_argument("--rounds", type=positive, default=5,
                        help="interleaved rounds of the batch and the numpy batch (default: %(default)s)")
    parser.add_argument("--profile", action="store_true",
                        help="also say where a step's time goes: law, plant and RK4, sample, statistics, rest "
                             "(batch, ns per robot-step) and reference table, recording (single run)")
    parser.set_defaults(handler=handle)


def positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"a positive whole number, got {text!r}")
    return value


def handle(args) -> int:
    from nonholo.sim.benchmark import PROFILE_PARTS, run_benchmark, step_profile

    progress = None if args.json else (lambda message: print(f"  measuring {message}...", file=sys.stderr))
    figures = run_benchmark(args.repeats, progress, args.rounds)
    if args.profile:
        figures["profile"] = step_profile(progress=progress)
    if args.json:
        print(json.dumps(figures))
        return 0
    print(f"{'figure (median of interleaved rounds)':<46} {'median':>9} {'':<13} {'spread':<17} target")
    for key, label, unit, target in TARGETS:
        spread = figures["spread"].get(key)
        low_high = f"{shown(spread[0])}–{shown(spread[1])}" if spread else ""
        value = f"{figures[key]:.3f}" if key.endswith("rk4_steps_per_robot_step") else shown(figures[key])
        print(f"{label[:46]:<46} {value:>9} {unit:<13} {low_high:<17} {target}".rstrip())
    if args.profile:
        profile = figures["profile"]
        print(f"\nwhere a batch step goes (dynamic feedback, {profile['robots']} robots x {profile['steps']} steps)")
        parts = profile["batch_ns_per_robot_step"]
        for key, label in PROFILE_PARTS:
            print(part_line(label, parts[key], parts["step"]))
        single = profile["single_ms"]
        print(f"where a single run goes ({profile['single_steps']} steps, recorded, {single['whole']:.2f} ms)")
        for key, label in (("reference_table", "reference table"), ("recording", "recording"),
                           ("rest", "the rest: integration, statistics, result")):
            value = f"{single[key]:>6.2f}" if single[key] > 0 else "    ~0"   # a difference of medians
            print(f"  {label:<50} {value} ms")
    return 0


def part_line(label: str, ns: float, step_ns: float) -> str:
    """One line of where a batch step goes. A part that is a difference of medians of loops
    timed apart can come out at or below zero within the machine's noise: shown as ~0."""
    if ns <= 0:
        return f"  {label:<50}     ~0 ns per robot-step"
    return f"  {label:<50} {ns:>6.1f} ns per robot-step  {100 * ns / step_ns:>4.0f} %"


def shown(value: float) -> str:
    return f"{value:.3g}" if value >= 1e5 else f"{value:.2f}"
