"""Speed of the simulator against baselines measured in the same run.

The workload is the thesis's Test 1 (figure eight, 80π s) tracked by dynamic feedback
linearization from the origin, dt = 0.01 s (25 133 RK4 steps). Baselines:

* ``baseline_python_ms``: the same RK4 as a plain-Python loop (``math`` functions, the
  law's own Python source, the same precomputed reference table);
* ``baseline_solve_ivp_ms``: scipy ``solve_ivp`` (RK45, default tolerances, which is the
  fastest setting and so the least flattering comparison) with a Python right-hand side;
* ``baseline_numpy_batch_robot_steps_per_s``: RK4 of the whole batch as numpy array
  operations (the usual way to vectorize without a compiler).

Beside the no-follower batch, ``formation_robot_steps_per_s`` runs 10^3 copies of the bundled
7-follower chain (``formation-chain``: a leader under dynamic feedback and seven l–φ followers,
each reading its parent's stage values) as one batch, statistics only, over its first
``FORMATION_DURATION`` s.

**The work.** A robot-step is one robot over one output step. The RK4 steps per robot-step
(``batch_rk4_steps_per_robot_step``, ``formation_rk4_steps_per_robot_step``: the result's
``rk4_steps`` over the robot-steps) say what the sub-step plan cost each batch, runs again
included: 1 for one RK4 step per output step; the chains' start-up needs hundreds. A
figure that moves with it is a plan's change, not the kernel's speed.

**Interleaved.** Machines are shared and noisy: each subject and its baselines run in turn,
round after round (``interleaved``), and every figure is the median of its rounds, with the
spread (fastest and slowest round) beside it; a speed-up is the ratio of the medians, and its
spread the range of the ratios of the same round.

**Where the time goes** (``step_profile``, ``nonholo bench --profile``): the batch step taken
apart with the kernel's own compiled pieces run alone over the same batch — one law evaluation
as stage 1 makes it (``root_command``: sin/cos of θ, the law; the batch has no limits) and one
as stages 2–4 make it (sin/cos rotated from stage 1's, ``kernel.rotated_heading``), the sample
at t_k (errors, running statistics and event counts, ``_probe_samples``), the batch kernel's
own time loop (``Kernel.roots``: what it takes beyond the evaluations and the sample is the
plant and the RK4 combination), and a run of two steps (the Python set-up and result) — and
the single run taken apart into the reference table, the recording and the rest.
"""
from __future__ import annotations

import dataclasses
import math
import statistics
import subprocess
import sys
import time
from collections.abc import Callable

import numpy as np
from numba import njit
from scipy.integrate import solve_ivp

from nonholo import examples, references
from nonholo.control.feedback_linearization import dynamic_feedback_law
from nonholo.control.registry import controller
from nonholo.references.feedforward import REF_DDX, REF_DDY, REF_DX, REF_DY, REF_X, REF_Y
from nonholo.sim import kernel as kn
from nonholo.sim.files import load_scenario
from nonholo.sim.scenario import Robot, Scenario
from nonholo.sim.simulator import kernel_for, simulate
from nonholo.sim.targets import TABLE_COLUMNS

DT = 0.01
BATCH_ROBOTS = 10_000
BATCH_DURATION = 20.0
FORMATION_COPIES = 1_000
FORMATION_DURATION = 10.0


def single_scenario() -> Scenario:
    return Scenario(references.eight(), [Robot("leader", controller("dynamic-feedback"))], dt=DT)


def batch_scenario(n: int = BATCH_ROBOTS, duration: float = BATCH_DURATION) -> Scenario:
    rng = np.random.default_rng(0)
    starts = rng.normal(scale=0.5, size=(n, 3))
    dfl = controller("dynamic-feedback")
    return Scenario(references.eight(), [Robot(f"r{i}", dfl, tuple(s)) for i, s in enumerate(starts)], dt=DT,
                    duration=duration)


def formation_batch(copies: int = FORMATION_COPIES, duration: float = FORMATION_DURATION) -> list[Scenario]:
    """``copies`` copies of the bundled 7-follower chain. Identical copies: the batch then runs
    the example's own sub-step plan (perturbed starts would raise the start-up turn rates of
    the deep links, and with them the sub-steps of every member)."""
    chain = dataclasses.replace(load_scenario(examples.path("formation-chain")), duration=duration)
    return [chain] * copies


def interleaved(subjects: dict[str, Callable[[], object]], rounds: int,
                every: dict[str, int] | None = None) -> dict[str, list[float]]:
    """Wall times (s) of each subject over ``rounds`` rounds, the subjects run in turn within
    a round (each called once before, untimed: JIT caches, first-touch memory); a subject
    of ``every`` runs only in every n-th round (slow baselines)."""
    every = every or {}
    for function in subjects.values():
        function()
    times: dict[str, list[float]] = {name: [] for name in subjects}
    for round_ in range(rounds):
        for name, function in subjects.items():
            if round_ % every.get(name, 1):
                continue
            started = time.perf_counter()
            function()
            times[name].append(time.perf_counter() - started)
    return times


def cold_first_call_s() -> float:
    """The first ``simulate`` of a fresh process (imports excluded, JIT cache on disk)."""
    code = ("import time; from nonholo.sim.benchmark import single_scenario; from nonholo import simulate; "
            "s = single_scenario(); t = time.perf_counter(); simulate(s); print(time.perf_counter() - t)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=600)
    return float(out.stdout.strip().splitlines()[-1])


def python_rk4(scenario: Scenario) -> float:
    """Plain-Python RK4 of the single scenario; returns the mean error (as a check)."""
    rows = scenario.reference.table(np.arange(2 * scenario.n_steps + 1) * (scenario.dt / 2))
    gains = scenario.robots[0].controller.gain_values()
    law = dynamic_feedback_law.py_func
    x, y, theta = scenario.robots[0].start
    xi = rows[0, 8]
    h = scenario.dt
    total = 0.0

    def rates(x, y, theta, xi, ref):
        c, s = math.cos(theta), math.sin(theta)
        v, omega, xi_dot, _ = law(x, y, theta, c, s, xi, ref, gains)
        return v * c, v * s, omega, xi_dot

    for k in range(scenario.n_steps):
        r0, r1, r2 = tuple(rows[2 * k]), tuple(rows[2 * k + 1]), tuple(rows[2 * k + 2])
        total += math.hypot(r0[REF_X] - x, r0[REF_Y] - y)
        a1 = rates(x, y, theta, xi, r0)
        a2 = rates(x + h / 2 * a1[0], y + h / 2 * a1[1], theta + h / 2 * a1[2], xi + h / 2 * a1[3], r1)
        a3 = rates(x + h / 2 * a2[0], y + h / 2 * a2[1], theta + h / 2 * a2[2], xi + h / 2 * a2[3], r1)
        a4 = rates(x + h * a3[0], y + h * a3[1], theta + h * a3[2], xi + h * a3[3], r2)
        x += h / 6 * (a1[0] + 2 * a2[0] + 2 * a3[0] + a4[0])
        y += h / 6 * (a1[1] + 2 * a2[1] + 2 * a3[1] + a4[1])
        theta += h / 6 * (a1[2] + 2 * a2[2] + 2 * a3[2] + a4[2])
        xi += h / 6 * (a1[3] + 2 * a2[3] + 2 * a3[3] + a4[3])
    return total / scenario.n_steps


def scipy_solve_ivp(scenario: Scenario):
    reference = scenario.reference
    gains = scenario.robots[0].controller.gain_values()
    law = dynamic_feedback_law.py_func

    def rhs(t, q):
        ref = tuple(reference.table(np.array([t]))[0])
        c, s = math.cos(q[2]), math.sin(q[2])
        v, omega, xi_dot, _ = law(q[0], q[1], q[2], c, s, q[3], ref, gains)
        return [v * c, v * s, omega, xi_dot]

    start = [*scenario.robots[0].start, reference.table([0.0])[0, 8]]
    grid = np.arange(scenario.n_steps + 1) * scenario.dt
    return solve_ivp(rhs, (0.0, grid[-1]), start, t_eval=grid)


def numpy_batch(scenario: Scenario) -> None:
    """RK4 of every robot at once with numpy array operations (dynamic feedback)."""
    rows = scenario.reference.table(np.arange(2 * scenario.n_steps + 1) * (scenario.dt / 2))
    kp1, kp2, kd1, kd2, xi_min = scenario.robots[0].controller.gain_vector()
    q = np.array([[*r.start, rows[0, 8]] for r in scenario.robots]).T
    h = scenario.dt

    def rates(q, ref):
        c, s = np.cos(q[2]), np.sin(q[2])
        r1 = ref[REF_DDX] + kp1 * (ref[REF_X] - q[0]) + kd1 * (ref[REF_DX] - q[3] * c)
        r2 = ref[REF_DDY] + kp2 * (ref[REF_Y] - q[1]) + kd2 * (ref[REF_DY] - q[3] * s)
        guarded = np.where(np.abs(q[3]) < xi_min, np.where(q[3] >= 0, xi_min, -xi_min), q[3])
        return np.stack([q[3] * c, q[3] * s, (r2 * c - r1 * s) / guarded, r1 * c + r2 * s])

    for k in range(scenario.n_steps):
        a1 = rates(q, rows[2 * k])
        a2 = rates(q + h / 2 * a1, rows[2 * k + 1])
        a3 = rates(q + h / 2 * a2, rows[2 * k + 1])
        a4 = rates(q + h * a3, rows[2 * k + 2])
        q = q + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)


def run_benchmark(repeats: int = 15, progress=None, rounds: int = 5) -> dict:
    """All figures of ``nonholo bench`` (see the module docstring): medians over interleaved
    rounds (``repeats`` rounds for the single run and its baselines, ``rounds`` for the
    batch and its baseline), with ``spread`` = {figure: [fastest, slowest]}."""
    say = progress or (lambda message: None)
    single = single_scenario()
    say(f"single simulation, solve_ivp and plain Python, interleaved ({repeats} rounds)")
    python_every = max(1, repeats // 5)   # the plain-Python loop is slow: five of the rounds
    times = interleaved({"single": lambda: simulate(single), "solve_ivp": lambda: scipy_solve_ivp(single),
                         "python": lambda: python_rk4(single)}, repeats, {"python": python_every})
    say("cold first call in a fresh process")
    cold_s = cold_first_call_s()
    say(f"batch of 10^4 robots and the numpy batch, interleaved ({rounds} rounds)")
    batch, small = batch_scenario(), batch_scenario(duration=2.0)
    last = {}   # the batch's last result: the RK4 steps its sub-step plan cost
    batch_times = interleaved({"batch": lambda: last.update(batch=simulate(batch, record=False)),
                               "numpy": lambda: numpy_batch(small)}, rounds)
    say("batch of 10^3 seven-follower chains")
    simulate(formation_batch(2), record=False)   # compiled before the clock starts
    chains = formation_batch()
    started = time.perf_counter()   # one run: it takes tens of seconds (its start-up needs hundreds of sub-steps)
    chains_run = simulate(chains, record=False)
    formation_s = time.perf_counter() - started
    formation_work = FORMATION_COPIES * len(chains[0].robots) * chains[0].n_steps
    batch_work, numpy_work = BATCH_ROBOTS * batch.n_steps, BATCH_ROBOTS * small.n_steps
    rates = {"batch": [batch_work / t for t in batch_times["batch"]],
             "numpy": [numpy_work / t for t in batch_times["numpy"]]}
    ms = {name: [1e3 * t for t in values] for name, values in times.items()}
    figures = {
        "single_ms": statistics.median(ms["single"]),
        "single_cold_s": cold_s,
        "batch_robot_steps_per_s": statistics.median(rates["batch"]),
        "formation_robot_steps_per_s": formation_work / formation_s,
        "batch_rk4_steps_per_robot_step": last["batch"].rk4_steps / batch_work,
        "formation_rk4_steps_per_robot_step": chains_run.rk4_steps / formation_work,
        "baseline_python_ms": statistics.median(ms["python"]),
        "baseline_solve_ivp_ms": statistics.median(ms["solve_ivp"]),
        "baseline_numpy_batch_robot_steps_per_s": statistics.median(rates["numpy"]),
    }
    figures["speedup_vs_python"] = figures["baseline_python_ms"] / figures["single_ms"]
    figures["speedup_vs_solve_ivp"] = figures["baseline_solve_ivp_ms"] / figures["single_ms"]
    figures["batch_speedup_vs_numpy"] = (figures["batch_robot_steps_per_s"]
                                         / figures["baseline_numpy_batch_robot_steps_per_s"])
    python_rounds = range(0, repeats, python_every)
    figures["spread"] = {
        "single_ms": _range(ms["single"]),
        "batch_robot_steps_per_s": _range(rates["batch"]),
        "baseline_python_ms": _range(ms["python"]),
        "baseline_solve_ivp_ms": _range(ms["solve_ivp"]),
        "baseline_numpy_batch_robot_steps_per_s": _range(rates["numpy"]),
        "speedup_vs_python": _range([ms["python"][i] / ms["single"][j] for i, j in enumerate(python_rounds)]),
        "speedup_vs_solve_ivp": _range([a / b for a, b in zip(ms["solve_ivp"], ms["single"])]),
        "batch_speedup_vs_numpy": _range([a / b for a, b in zip(rates["batch"], rates["numpy"])]),
    }
    figures["rounds"] = {"single": repeats, "python": len(ms["python"]), "batch": rounds}
    return figures


def _range(values: list[float]) -> list[float]:
    return [min(values), max(values)]


# --- where the time goes ---------------------------------------------------------------------

_PROBE = dict(error_model="numpy", fastmath={"contract"})   # as the kernel of lone roots


@njit(**_PROBE)
def _probe_commands(law, gains, state, rows, n_steps, sink):
    """One law evaluation per robot and step as RK4 stage 1 makes it (``root_command``: sin/cos
    of θ in full, the law; the limits, inf constants, folded away as the batch's time loop
    without limits leaves them out)."""
    for k in range(n_steps):
        ref = kn.row_values(rows, 2 * k)
        for b in range(state.shape[1]):
            v, omega, xi_dot, singular, sat_v, sat_w, _, _ = kn.root_command(
                law, gains, state[0, b], state[1, b], state[2, b], state[3, b], ref, np.inf, np.inf)
            sink[b] += v + omega + xi_dot + singular + sat_v + sat_w


@njit(**_PROBE)
def _probe_rotated_commands(law, gains, state, heading, rows, n_steps, sink):
    """One law evaluation per robot and step as RK4 stages 2–4 make it: sin/cos of θ + δ
    rotated from stage 1's (``heading``: sin θ, cos θ per robot; δ = 5·10⁻³, in range), the
    law (the limits folded away, as in ``_probe_commands``)."""
    for k in range(n_steps):
        ref = kn.row_values(rows, 2 * k + 1)
        for b in range(state.shape[1]):
            theta = state[2, b] + 5e-3
            s, c = kn.rotated_heading(heading[0, b], heading[1, b], 5e-3, theta)
            v, omega, xi_dot, singular, sat_v, sat_w = kn.law_command(
                law, gains, state[0, b], state[1, b], theta, s, c, state[3, b], ref, np.inf, np.inf)
            sink[b] += v + omega + xi_dot + singular + sat_v + sat_w


@njit(**_PROBE)
def _probe_samples(state, rows, n_steps, stats):
    """The sample at t_k alone, as ``Kernel.roots`` adds it in stage 1's loop: each robot's
    errors against the reference row and its running statistics and event counts updated
    (``root_errors``, ``add_sample``), ``ROOTS_CHUNK`` robots at a time through the whole time
    range (their statistics in the core's caches, as the kernel's); ξ and θ̇ = 0 stand for the
    command (v, ω)."""
    n = state.shape[1]
    for start in range(0, n, kn.ROOTS_CHUNK):
        c0, c1 = np.uint64(start), np.uint64(min(start + kn.ROOTS_CHUNK, n))
        for k in range(n_steps):
            ref = kn.row_values(rows, 2 * k)
            for b in range(c0, c1):
                x, y, theta, xi = state[0, b], state[1, b], state[2, b], state[3, b]
                # (not a posture law: no goal read from the fields argument)
                err1, err2 = kn.root_errors(False, stats, 0, b, x, y, theta, ref)
                kn.store_stats(stats, 0, b, kn.add_sample(kn.robot_stats(stats, 0, b), ref[0], k, xi, 0.0, 0.0, 0.0,
                                                          0.0, err1, err2))


PROFILE_PARTS = (
    ("law", "law: 4 evaluations (the sample takes the first)"),
    ("plant_rk4", "plant and RK4 combination"),
    ("sample", "the sample at t_k: errors, statistics, events"),
    ("setup", "set-up and result (Python, once per run)"),
    ("rest", "the rest: between kernel and simulator"),
    ("step", "whole step (the batch figure)"),
)


def step_profile(robots: int = BATCH_ROBOTS, duration: float = BATCH_DURATION, rounds: int = 3,
                 progress=None) -> dict:
    """Where a step's time goes (see the module docstring): ns per robot-step of the batch's
    parts (``PROFILE_PARTS``), and for the single run its reference table, recording and the
    rest in ms. Medians over interleaved rounds."""
    say = progress or (lambda message: None)
    batch = batch_scenario(robots, duration)
    config = batch.robots[0].controller
    law, gains = config.law, config.gain_values()
    n_steps = batch.n_steps
    rows = batch.reference.table(np.arange(2 * n_steps + 3) * (DT / 2))
    state = np.array([[*r.start, rows[0, 8]] for r in batch.robots]).T.copy()
    sink = np.zeros(robots)
    heading = np.array([np.sin(state[2]), np.cos(state[2])])
    kernel = kernel_for(((law, config.controller.gain_tuple),), False)
    fields = np.zeros((kn.MAX_FIELDS, 1, robots))
    fields[:len(gains)] = np.array(gains)[:, None, None]
    graph = (np.full((2, 1, robots), np.inf), rows, 2 * np.arange(n_steps + 1), np.ones(n_steps, np.int64),
             np.zeros((1, len(TABLE_COLUMNS), 1)), np.zeros((2, 1, robots)), np.full(1, kn.ROOT_A, np.int64),
             np.zeros(1, np.int64), np.full((2, 1), -1, np.int64), np.zeros(1, np.int64), np.zeros((1, robots)), batch.sin_floor,
             np.zeros(robots), 0.0, DT, 0)

    def kernel_alone():   # the batch's own time loop (``Kernel.roots``), without the simulator around it
        stats, pair_stats = kn.new_stats(1, robots)
        kernel.roots(state[:, None, :].copy(), fields, *graph, 0, n_steps, n_steps, stats, pair_stats,
                     np.empty((kn.REC_COUNT, 0, 1, robots)), np.zeros((kn.HELD_COUNT, 1, robots)),
                     np.zeros(n_steps + 1), False)

    short = batch_scenario(robots, 2 * DT)   # two steps: the run's set-up and result alone
    say("the batch step's parts")
    times = interleaved({
        "setup": lambda: simulate(short, record=False),
        "command": lambda: _probe_commands(law, gains, state, rows, n_steps, sink),
        "rotated": lambda: _probe_rotated_commands(law, gains, state, heading, rows, n_steps, sink),
        "sample": lambda: _probe_samples(state, rows, n_steps, kn.new_stats(1, robots)[0]),
        "kernel": kernel_alone, "step": lambda: simulate(batch, record=False)}, rounds)
    ns = {name: 1e9 * statistics.median(values) / (robots * n_steps) for name, values in times.items()}
    law_ns = ns["command"] + 3.0 * ns["rotated"]   # stage 1's evaluation, and stages 2–4's
    parts = {"law": law_ns, "plant_rk4": ns["kernel"] - law_ns - ns["sample"],
             "sample": ns["sample"], "setup": ns["setup"], "step": ns["step"]}
    parts["rest"] = parts["step"] - sum(parts[name] for name in ("law", "plant_rk4", "sample", "setup"))
    say("the single run's parts")
    single = single_scenario()
    table_times = np.arange(2 * single.n_steps + 1) * (DT / 2)
    single_times = interleaved({"recorded": lambda: simulate(single), "statistics": lambda: simulate(single, record=False),
                                "reference": lambda: single.reference.table(table_times)}, 5 * rounds)
    single_ms = {name: 1e3 * statistics.median(values) for name, values in single_times.items()}
    return {"batch_ns_per_robot_step": parts, "robots": robots, "steps": n_steps,
            "single_ms": {"whole": single_ms["recorded"], "reference_table": single_ms["reference"],
                          "recording": single_ms["recorded"] - single_ms["statistics"],
                          "rest": single_ms["statistics"] - single_ms["reference"]},
            "single_steps": single.n_steps}
