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
* ``held``   (6, n): the command held between control instants (sampled-data mode)

``commands`` arrays (6, n) hold v, ω, ξ̇, singular flag, v saturated, ω saturated.

The kernel mutates ``state``, ``stats``, ``record`` and ``held`` and can be resumed
(``k_start``/``k_stop``), so the caller can show progress on long runs. One kernel is
compiled per law (``make_integrator``) and cached on disk by numba.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from nonholo.models.unicycle import unicycle_rates
from nonholo.numerics import sincos, wrap_angle
from nonholo.references.feedforward import REF_THETA, REF_X, REF_Y

(E_MEAN, E_M2, E_SQ, E_MAX, E_FINAL, H_SUM, H_SQ, H_MAX, H_FINAL, V_PEAK, W_PEAK, V_SQ, W_SQ,
 SAT_V, SAT_W, SINGULAR, FIRST_SINGULAR) = range(17)
STAT_COUNT = 17
REC_X, REC_Y, REC_THETA, REC_XI, REC_V, REC_OMEGA = range(6)
CMD_V, CMD_OMEGA, CMD_XI_DOT, CMD_SINGULAR, CMD_SAT_V, CMD_SAT_OMEGA = range(6)


def new_stats(n: int) -> np.ndarray:
    stats = np.zeros((STAT_COUNT, n))
    stats[FIRST_SINGULAR] = np.inf
    return stats


@njit(cache=True, error_model="numpy")
def held_rates(state, command, rates):
    """Unicycle rates under a command held constant (zero-order hold)."""
    for i in range(state.shape[1]):
        sin_t, cos_t = sincos(state[2, i])
        rates[0, i], rates[1, i], rates[2, i] = unicycle_rates(command[CMD_V, i], command[CMD_OMEGA, i], cos_t, sin_t)
        rates[3, i] = command[CMD_XI_DOT, i]


@njit(cache=True, error_model="numpy")
def shifted(out, state, step, rates):
    """out = state + step·rates."""
    for c in range(state.shape[0]):
        for i in range(state.shape[1]):
            out[c, i] = state[c, i] + step * rates[c, i]


@njit(cache=True, error_model="numpy")
def accumulate_rates(total, weight, rates):
    for c in range(total.shape[0]):
        for i in range(total.shape[1]):
            total[c, i] += weight * rates[c, i]


@njit(cache=True, error_model="numpy")
def finish_rk4_step(state, h, total, rates):
    """state += h/6 (k1 + 2k2 + 2k3 + k4), with ``total`` = k1 + 2k2 + 2k3."""
    sixth = h / 6.0
    for c in range(state.shape[0]):
        for i in range(state.shape[1]):
            state[c, i] += sixth * (total[c, i] + rates[c, i])


@njit(cache=True, error_model="numpy")
def accumulate_sample(stats, record, k, state, ref, command):
    """Update the running statistics with the sample at output step k (t_k = ref[0])."""
    count = k + 1.0
    recording = record.shape[1] > 0
    for i in range(state.shape[1]):
        x, y, theta = state[0, i], state[1, i], state[2, i]
        v, omega = command[CMD_V, i], command[CMD_OMEGA, i]
        ex = ref[REF_X] - x
        ey = ref[REF_Y] - y
        e = math.sqrt(ex * ex + ey * ey)
        delta = e - stats[E_MEAN, i]
        stats[E_MEAN, i] += delta / count
        stats[E_M2, i] += delta * (e - stats[E_MEAN, i])
        stats[E_SQ, i] += e * e
        stats[E_MAX, i] = max(stats[E_MAX, i], e)
        stats[E_FINAL, i] = e
        h = abs(wrap_angle(ref[REF_THETA] - theta))
        stats[H_SUM, i] += h
        stats[H_SQ, i] += h * h
        stats[H_MAX, i] = max(stats[H_MAX, i], h)
        stats[H_FINAL, i] = h
        stats[V_PEAK, i] = max(stats[V_PEAK, i], abs(v))
        stats[W_PEAK, i] = max(stats[W_PEAK, i], abs(omega))
        stats[V_SQ, i] += v * v
        stats[W_SQ, i] += omega * omega
        stats[SAT_V, i] += command[CMD_SAT_V, i]
        stats[SAT_W, i] += command[CMD_SAT_OMEGA, i]
        singular = command[CMD_SINGULAR, i]
        stats[SINGULAR, i] += singular
        if singular > 0.0 and stats[FIRST_SINGULAR, i] == np.inf:
            stats[FIRST_SINGULAR, i] = ref[0]
        if recording:
            record[REC_X, k, i] = x
            record[REC_Y, k, i] = y
            record[REC_THETA, k, i] = theta
            record[REC_XI, k, i] = state[3, i]
            record[REC_V, k, i] = v
            record[REC_OMEGA, k, i] = omega


def make_integrator(law):
    """Compile (once, cached on disk) the functions that simulate robots under ``law``.

    Returns ``(law_rates, integrate, score)``:

    * ``law_rates(state, ref, gains, limits, command, rates)``: commands and state rates
      of every robot at one instant (continuous-time law, with saturation);
    * ``integrate(...)``: the RK4 time loop (see the module docstring);
    * ``score(states, rows, gains, limits, stats, record)``: statistics of a trajectory
      computed elsewhere (for the scipy cross-check), with the same sampling code.
    """

    @njit(cache=True, error_model="numpy")
    def law_rates(state, ref, gains, limits, command, rates):
        for i in range(state.shape[1]):
            x, y, theta, xi = state[0, i], state[1, i], state[2, i], state[3, i]
            sin_t, cos_t = sincos(theta)
            v_raw, omega_raw, xi_dot, singular = law(x, y, theta, cos_t, sin_t, xi, ref, gains, i)
            v = min(max(v_raw, -limits[0, i]), limits[0, i])
            omega = min(max(omega_raw, -limits[1, i]), limits[1, i])
            command[CMD_V, i] = v
            command[CMD_OMEGA, i] = omega
            command[CMD_XI_DOT, i] = xi_dot
            command[CMD_SINGULAR, i] = singular
            command[CMD_SAT_V, i] = 1.0 if v != v_raw else 0.0
            command[CMD_SAT_OMEGA, i] = 1.0 if omega != omega_raw else 0.0
            rates[0, i], rates[1, i], rates[2, i] = unicycle_rates(v, omega, cos_t, sin_t)
            rates[3, i] = xi_dot

    @njit(cache=True, error_model="numpy")
    def stage_rates(state, ref, gains, limits, hold_every, k, first_stage, command, held, rates):
        """Rates at one RK stage; returns the command in force (for sampling)."""
        if hold_every == 0:
            law_rates(state, ref, gains, limits, command, rates)
            return command
        if first_stage and k % hold_every == 0:
            law_rates(state, ref, gains, limits, held, rates)
        else:
            held_rates(state, held, rates)
        return held

    @njit(cache=True, error_model="numpy")
    def integrate(state, gains, limits, rows, row_start, substeps, dt, hold_every, k_start, k_stop, n_steps,
                  stats, record, held):
        n = state.shape[1]
        command = np.zeros((6, n))
        rates = np.empty((4, n))
        total = np.empty((4, n))
        trial = np.empty((4, n))
        for k in range(k_start, k_stop):
            m = substeps[k]
            h = dt / m
            row = row_start[k]
            for j in range(m):
                in_force = stage_rates(state, rows[row], gains, limits, hold_every, k, j == 0, command, held, rates)
                if j == 0:
                    accumulate_sample(stats, record, k, state, rows[row], in_force)
                total[:, :] = rates
                shifted(trial, state, 0.5 * h, rates)
                stage_rates(trial, rows[row + 1], gains, limits, hold_every, k, False, command, held, rates)
                accumulate_rates(total, 2.0, rates)
                shifted(trial, state, 0.5 * h, rates)
                stage_rates(trial, rows[row + 1], gains, limits, hold_every, k, False, command, held, rates)
                accumulate_rates(total, 2.0, rates)
                shifted(trial, state, h, rates)
                stage_rates(trial, rows[row + 2], gains, limits, hold_every, k, False, command, held, rates)
                finish_rk4_step(state, h, total, rates)
                row += 2
        if k_stop == n_steps:
            last = rows[row_start[n_steps]]
            in_force = stage_rates(state, last, gains, limits, hold_every, n_steps, True, command, held, rates)
            accumulate_sample(stats, record, n_steps, state, last, in_force)

    @njit(cache=True, error_model="numpy")
    def score(states, rows, gains, limits, stats, record):
        n = states.shape[2]
        command = np.zeros((6, n))
        rates = np.empty((4, n))
        for k in range(states.shape[0]):
            law_rates(states[k], rows[k], gains, limits, command, rates)
            accumulate_sample(stats, record, k, states[k], rows[k], command)

    return law_rates, integrate, score
