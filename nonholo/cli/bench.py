"""``nonholo bench``: simulator speed against baselines measured in the same run."""
from __future__ import annotations

import json
import sys

TARGETS = (
    ("single_ms", "single simulation (Test 1, DFL, dt = 0.01 s)", "ms", "<= 4.5"),
    ("single_cold_s", "first call in a fresh process (JIT cache on disk)", "s", ""),
    ("batch_robot_steps_per_s", "batch of 10^4 robots", "robot-steps/s", ">= 1e8"),
    ("formation_robot_steps_per_s", "batch of 10^3 chains of a leader and 7 followers", "robot-steps/s", ""),
    ("baseline_python_ms", "baseline: plain-Python RK4 loop", "ms", ""),
    ("baseline_solve_ivp_ms", "baseline: scipy solve_ivp (RK45, default tolerances)", "ms", ""),
    ("baseline_numpy_batch_robot_steps_per_s", "baseline: numpy-vectorized batch", "robot-steps/s", ""),
    ("speedup_vs_python", "single vs plain Python", "x", ">= 15"),
    ("speedup_vs_solve_ivp", "single vs solve_ivp", "x", ">= 5"),
    ("batch_speedup_vs_numpy", "batch vs numpy batch", "x", ">= 10"),
)


def register(subparsers) -> None:
    parser = subparsers.add_parser("bench", help="measure simulator speed against baselines",
                                   description="Measure the simulator on the thesis's Test 1 (single run and a "
                                               "batch of 10^4 robots) against plain-Python, solve_ivp and numpy "
                                               "baselines measured in the same run.")
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    parser.add_argument("--repeats", type=int, default=15, help="timed repetitions of the single run")
    parser.set_defaults(handler=handle)


def handle(args) -> int:
    from nonholo.sim.benchmark import run_benchmark

    progress = None if args.json else (lambda message: print(f"  measuring {message}...", file=sys.stderr))
    figures = run_benchmark(args.repeats, progress)
    if args.json:
        print(json.dumps(figures))
        return 0
    for key, label, unit, target in TARGETS:
        value = figures[key]
        shown = f"{value:.3g}" if value >= 1e5 else f"{value:.2f}"
        print(f"{label:<55} {shown:>10} {unit:<14} {('target ' + target) if target else ''}")
    return 0
