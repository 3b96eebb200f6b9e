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
"""
from __future__ import annotations

import dataclasses
import math
import statistics
import subprocess
import sys
import time

import numpy as np
from scipy.integrate import solve_ivp

from nonholo import examples, references
from nonholo.control.feedback_linearization import dynamic_feedback_law
from nonholo.control.registry import controller
from nonholo.references.feedforward import REF_DDX, REF_DDY, REF_DX, REF_DY, REF_X, REF_Y
from nonholo.sim.files import load_scenario
from nonholo.sim.scenario import Robot, Scenario
from nonholo.sim.simulator import simulate

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


def median_time(function, repeats: int) -> float:
    function()
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        function()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


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


def run_benchmark(repeats: int = 15, progress=None) -> dict:
    """All figures of ``nonholo bench`` (see the module docstring)."""
    say = progress or (lambda message: None)
    single = single_scenario()
    say("single simulation")
    single_s = median_time(lambda: simulate(single), repeats)
    say("cold first call in a fresh process")
    cold_s = cold_first_call_s()
    say("batch of 10^4 robots")
    batch = batch_scenario()
    batch_s = median_time(lambda: simulate(batch, record=False), 3)
    batch_work = BATCH_ROBOTS * batch.n_steps
    say("batch of 10^3 seven-follower chains")
    simulate(formation_batch(2), record=False)   # compiled before the clock starts
    chains = formation_batch()
    started = time.perf_counter()   # one run: it takes tens of seconds (its start-up needs hundreds of sub-steps)
    simulate(chains, record=False)
    formation_s = time.perf_counter() - started
    formation_work = FORMATION_COPIES * len(chains[0].robots) * chains[0].n_steps
    say("baseline: plain-Python RK4 loop")
    python_s = median_time(lambda: python_rk4(single), 1)
    say("baseline: scipy solve_ivp")
    ivp_s = median_time(lambda: scipy_solve_ivp(single), 3)
    say("baseline: numpy batch")
    small = batch_scenario(duration=2.0)
    numpy_s = median_time(lambda: numpy_batch(small), 1)
    figures = {
        "single_ms": 1e3 * single_s,
        "single_cold_s": cold_s,
        "batch_robot_steps_per_s": batch_work / batch_s,
        "formation_robot_steps_per_s": formation_work / formation_s,
        "baseline_python_ms": 1e3 * python_s,
        "baseline_solve_ivp_ms": 1e3 * ivp_s,
        "baseline_numpy_batch_robot_steps_per_s": BATCH_ROBOTS * small.n_steps / numpy_s,
    }
    figures["speedup_vs_python"] = figures["baseline_python_ms"] / figures["single_ms"]
    figures["speedup_vs_solve_ivp"] = figures["baseline_solve_ivp_ms"] / figures["single_ms"]
    figures["batch_speedup_vs_numpy"] = (figures["batch_robot_steps_per_s"]
                                         / figures["baseline_numpy_batch_robot_steps_per_s"])
    return figures
