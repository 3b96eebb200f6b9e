"""Compiled batch integration: fixed-step RK4 of the unicycle under a tracking law.

Data layout (structure of arrays, robots innermost so that loops vectorize):

* ``state``  (4, n): x, y, θ, ξ (ξ = dynamic compensator; constant for static laws)
* ``gains``  (g, n): the law's gain vector per robot
* ``limits`` (2, n): |v| ≤ v_max, |ω| ≤ ω_max (inf = no limit)
* ``rows``   (r, 10): the reference evaluated at every stage time (``REF_COLUMNS``);
  output step k with m_k sub-steps owns rows ``row_start[k] … row_start[k] + 2 m_k``
  (times t_k + j h/2, h = dt/m_k), the last one shared with step k + 1
* ``stats``  (STAT_COUNT, n): running statistics sampled at t_k = k·dt (Welford mean)
* ``record`` (6, N + 1, n) or (6, 0, n): x, y, θ, ξ, v, ω on the output grid
* ``held``   (3, n): v, ω, ξ̇ held between control instants (sampled-data mode)

Each RK4 sub-step is one loop over robots that keeps the four stages in registers, so
memory is touched once per robot and step and the loop compiles to SIMD code. The kernel
mutates ``state``, ``stats``, ``record`` and ``held`` and can be resumed
(``k_start``/``k_stop``), so callers can show progress. One kernel is compiled per law
(``make_integrator``) and cached on disk by numba.
"""
from __future__ import annotations

import math

import llvmlite.binding
import numpy as np
from numba import njit

from nonholo.models.unicycle import unicycle_rates
from nonholo.numerics import sincos, wrap_angle
from nonholo.references.feedforward import REF_THETA, REF_X, REF_Y

# The robot loops read and write many rows of distinct arrays, which LLVM cannot prove
# disjoint; past its default of 8 run-time overlap checks it refuses to vectorize
# ("too many memory checks needed"). These limits only allow more such checks (a few
# comparisons per loop, not per robot); the options are process-wide.
llvmlite.binding.set_option("nonholo", "-runtime-memory-check-threshold=64")
llvmlite.binding.set_option("nonholo", "-vectorize-memory-check-threshold=256")

(E_MEAN, E_M2, E_SQ, E_MAX, E_FINAL, H_SUM, H_SQ, H_MAX, H_FINAL, V_PEAK, W_PEAK, V_SQ, W_SQ,
 SAT_V, SAT_W, SINGULAR, FIRST_SINGULAR) = range(17)
STAT_COUNT = 17
REC_X, REC_Y, REC_THETA, REC_XI, REC_V, REC_OMEGA = range(6)
HELD_V, HELD_OMEGA, HELD_XI_DOT = range(3)

_OPTIONS = dict(cache=True, error_model="numpy")


def new_stats(n: int) -> np.ndarray:
    stats = np.zeros((STAT_COUNT, n))
    stats[FIRST_SINGULAR] = np.inf
    return stats


@njit(inline="always", **_OPTIONS)
def sample_robot(stats, k, i, state_i, command, ref):
    """Add robot i's sample at output step k (time ref[0]) to its running statistics.

    ``state_i`` = (x, y, θ, ξ); ``command`` = (v, ω, singular, v saturated, ω saturated).
    """
    x, y, theta, xi = state_i
    v, omega, singular, saturated_v, saturated_omega = command
    ex = ref[REF_X] - x
    ey = ref[REF_Y] - y
    e = math.sqrt(ex * ex + ey * ey)
    delta = e - stats[E_MEAN, i]
    mean = stats[E_MEAN, i] + delta / (k + 1.0)
    stats[E_MEAN, i] = mean
    stats[E_M2, i] += delta * (e - mean)
    stats[E_SQ, i] += e * e
    stats[E_MAX, i] = max(stats[E_MAX, i], e)
    stats[E_FINAL, i] = e
    heading = abs(wrap_angle(ref[REF_THETA] - theta))
    stats[H_SUM, i] += heading
    stats[H_SQ, i] += heading * heading
    stats[H_MAX, i] = max(stats[H_MAX, i], heading)
    stats[H_FINAL, i] = heading
    stats[V_PEAK, i] = max(stats[V_PEAK, i], abs(v))
    stats[W_PEAK, i] = max(stats[W_PEAK, i], abs(omega))
    stats[V_SQ, i] += v * v
    stats[W_SQ, i] += omega * omega
    stats[SAT_V, i] += saturated_v
    stats[SAT_W, i] += saturated_omega
    stats[SINGULAR, i] += singular
    stats[FIRST_SINGULAR, i] = min(stats[FIRST_SINGULAR, i], ref[0] if singular > 0.0 else np.inf)


@njit(inline="always", **_OPTIONS)
def record_robot(record, k, i, state_i, command):
    """Store robot i's state and command at output step k in the trajectory record."""
    x, y, theta, xi = state_i
    record[REC_X, k, i] = x
    record[REC_Y, k, i] = y
    record[REC_THETA, k, i] = theta
    record[REC_XI, k, i] = xi
    record[REC_V, k, i] = command[0]
    record[REC_OMEGA, k, i] = command[1]


@njit(inline="always", **_OPTIONS)
def row_values(rows, r):
    """Reference row r as a tuple of scalars (laws index it like an array)."""
    return (rows[r, 0], rows[r, 1], rows[r, 2], rows[r, 3], rows[r, 4], rows[r, 5], rows[r, 6], rows[r, 7],
            rows[r, 8], rows[r, 9])


@njit(inline="always", **_OPTIONS)
def command_at(law, x, y, theta, xi, ref, gains, limits, i):
    """Saturated law output and its flags at one state: (v, ω, ξ̇, singular,
    v saturated, ω saturated, cos θ, sin θ)."""
    sin_t, cos_t = sincos(theta)
    v_raw, omega_raw, xi_dot, singular = law(x, y, theta, cos_t, sin_t, xi, ref, gains, i)
    v = min(max(v_raw, -limits[0, i]), limits[0, i])
    omega = min(max(omega_raw, -limits[1, i]), limits[1, i])
    return (v, omega, xi_dot, singular, 1.0 if v != v_raw else 0.0, 1.0 if omega != omega_raw else 0.0,
            cos_t, sin_t)


@njit(inline="always", **_OPTIONS)
def sample(recording, stats, record, k, i, state_i, command, ref):
    sample_robot(stats, k, i, state_i, command, ref)
    if recording:
        record_robot(record, k, i, state_i, command)


@njit(inline="always", **_OPTIONS)
def held_command(held, i):
    """The held command as sampled: its flags were counted at its control instant."""
    return held[HELD_V, i], held[HELD_OMEGA, i], 0.0, 0.0, 0.0


@njit(inline="always", **_OPTIONS)
def substep(law, recording, sampled_data, at_sample, state, rows, row, h, gains, limits, held, stats, record, k):
    """One RK4 sub-step of every robot; ``at_sample`` adds the statistics at its start.

    The four stages are a constant-trip loop that LLVM unrolls into registers.
    """
    r0, r1, r2 = row_values(rows, row), row_values(rows, row + 1), row_values(rows, row + 2)
    for i in range(state.shape[1]):
        x0, y0, theta0, xi0 = state[0, i], state[1, i], state[2, i], state[3, i]
        x, y, theta, xi = x0, y0, theta0, xi0
        sum_x = sum_y = sum_theta = sum_xi = 0.0
        for stage in range(4):
            ref = r0 if stage == 0 else (r1 if stage < 3 else r2)
            if sampled_data:
                sin_t, cos_t = sincos(theta)
                v, omega, xi_dot = held[HELD_V, i], held[HELD_OMEGA, i], held[HELD_XI_DOT, i]
                command = held_command(held, i)
            else:
                v, omega, xi_dot, singular, sat_v, sat_w, cos_t, sin_t = command_at(
                    law, x, y, theta, xi, ref, gains, limits, i)
                command = (v, omega, singular, sat_v, sat_w)
            if at_sample and stage == 0:
                sample(recording, stats, record, k, i, (x, y, theta, xi), command, ref)
            dx, dy, dtheta = unicycle_rates(v, omega, cos_t, sin_t)
            weight = 1.0 if stage == 0 or stage == 3 else 2.0
            sum_x += weight * dx
            sum_y += weight * dy
            sum_theta += weight * dtheta
            sum_xi += weight * xi_dot
            step = 0.5 * h if stage < 2 else h
            x, y, theta, xi = x0 + step * dx, y0 + step * dy, theta0 + step * dtheta, xi0 + step * xi_dot
        sixth = h / 6.0
        state[0, i] = x0 + sixth * sum_x
        state[1, i] = y0 + sixth * sum_y
        state[2, i] = theta0 + sixth * sum_theta
        state[3, i] = xi0 + sixth * sum_xi


@njit(inline="always", **_OPTIONS)
def sample_all(law, recording, sampled_data, state, ref, gains, limits, held, stats, record, k):
    """Sample every robot at output step k. Under sampled-data control the held command is
    what acts, except at control instants, where the caller refreshed it first."""
    for i in range(state.shape[1]):
        x, y, theta, xi = state[0, i], state[1, i], state[2, i], state[3, i]
        if sampled_data:
            command = held_command(held, i)
        else:
            v, omega, _, singular, sat_v, sat_w, _, _ = command_at(law, x, y, theta, xi, ref, gains, limits, i)
            command = (v, omega, singular, sat_v, sat_w)
        sample(recording, stats, record, k, i, (x, y, theta, xi), command, ref)


@njit(inline="always", **_OPTIONS)
def update_held(law, recording, state, ref, gains, limits, held, stats, record, k):
    """Sampled-data control instant: evaluate the law once, hold its output, sample."""
    for i in range(state.shape[1]):
        x, y, theta, xi = state[0, i], state[1, i], state[2, i], state[3, i]
        v, omega, xi_dot, singular, sat_v, sat_w, _, _ = command_at(law, x, y, theta, xi, ref, gains, limits, i)
        held[HELD_V, i] = v
        held[HELD_OMEGA, i] = omega
        held[HELD_XI_DOT, i] = xi_dot
        sample(recording, stats, record, k, i, (x, y, theta, xi), (v, omega, singular, sat_v, sat_w), ref)


def _stable_identity(law) -> None:
    """Give the law's dispatcher a deterministic pickling identity. numba keys its disk
    cache of a closure on the pickled closure variables, and a dispatcher pickles with a
    random per-process uuid unless one was set: without this every process recompiles."""
    if getattr(law, "_MemoMixin__uuid", None) is None:
        law._set_uuid(f"{law.py_func.__module__}.{law.py_func.__qualname__}")


def make_integrator(law, recording: bool):
    """Compile (once, cached on disk) the functions that simulate robots under ``law``,
    keeping trajectories in ``record`` if ``recording`` (a compile-time choice: the
    conditional stores would get in the way of the loop over robots).

    Returns ``(law_rates, integrate, score)``:

    * ``law_rates(state, rows, gains, limits, rates)``: state rates (4, n) of every robot
      under the continuous-time law at the time of ``rows[0]`` (scipy's right-hand side);
    * ``integrate(...)``: the RK4 time loop (see the module docstring);
    * ``score(states, rows, gains, limits, stats, record)``: statistics of a trajectory
      computed elsewhere (the scipy cross-check), by the same sampling code.

    Only these closures capture ``law``: numba caches closures over module-level
    functions across processes, not closures over other closures.
    """
    _stable_identity(law)

    @njit(**_OPTIONS)
    def integrate(state, gains, limits, rows, row_start, substeps, dt, hold_every, k_start, k_stop, n_steps,
                  stats, record, held):
        sampled_data = hold_every != 0
        for k in range(k_start, k_stop):
            m = substeps[k]
            h = dt / m
            row = row_start[k]
            refresh = sampled_data and k % hold_every == 0
            if refresh:
                update_held(law, recording, state, row_values(rows, row), gains, limits, held, stats, record, k)
            for j in range(m):
                substep(law, recording, sampled_data, j == 0 and not refresh, state, rows, row + 2 * j, h, gains,
                        limits, held, stats, record, k)
        if k_stop == n_steps:
            last = row_values(rows, row_start[n_steps])
            if sampled_data and n_steps % hold_every == 0:
                update_held(law, recording, state, last, gains, limits, held, stats, record, n_steps)
            else:
                sample_all(law, recording, sampled_data, state, last, gains, limits, held, stats, record, n_steps)

    @njit(**_OPTIONS)
    def law_rates(state, rows, gains, limits, rates):
        ref = row_values(rows, 0)
        for i in range(state.shape[1]):
            v, omega, xi_dot, _, _, _, cos_t, sin_t = command_at(
                law, state[0, i], state[1, i], state[2, i], state[3, i], ref, gains, limits, i)
            rates[0, i], rates[1, i], rates[2, i] = unicycle_rates(v, omega, cos_t, sin_t)
            rates[3, i] = xi_dot

    @njit(**_OPTIONS)
    def score(states, rows, gains, limits, stats, record):
        held = np.zeros((3, states.shape[2]))
        for k in range(states.shape[0]):
            sample_all(law, recording, False, states[k], row_values(rows, k), gains, limits, held, stats, record, k)

    return law_rates, integrate, score
