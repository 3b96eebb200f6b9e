"""Follower control laws (spec follower-posture.md §2.2 and §3.2; thesis Eq 4.56–4.62
with errata 14–19).

Both laws invert the decoupling matrix G of the follower kinematics
``nonholo.models.formation_kinematics`` (ż = G u_f + F u_l) so that the outputs obey the
linear target dynamics ż = ż_d + K (z_d − z), K = diag(k1, k2), exactly while the law is
nonsingular. The leaders' *actual* inputs (v_l, ω_l) enter as known drift.

Separation–bearing (l–φ), G⁻¹ form (no singularity at cos γ = 0, erratum 15):

    w1 = k1 (l_d − l) + l̇_d + v_l cos φ
    w2 = k2 (φ_d − φ) + φ̇_d − v_l sin φ / l + ω_l
    v_f = w1 cos γ − l w2 sin γ,    ω_f = (w1 sin γ + l w2 cos γ) / d

Separation–separation (l–l), symmetric form (errata 17–19); singular only where
sin(γ1 − γ2) = 0:

    w_i = k_i (l_i,d − l_i) + l̇_i,d + v_i cos φ_i
    v_f = (w1 sin γ2 − w2 sin γ1) / sin(γ2 − γ1),   ω_f = (w1 cos γ2 − w2 cos γ1) / (d sin(γ1 − γ2))

Arguments are scalars only, so the kernel's loop over formations stays vectorizable.
"""
from __future__ import annotations

from numba import njit


@njit(error_model="numpy", fastmath=False)
def separation_bearing_law(separation, bearing, cos_phi, sin_phi, cos_gamma, sin_gamma, v_leader, omega_leader,
                           separation_d, bearing_d, separation_d_rate, bearing_d_rate, k1, k2, d):
    """(v_f, ω_f) of the l–φ follower (spec §2.2)."""
    w1 = k1 * (separation_d - separation) + separation_d_rate + v_leader * cos_phi
    w2 = k2 * (bearing_d - bearing) + bearing_d_rate - v_leader * sin_phi / separation + omega_leader
    return w1 * cos_gamma - separation * w2 * sin_gamma, (w1 * sin_gamma + separation * w2 * cos_gamma) / d


@njit(error_model="numpy", fastmath=False)
def separation_separation_law(separation_1, separation_2, cos_phi_1, cos_phi_2, cos_gamma_1, sin_gamma_1,
                              cos_gamma_2, sin_gamma_2, v_leader_1, v_leader_2, separation_1_d, separation_2_d,
                              separation_1_d_rate, separation_2_d_rate, k1, k2, d, sin_floor):
    """(v_f, ω_f, sin(γ1 − γ2), singular) of the l–l follower (spec §3.2).

    Where |sin(γ1 − γ2)| < ``sin_floor`` the division uses ±sin_floor instead (a large but
    finite command) and ``singular`` is 1.
    """
    w1 = k1 * (separation_1_d - separation_1) + separation_1_d_rate + v_leader_1 * cos_phi_1
    w2 = k2 * (separation_2_d - separation_2) + separation_2_d_rate + v_leader_2 * cos_phi_2
    sin_difference = sin_gamma_1 * cos_gamma_2 - cos_gamma_1 * sin_gamma_2   # sin(γ1 − γ2)
    singular = abs(sin_difference) < sin_floor
    guarded = sin_difference if not singular else (sin_floor if sin_difference >= 0.0 else -sin_floor)
    v_f = (w2 * sin_gamma_1 - w1 * sin_gamma_2) / guarded
    omega_f = (w1 * cos_gamma_2 - w2 * cos_gamma_1) / (d * guarded)
    return v_f, omega_f, sin_difference, 1.0 if singular else 0.0
