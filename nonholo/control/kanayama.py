"""Stable tracking on the linearized error model (thesis §4.5, Eq 4.26; spec leader.md
§3.4), after Kanayama, Kimura, Miyazaki & Noguchi (1990):

    v = v_d cos e3 + Kx e1
    ω = ω_d + v_d (Ky e2 + Kθ sin e3),      Kx, Ky, Kθ > 0, v_d > 0

Lyapunov function (e1² + e2²)/2 + (1 − cos e3)/Ky. The lateral loop has natural
frequency v_d √Ky and damping Kθ / (2√Ky). Law signature: see
``nonholo.control.linearization``.
"""
from __future__ import annotations

import math

from numba import njit

from nonholo.control.declare import POSITIVE, Gain, control_law
from nonholo.control.tracking_errors import heading_error_sincos, tracking_errors
from nonholo.references.feedforward import REF_OMEGA, REF_V


@control_law("kanayama", title="Stable tracking (linearized error model)",
             source="thesis §4.5 Eq 4.26; spec §3.4; Kanayama, Kimura, Miyazaki & Noguchi 1990",
             gains={"kx": Gain(10.0, POSITIVE), "ky": Gain(0.0064, POSITIVE), "ktheta": Gain(0.16, POSITIVE)},
             direction=1,   # its Lyapunov function needs v_d > 0 (spec §3.4): backward, it diverges
             stiffness=lambda g, v_d, omega_d: max(g["kx"], v_d * (math.sqrt(g["ky"]) + g["ktheta"])))
@njit(error_model="numpy", fastmath=False)
def kanayama_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    kx, ky, ktheta = gains.kx, gains.ky, gains.ktheta
    v_d, omega_d = ref[REF_V], ref[REF_OMEGA]
    e1, e2, e3 = tracking_errors(x, y, theta, cos_theta, sin_theta, ref)
    sin_e3, cos_e3 = heading_error_sincos(cos_theta, sin_theta, ref)
    return v_d * cos_e3 + kx * e1, omega_d + v_d * (ky * e2 + ktheta * sin_e3), 0.0, 0.0
