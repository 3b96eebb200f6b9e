"""Compiled batch integration: fixed-step RK4 of the unicycle under a tracking law.

Data layout (structure of arrays, robots innermost so that loops vectorize):

* ``state``  (4, n): x, y, θ, ξ (ξ = dynamic compensator; constant for static laws)
* ``gains``  (MAX_GAINS, n): the law's gain vector per robot (unused rows zero)
* ``limits`` (2, n): |v| ≤ v_max, |ω| ≤ ω_max (inf = no limit)
* ``rows``   (r, 10): the reference evaluated at every stage time (``REF_COLUMNS``);
  output step k with m_k sub-steps owns rows ``row_start[k] … row_start[k] + 2 m_k``
  (times t_k + j h/2, h = dt/m_k), the last one shared with step k + 1
* ``stats``  (STAT_COUNT, n): running statistics sampled at t_k = k·dt (Welford mean)
* ``record`` (6, N + 1, n) or (6, 0, n): x, y, θ, ξ, v, ω on the output grid
* ``held``   (6, n): v, ω, ξ̇ and their flags held between control instants

Each RK4 sub-step is one loop over robots that keeps the four stages in registers, so
memory is touched once per robot and step. Inside the loops over robots only inline
functions of scalars and tuples are called: an inlined function that receives an array
reference-counts it on every iteration, which costs atomics and stops vectorization. The
statistics are sampled by a loop of their own at each output time. The kernel
mutates ``state``, ``stats``, ``record`` and ``held`` and can be resumed
(``k_start``/``k_stop``), so callers can show progress. One kernel is compiled per law
(``make_integrator``) and cached on disk by numba.
"""
from __future__ import annotations

import math
from functools import cache

import llvmlite.binding
import numpy as np
from numba import njit
from numba.core.dispatcher import Dispatcher

from nonholo.models.unicycle import unicycle_rates
from nonholo.numerics import sincos, wrap_angle
from nonholo.references.feedforward import REF_THETA, REF_X, REF_Y

# The robot loops read and write many rows of distinct arrays, which LLVM cannot prove
# disjoint; past its default of 8 run-time overlap checks it refuses to vectorize
# ("too many memory checks needed"). These limits only allow more such checks (a few
# comparisons per loop, not per robot); the options are process-wide.
llvmlite.binding.set_option("nonholo", "-runtime-memory-check-threshold=256")
llvmlite.binding.set_option("nonholo", "-vectorize-memory-check-threshold=1024")

(E_MEAN, E_M2, E_SQ, E_MAX, E_FINAL, H_SUM, H_SQ, H_MAX, H_FINAL, V_PEAK, W_PEAK, V_SQ, W_SQ,
 SAT_V, SAT_W, SINGULAR, FIRST_SINGULAR) = range(17)
STAT_COUNT = 17
REC_X, REC_Y, REC_THETA, REC_XI, REC_V, REC_OMEGA = range(6)
HELD_V, HELD_OMEGA, HELD_XI_DOT, HELD_SINGULAR, HELD_SAT_V, HELD_SAT_OMEGA = range(6)
MAX_GAINS = 10  # MAX_LAW_FIELDS

# "contract" lets LLVM fuse a*b + c into one FMA instruction (deterministic, and more
# accurate); no other fast-math relaxations, so NaN/inf semantics and ordering stay IEEE.
_OPTIONS = dict(cache=True, error_model="numpy", fastmath={"contract"})


def new_stats(n: int) -> np.ndarray:
    stats = np.zeros((STAT_COUNT, n))
    stats[FIRST_SINGULAR] = np.inf
    return stats


@njit(inline="always", **_OPTIONS)
def gains_of(gains, i):
    return (gains[0, i], gains[1, i], gains[2, i], gains[3, i], gains[4, i], gains[5, i], gains[6, i], gains[7, i],
            gains[8, i], gains[9, i])


@cache
def packed_law(law, gain_tuple):
    """``law`` taking its gains as MAX_GAINS plain slots (the rows of the gain array):
    the first fields of its namedtuple ``gain_tuple``, the rest unused."""
    n = len(gain_tuple._fields)

    @njit(inline="always", error_model="numpy")
    def packed(x, y, theta, cos_theta, sin_theta, xi, ref, slots):
        return law(x, y, theta, cos_theta, sin_theta, xi, ref, gain_tuple(*slots[:n]))

    function = law.py_func
    packed._set_uuid(f"{function.__module__}.{function.__qualname__}.packed")
    return packed


@njit(inline="always", **_OPTIONS)
def row_values(rows, r):
    """Reference row r as a tuple of scalars (laws index it like an array)."""
    return (rows[r, 0], rows[r, 1], rows[r, 2], rows[r, 3], rows[r, 4], rows[r, 5], rows[r, 6], rows[r, 7],
            rows[r, 8], rows[r, 9])


@njit(inline="always", **_OPTIONS)
def saturate(v_raw, omega_raw, v_max, omega_max):
    """Actuator limits: clipped (v, ω) and 1.0 flags where each limit acted. abs(nan) >
    limit is False: a non-finite command is not "saturation" (the simulator reports
    divergence separately)."""
    v = min(max(v_raw, -v_max), v_max)
    omega = min(max(omega_raw, -omega_max), omega_max)
    return v, omega, 1.0 if abs(v_raw) > v_max else 0.0, 1.0 if abs(omega_raw) > omega_max else 0.0


@njit(inline="always", **_OPTIONS)
def command_at(law, x, y, theta, xi, ref, gains_i, v_max, omega_max):
    """Saturated law output and its flags at one state: (v, ω, ξ̇, singular,
    v saturated, ω saturated, cos θ, sin θ)."""
    sin_t, cos_t = sincos(theta)
    v_raw, omega_raw, xi_dot, singular = law(x, y, theta, cos_t, sin_t, xi, ref, gains_i)
    v, omega, saturated_v, saturated_omega = saturate(v_raw, omega_raw, v_max, omega_max)
    return v, omega, xi_dot, singular, saturated_v, saturated_omega, cos_t, sin_t


@njit(inline="always", **_OPTIONS)
def refresh_held(law, state, ref, gains, limits, held):
    """Sampled-data control instant: evaluate the law once and hold its output."""
    for i in range(state.shape[1]):
        v, omega, xi_dot, singular, sat_v, sat_w, _, _ = command_at(
            law, state[0, i], state[1, i], state[2, i], state[3, i], ref, gains_of(gains, i), limits[0, i],
            limits[1, i])
        held[HELD_V, i] = v
        held[HELD_OMEGA, i] = omega
        held[HELD_XI_DOT, i] = xi_dot
        held[HELD_SINGULAR, i] = singular
        held[HELD_SAT_V, i] = sat_v
        held[HELD_SAT_OMEGA, i] = sat_w


@njit(inline="always", **_OPTIONS)
def sample_step(law, recording, sampled_data, state, ref, gains, limits, held, stats, record, k):
    """Add every robot's sample at output step k (time ref[0]) to its statistics: the
    position-error norm (Welford mean), heading error, commands in force and events."""
    for i in range(state.shape[1]):
        x, y, theta, xi = state[0, i], state[1, i], state[2, i], state[3, i]
        if sampled_data:
            v, omega = held[HELD_V, i], held[HELD_OMEGA, i]
            singular, sat_v, sat_w = held[HELD_SINGULAR, i], held[HELD_SAT_V, i], held[HELD_SAT_OMEGA, i]
        else:
            v, omega, _, singular, sat_v, sat_w, _, _ = command_at(
                law, x, y, theta, xi, ref, gains_of(gains, i), limits[0, i], limits[1, i])
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
        stats[SAT_V, i] += sat_v
        stats[SAT_W, i] += sat_w
        stats[SINGULAR, i] += singular
        stats[FIRST_SINGULAR, i] = min(stats[FIRST_SINGULAR, i], ref[0] if singular > 0.0 else np.inf)
        if recording:
            record[REC_X, k, i] = x
            record[REC_Y, k, i] = y
            record[REC_THETA, k, i] = theta
            record[REC_XI, k, i] = xi
            record[REC_V, k, i] = v
            record[REC_OMEGA, k, i] = omega


@njit(inline="always", **_OPTIONS)
def stage_rates(law, sampled_data, x, y, theta, xi, ref, gains_i, v_max, omega_max, held_command):
    """(ẋ, ẏ, θ̇, ξ̇) at one RK4 stage: the law's command, or the held one."""
    if sampled_data:
        sin_t, cos_t = sincos(theta)
        v, omega, xi_dot = held_command
    else:
        v, omega, xi_dot, _, _, _, cos_t, sin_t = command_at(law, x, y, theta, xi, ref, gains_i, v_max, omega_max)
    dx, dy, dtheta = unicycle_rates(v, omega, cos_t, sin_t)
    return dx, dy, dtheta, xi_dot


@njit(inline="always", **_OPTIONS)
def substep(law, sampled_data, state, rows, row, h, gains, limits, held):
    """One classical RK4 sub-step of every robot, the four stages in registers."""
    r0, r1, r2 = row_values(rows, row), row_values(rows, row + 1), row_values(rows, row + 2)
    half = 0.5 * h
    for i in range(state.shape[1]):
        x, y, theta, xi = state[0, i], state[1, i], state[2, i], state[3, i]
        gains_i, v_max, omega_max = gains_of(gains, i), limits[0, i], limits[1, i]
        held_command = (held[HELD_V, i], held[HELD_OMEGA, i], held[HELD_XI_DOT, i])
        a1, b1, c1, d1 = stage_rates(law, sampled_data, x, y, theta, xi, r0, gains_i, v_max, omega_max, held_command)
        a2, b2, c2, d2 = stage_rates(law, sampled_data, x + half * a1, y + half * b1, theta + half * c1,
                                     xi + half * d1, r1, gains_i, v_max, omega_max, held_command)
        a3, b3, c3, d3 = stage_rates(law, sampled_data, x + half * a2, y + half * b2, theta + half * c2,
                                     xi + half * d2, r1, gains_i, v_max, omega_max, held_command)
        a4, b4, c4, d4 = stage_rates(law, sampled_data, x + h * a3, y + h * b3, theta + h * c3, xi + h * d3, r2,
                                     gains_i, v_max, omega_max, held_command)
        sixth = h / 6.0
        state[0, i] = x + sixth * (a1 + 2.0 * (a2 + a3) + a4)
        state[1, i] = y + sixth * (b1 + 2.0 * (b2 + b3) + b4)
        state[2, i] = theta + sixth * (c1 + 2.0 * (c2 + c3) + c4)
        state[3, i] = xi + sixth * (d1 + 2.0 * (d2 + d3) + d4)


def stable_cache_identity(dispatcher, _seen=None) -> None:
    """Give ``dispatcher`` and every compiled function its code calls (recursively) a
    deterministic pickling identity.

    numba keys its disk cache of a closure on the pickled closure variables; a law pickles
    *with the functions it calls*, each with a random per-process uuid unless one was set.
    Without this every process would recompile every kernel.
    """
    seen = set() if _seen is None else _seen
    if id(dispatcher) in seen:
        return
    seen.add(id(dispatcher))
    function = dispatcher.py_func
    if getattr(dispatcher, "_MemoMixin__uuid", None) is None:
        dispatcher._set_uuid(f"{function.__module__}.{function.__qualname__}")
    called = [function.__globals__.get(name) for name in function.__code__.co_names]
    called += [cell.cell_contents for cell in function.__closure__ or ()]
    for value in called:
        if isinstance(value, Dispatcher):
            stable_cache_identity(value, seen)


def make_integrator(law, recording: bool):
    """Compile (once, cached on disk) the functions that simulate robots under ``law``,
    keeping trajectories in ``record`` if ``recording`` (a compile-time choice, so that
    the statistics-only variant has no conditional stores).

    Returns ``(law_rates, integrate, score)``:

    * ``law_rates(state, rows, gains, limits, rates)``: state rates (4, n) of every robot
      under the continuous-time law at the time of ``rows[0]`` (scipy's right-hand side);
    * ``integrate(...)``: the RK4 time loop (see the module docstring);
    * ``score(states, rows, gains, limits, stats, record)``: statistics of a trajectory
      computed elsewhere (the scipy cross-check), by the same sampling code.

    Only these closures capture ``law``: numba caches closures over module-level
    functions across processes, not closures over other closures.
    """
    stable_cache_identity(law)

    @njit(**_OPTIONS)
    def integrate(state, gains, limits, rows, row_start, substeps, dt, hold_every, k_start, k_stop, n_steps,
                  stats, record, held):
        sampled_data = hold_every != 0
        for k in range(k_start, k_stop + (1 if k_stop == n_steps else 0)):
            row = row_start[k]
            if sampled_data and k % hold_every == 0:
                refresh_held(law, state, row_values(rows, row), gains, limits, held)
            sample_step(law, recording, sampled_data, state, row_values(rows, row), gains, limits, held, stats,
                        record, k)
            if k == n_steps:
                break
            m = substeps[k]
            for j in range(m):
                substep(law, sampled_data, state, rows, row + 2 * j, dt / m, gains, limits, held)

    @njit(**_OPTIONS)
    def law_rates(state, rows, gains, limits, rates):
        ref = row_values(rows, 0)
        for i in range(state.shape[1]):
            v, omega, xi_dot, _, _, _, cos_t, sin_t = command_at(
                law, state[0, i], state[1, i], state[2, i], state[3, i], ref, gains_of(gains, i), limits[0, i],
                limits[1, i])
            rates[0, i], rates[1, i], rates[2, i] = unicycle_rates(v, omega, cos_t, sin_t)
            rates[3, i] = xi_dot

    @njit(**_OPTIONS)
    def score(states, rows, gains, limits, stats, record):
        held = np.zeros((6, states.shape[2]))
        for k in range(states.shape[0]):
            sample_step(law, recording, False, states[k], row_values(rows, k), gains, limits, held, stats, record, k)

    return law_rates, integrate, score
