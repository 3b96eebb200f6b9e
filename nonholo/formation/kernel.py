"""Compiled batch RK4 of formations (the core kernel's patterns, ``nonholo.sim.kernel``).

Data layout (structure of arrays; the batch of formations innermost, so the loops over
formations vectorize like the core's loops over robots):

* ``state``    (4, R, B): x, y, θ, ξ of robot r in formation b (ξ: a leader's compensator)
* ``branch``   (R, B): the continuous bearing φ of each l–φ link at the start of the
  current sub-step (spec §2.5: φ is kept on the 2π branch nearest its previous value)
* ``rows``     (rows, 10): the leader reference at every RK4 stage time (core layout;
  posture leaders only read the time column)
* ``targets``  (rows, 4, R): follower targets and their rates at the same times
  (``schedule.TABLE_COLUMNS``)
* ``leader_gains`` (LEADER_GAINS, R, B), ``params`` (3, R, B) = k1, k2, d of followers,
  ``limits`` (2, R, B) = |v| ≤ v_max, |ω| ≤ ω_max
* topology: ``order`` (R,) parents-first, ``kinds`` (R,), ``parents`` (2, R)
* ``record``   (RECORD_FIELDS, N + 1, R, B) on the output grid; ``step_rate`` (N + 1,)
  the fastest rate (|ω|, |ξ̇/ξ|) met during each output step, for sub-step planning.

At every RK4 stage the robots are evaluated parents-first: a follower's law reads its
parents' stage poses and their *computed* (saturated) commands of the same stage (spec
§4). Laws receive scalars and tuples only. The output rates (l̇, φ̇ or l̇1, l̇2) recorded
at each sample come from ``nonholo.models.formation_kinematics``, the model definition
shared with symbolic analysis, evaluated at the applied commands.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from nonholo.formation.geometry import link_geometry
from nonholo.formation.laws import separation_bearing_law, separation_separation_law
from nonholo.models.formation_kinematics import separation_bearing_rates, separation_rate
from nonholo.models.unicycle import unicycle_rates
from nonholo.numerics import sincos, wrap_angle
from nonholo.sim.kernel import row_values, stable_cache_identity
from nonholo.sim.kernel import saturate as saturate_commands

LEADER, SEPARATION_BEARING, SEPARATION_SEPARATION = 0, 1, 2
LEADER_GAINS = 10  # MAX_LAW_FIELDS
(REC_X, REC_Y, REC_THETA, REC_XI, REC_V, REC_OMEGA, REC_OUT1, REC_OUT2, REC_ERR1, REC_ERR2, REC_RATE1, REC_RATE2,
 REC_SIN_GAMMA, REC_SINGULAR, REC_SATURATED) = range(15)
RECORD_FIELDS = 15
(OUT1, OUT2, RATE1, RATE2, SIN_GAMMA, SINGULAR, SATURATED) = range(7)
OUTPUT_FIELDS = 7
_OPTIONS = dict(cache=True, error_model="numpy")


@njit(inline="always", **_OPTIONS)
def leader_gains_of(gains, r, b):
    return (gains[0, r, b], gains[1, r, b], gains[2, r, b], gains[3, r, b], gains[4, r, b], gains[5, r, b],
            gains[6, r, b], gains[7, r, b], gains[8, r, b], gains[9, r, b])


@njit(inline="always", **_OPTIONS)
def saturate(v_raw, omega_raw, v_max, omega_max):
    """Clipped (v, ω) and a flag: 1 if v was clipped, 2 if ω, 3 if both."""
    v, omega, saturated_v, saturated_omega = saturate_commands(v_raw, omega_raw, v_max, omega_max)
    return v, omega, saturated_v + 2.0 * saturated_omega


@njit(inline="always", **_OPTIONS)
def continuous_bearing(raw, previous):
    """φ on the 2π branch nearest ``previous`` (spec §2.5)."""
    return previous + wrap_angle(raw - previous)


@njit(inline="always", **_OPTIONS)
def evaluate_robots(law, stage, branch, ref, targets, target_row, order, kinds, parents, leader_gains, params, limits,
                    sin_floor, xi_speed, command, slope, outputs):
    """Commands, state rates and link outputs of every robot at one stage, parents first.
    Returns the fastest rate met (max |ω|, and |ξ̇/ξ| if ``xi_speed`` = 1, i.e. ξ is a
    dynamic-feedback speed) for sub-step planning."""
    peak = 0.0
    n_batch = stage.shape[2]
    for position in range(order.size):
        r = order[position]
        kind = kinds[r]
        if kind == LEADER:
            for b in range(n_batch):
                x, y, theta, xi = stage[0, r, b], stage[1, r, b], stage[2, r, b], stage[3, r, b]
                sin_t, cos_t = sincos(theta)
                v_raw, omega_raw, xi_dot, singular = law(x, y, theta, cos_t, sin_t, xi, ref,
                                                         leader_gains_of(leader_gains, r, b))
                v, omega, saturated = saturate(v_raw, omega_raw, limits[0, r, b], limits[1, r, b])
                command[0, r, b], command[1, r, b] = v, omega
                slope[0, r, b], slope[1, r, b], slope[2, r, b] = unicycle_rates(v, omega, cos_t, sin_t)
                slope[3, r, b] = xi_dot
                outputs[SINGULAR, r, b], outputs[SATURATED, r, b] = singular, saturated
                outputs[OUT1, r, b] = outputs[OUT2, r, b] = outputs[RATE1, r, b] = outputs[RATE2, r, b] = 0.0
                outputs[SIN_GAMMA, r, b] = 0.0
                peak = max(peak, abs(omega), xi_speed * abs(xi_dot) / max(abs(xi), 1e-300))
        elif kind == SEPARATION_BEARING:
            p = parents[0, r]
            l_d, phi_d = targets[target_row, 0, r], targets[target_row, 1, r]
            l_d_rate, phi_d_rate = targets[target_row, 2, r], targets[target_row, 3, r]
            for b in range(n_batch):
                k1, k2, d = params[0, r, b], params[1, r, b], params[2, r, b]
                theta = stage[2, r, b]
                sin_t, cos_t = sincos(theta)
                v_l, omega_l = command[0, p, b], command[1, p, b]
                separation, raw, cos_phi, sin_phi, cos_g, sin_g = link_geometry(
                    stage[0, p, b], stage[1, p, b], stage[2, p, b], stage[0, r, b], stage[1, r, b], cos_t, sin_t,
                    theta, d)
                bearing = continuous_bearing(raw, branch[r, b])
                v_raw, omega_raw = separation_bearing_law(separation, bearing, cos_phi, sin_phi, cos_g, sin_g, v_l,
                                                          omega_l, l_d, phi_d, l_d_rate, phi_d_rate, k1, k2, d)
                v, omega, saturated = saturate(v_raw, omega_raw, limits[0, r, b], limits[1, r, b])
                command[0, r, b], command[1, r, b] = v, omega
                slope[0, r, b], slope[1, r, b], slope[2, r, b] = unicycle_rates(v, omega, cos_t, sin_t)
                slope[3, r, b] = 0.0
                l_rate, phi_rate, _ = separation_bearing_rates(v, omega, v_l, omega_l, separation, d, cos_phi, sin_phi,
                                                               cos_g, sin_g)
                outputs[OUT1, r, b], outputs[OUT2, r, b] = separation, bearing
                outputs[RATE1, r, b], outputs[RATE2, r, b] = l_rate, phi_rate
                outputs[SIN_GAMMA, r, b], outputs[SINGULAR, r, b], outputs[SATURATED, r, b] = 0.0, 0.0, saturated
                peak = max(peak, abs(omega))
        else:
            p1, p2 = parents[0, r], parents[1, r]
            l1_d, l2_d = targets[target_row, 0, r], targets[target_row, 1, r]
            l1_d_rate, l2_d_rate = targets[target_row, 2, r], targets[target_row, 3, r]
            for b in range(n_batch):
                k1, k2, d = params[0, r, b], params[1, r, b], params[2, r, b]
                x, y, theta = stage[0, r, b], stage[1, r, b], stage[2, r, b]
                sin_t, cos_t = sincos(theta)
                v_1, v_2 = command[0, p1, b], command[0, p2, b]
                l1, _, cos_phi_1, _, cos_g1, sin_g1 = link_geometry(stage[0, p1, b], stage[1, p1, b], stage[2, p1, b],
                                                                   x, y, cos_t, sin_t, theta, d)
                l2, _, cos_phi_2, _, cos_g2, sin_g2 = link_geometry(stage[0, p2, b], stage[1, p2, b], stage[2, p2, b],
                                                                   x, y, cos_t, sin_t, theta, d)
                v_raw, omega_raw, sin_difference, singular = separation_separation_law(
                    l1, l2, cos_phi_1, cos_phi_2, cos_g1, sin_g1, cos_g2, sin_g2, v_1, v_2, l1_d, l2_d, l1_d_rate,
                    l2_d_rate, k1, k2, d, sin_floor)
                v, omega, saturated = saturate(v_raw, omega_raw, limits[0, r, b], limits[1, r, b])
                command[0, r, b], command[1, r, b] = v, omega
                slope[0, r, b], slope[1, r, b], slope[2, r, b] = unicycle_rates(v, omega, cos_t, sin_t)
                slope[3, r, b] = 0.0
                outputs[OUT1, r, b], outputs[OUT2, r, b] = l1, l2
                outputs[RATE1, r, b] = separation_rate(v, omega, v_1, d, cos_phi_1, cos_g1, sin_g1)
                outputs[RATE2, r, b] = separation_rate(v, omega, v_2, d, cos_phi_2, cos_g2, sin_g2)
                outputs[SIN_GAMMA, r, b], outputs[SINGULAR, r, b] = sin_difference, singular
                outputs[SATURATED, r, b] = saturated
                peak = max(peak, abs(omega))
    return peak


@njit(inline="always", **_OPTIONS)
def update_branches(state, branch, kinds, parents, params):
    """Move every l–φ bearing branch to the bearing at the current state."""
    for r in range(kinds.size):
        if kinds[r] != SEPARATION_BEARING:
            continue
        p = parents[0, r]
        for b in range(state.shape[2]):
            theta = state[2, r, b]
            sin_t, cos_t = sincos(theta)
            _, raw, _, _, _, _ = link_geometry(state[0, p, b], state[1, p, b], state[2, p, b], state[0, r, b],
                                              state[1, r, b], cos_t, sin_t, theta, params[2, r, b])
            branch[r, b] = continuous_bearing(raw, branch[r, b])


@njit(inline="always", **_OPTIONS)
def store_sample(record, k, state, command, outputs, targets, target_row, kinds):
    for r in range(state.shape[1]):
        follower = kinds[r] != LEADER
        out1_d, out2_d = targets[target_row, 0, r], targets[target_row, 1, r]
        for b in range(state.shape[2]):
            record[REC_X, k, r, b] = state[0, r, b]
            record[REC_Y, k, r, b] = state[1, r, b]
            record[REC_THETA, k, r, b] = state[2, r, b]
            record[REC_XI, k, r, b] = state[3, r, b]
            record[REC_V, k, r, b] = command[0, r, b]
            record[REC_OMEGA, k, r, b] = command[1, r, b]
            record[REC_OUT1, k, r, b] = outputs[OUT1, r, b]
            record[REC_OUT2, k, r, b] = outputs[OUT2, r, b]
            record[REC_ERR1, k, r, b] = outputs[OUT1, r, b] - out1_d if follower else 0.0
            record[REC_ERR2, k, r, b] = outputs[OUT2, r, b] - out2_d if follower else 0.0
            record[REC_RATE1, k, r, b] = outputs[RATE1, r, b]
            record[REC_RATE2, k, r, b] = outputs[RATE2, r, b]
            record[REC_SIN_GAMMA, k, r, b] = outputs[SIN_GAMMA, r, b]
            record[REC_SINGULAR, k, r, b] = outputs[SINGULAR, r, b]
            record[REC_SATURATED, k, r, b] = outputs[SATURATED, r, b]


@njit(inline="always", **_OPTIONS)
def rk4_substep(law, state, branch, stage, slopes, command, outputs, rows, targets, row, h, order, kinds, parents,
                leader_gains, params, limits, sin_floor, xi_speed):
    """One classical RK4 sub-step of every formation; returns the fastest rate met."""
    peak = 0.0
    n_robots, n_batch = state.shape[1], state.shape[2]
    for s in range(4):
        offset = 0 if s == 0 else (1 if s < 3 else 2)
        weight = 0.0 if s == 0 else (0.5 * h if s < 3 else h)
        for v in range(4):
            for r in range(n_robots):
                for b in range(n_batch):
                    stage[v, r, b] = state[v, r, b] + (weight * slopes[s - 1, v, r, b] if s > 0 else 0.0)
        peak = max(peak, evaluate_robots(law, stage, branch, row_values(rows, row + offset), targets, row + offset,
                                         order, kinds, parents, leader_gains, params, limits, sin_floor, xi_speed, command,
                                         slopes[s], outputs))
    sixth = h / 6.0
    for v in range(4):
        for r in range(n_robots):
            for b in range(n_batch):
                state[v, r, b] += sixth * (slopes[0, v, r, b] + 2.0 * (slopes[1, v, r, b] + slopes[2, v, r, b])
                                           + slopes[3, v, r, b])
    update_branches(state, branch, kinds, parents, params)
    return peak


def make_formation_integrator(law):
    """Compile (once, cached on disk) the formation functions for leaders under ``law``.

    Returns ``(integrate, rates, sample)``:

    * ``integrate(state, branch, rows, targets, row_start, substeps, dt, order, kinds, parents,
      leader_gains, params, limits, sin_floor, xi_speed, record, step_rate, k_start, k_stop, n_steps)``:
      the RK4 time loop, sampling the record at every output time;
    * ``rates(state, branch, rows, targets, order, kinds, parents, leader_gains, params, limits,
      sin_floor, xi_speed, slope)``: state rates at the time of ``rows[0]`` (scipy's right-hand side);
    * ``sample(states, branch, rows, targets, order, kinds, parents, leader_gains, params, limits,
      sin_floor, xi_speed, record)``: the record of a trajectory computed elsewhere (states (N+1, 4, R, B)).

    Only these closures capture ``law`` (numba caches closures over module-level functions).
    """
    stable_cache_identity(law)

    @njit(**_OPTIONS)
    def integrate(state, branch, rows, targets, row_start, substeps, dt, order, kinds, parents, leader_gains, params,
                  limits, sin_floor, xi_speed, record, step_rate, k_start, k_stop, n_steps):
        n_robots, n_batch = state.shape[1], state.shape[2]
        stage = np.empty_like(state)
        slopes = np.zeros((4, 4, n_robots, n_batch))
        command = np.zeros((2, n_robots, n_batch))
        outputs = np.zeros((OUTPUT_FIELDS, n_robots, n_batch))
        for k in range(k_start, k_stop + (1 if k_stop == n_steps else 0)):
            row = row_start[k]
            step_rate[k] = evaluate_robots(law, state, branch, row_values(rows, row), targets, row, order, kinds,
                                           parents, leader_gains, params, limits, sin_floor, xi_speed, command, slopes[0],
                                           outputs)
            store_sample(record, k, state, command, outputs, targets, row, kinds)
            if k == n_steps:
                break
            m = substeps[k]
            for j in range(m):
                step_rate[k] = max(step_rate[k], rk4_substep(
                    law, state, branch, stage, slopes, command, outputs, rows, targets, row + 2 * j, dt / m, order,
                    kinds, parents, leader_gains, params, limits, sin_floor, xi_speed))

    @njit(**_OPTIONS)
    def rates(state, branch, rows, targets, order, kinds, parents, leader_gains, params, limits, sin_floor, xi_speed, slope):
        command = np.zeros((2, state.shape[1], state.shape[2]))
        outputs = np.zeros((OUTPUT_FIELDS, state.shape[1], state.shape[2]))
        evaluate_robots(law, state, branch, row_values(rows, 0), targets, 0, order, kinds, parents, leader_gains,
                        params, limits, sin_floor, xi_speed, command, slope, outputs)

    @njit(**_OPTIONS)
    def sample(states, branch, rows, targets, order, kinds, parents, leader_gains, params, limits, sin_floor, xi_speed,
               record):
        n_robots, n_batch = states.shape[2], states.shape[3]
        command = np.zeros((2, n_robots, n_batch))
        slope = np.zeros((4, n_robots, n_batch))
        outputs = np.zeros((OUTPUT_FIELDS, n_robots, n_batch))
        for k in range(states.shape[0]):
            state = states[k]
            update_branches(state, branch, kinds, parents, params)
            evaluate_robots(law, state, branch, row_values(rows, k), targets, k, order, kinds, parents, leader_gains,
                            params, limits, sin_floor, xi_speed, command, slope, outputs)
            store_sample(record, k, state, command, outputs, targets, k, kinds)

    return integrate, rates, sample
