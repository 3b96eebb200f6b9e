"""Feedback linearization of the unicycle.

* Static input–output linearization of an offset point (thesis §4.8, Eq 4.34–4.38,
  errata 12–13; spec leader.md §3.5): output B = (x + d cos θ, y + d sin θ), d ≠ 0,

      v = cos θ r1 + sin θ r2,   ω = (−sin θ r1 + cos θ r2) / d,
      r_i = ż_d,i + k_i (z_d,i − z_i),

  with B's reference built from the centre reference: z_d = p_d + d (cos θ_d, sin θ_d),
  ż_d = ṗ_d + d ω_d (−sin θ_d, cos θ_d). Closed loop ż = r; θ is internal dynamics.

* Full-state linearization by dynamic feedback (thesis §4.9, Eq 4.39–4.50, errata
  14–16; spec §3.6), after Oriolo, De Luca & Vendittelli (2002): compensator ξ = v,

      ξ̇ = r1 cos θ + r2 sin θ,   v = ξ,   ω = (r2 cos θ − r1 sin θ) / ξ,
      r1 = ẍ_d + kp1 (x_d − x) + kd1 (ẋ_d − ξ cos θ),
      r2 = ÿ_d + kp2 (y_d − y) + kd2 (ẏ_d − ξ sin θ),

  so that e = p_d − p obeys ë_i + kd_i ė_i + kp_i e_i = 0 while ξ ≠ 0.

  **Singularity guard** (documented behaviour): where |ξ| < ξ_min (gain ``xi_min``,
  default 1e-3 m/s) ω is computed with ξ replaced by ξ_min·sign(ξ) (+ξ_min at ξ = 0):
  a large but finite turn rate instead of a division by zero. Every sample at which the
  guard acts is counted as a singularity event and reported in the results.

Law signature: see ``nonholo.control.linearization``.
"""
from __future__ import annotations

import math

from numba import njit

from nonholo.control.declare import NONZERO, POSITIVE, Gain, control_law
from nonholo.numerics import sincos
from nonholo.references.feedforward import (REF_DDX, REF_DDY, REF_DX, REF_DY, REF_OMEGA, REF_THETA, REF_X,
                                            REF_Y)


@control_law("offset-point", title="Static input-output linearization of an offset point",
             source="thesis §4.8 Eq 4.34-4.38; spec §3.5; De Luca, Oriolo & Vendittelli 2001",
             gains={"d": Gain(0.5, NONZERO), "k1": Gain(1.0, POSITIVE), "k2": Gain(1.0, POSITIVE)},
             # θ is internal dynamics, ė3 ≈ −(v_d/d) sin e3: stable only with the tracked point
             # leading, d > 0 forward and d < 0 backward (else the robot turns around)
             direction=lambda g: 1 if g["d"] > 0 else -1,
             stiffness=lambda g, v_d, omega_d: max(g["k1"], g["k2"], (v_d + abs(g["d"]) * omega_d) / abs(g["d"])))
@njit(error_model="numpy", fastmath=False)
def offset_point_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    d, k1, k2 = gains.d, gains.k1, gains.k2
    sin_d, cos_d = sincos(ref[REF_THETA])
    turn = d * ref[REF_OMEGA]
    r1 = ref[REF_DX] - turn * sin_d + k1 * (ref[REF_X] + d * cos_d - (x + d * cos_theta))
    r2 = ref[REF_DY] + turn * cos_d + k2 * (ref[REF_Y] + d * sin_d - (y + d * sin_theta))
    return cos_theta * r1 + sin_theta * r2, (cos_theta * r2 - sin_theta * r1) / d, 0.0, 0.0


@control_law("dynamic-feedback", title="Full-state linearization by dynamic feedback",
             source="thesis §4.9 Eq 4.39-4.50; spec §3.6; Oriolo, De Luca & Vendittelli 2002",
             gains={"kp1": Gain(1.0, POSITIVE), "kp2": Gain(1.0, POSITIVE), "kd1": Gain(0.7, POSITIVE),
                    "kd2": Gain(0.7, POSITIVE), "xi_min": Gain(1e-3, POSITIVE)},
             aliases={"kp": ("kp1", "kp2"), "kd": ("kd1", "kd2")},
             state="xi", initial="reference-speed", needs_moving_reference=False,
             stiffness=lambda g, v_d, omega_d: max(g["kd1"], g["kd2"], math.sqrt(max(g["kp1"], g["kp2"]))))
@njit(error_model="numpy", fastmath=False)
def dynamic_feedback_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    kp1, kp2, kd1, kd2, xi_min = gains.kp1, gains.kp2, gains.kd1, gains.kd2, gains.xi_min
    r1 = ref[REF_DDX] + kp1 * (ref[REF_X] - x) + kd1 * (ref[REF_DX] - xi * cos_theta)
    r2 = ref[REF_DDY] + kp2 * (ref[REF_Y] - y) + kd2 * (ref[REF_DY] - xi * sin_theta)
    singular = abs(xi) < xi_min
    guarded = xi if not singular else (xi_min if xi >= 0.0 else -xi_min)
    omega = (r2 * cos_theta - r1 * sin_theta) / guarded
    return xi, omega, r1 * cos_theta + r2 * sin_theta, 1.0 if singular else 0.0
