"""Cascaded design (thesis §4.4, Eq 4.24–4.25; spec leader.md §3.3), after Panteley,
Lefeber, Loría & Nijmeijer (1998):

    v = v_d + c2 e1 − c3 ω_d e2,          c2 > 0, c3 > −1
    ω = ω_d + c1 e3        (Eq 4.24, variant "linear")
    ω = ω_d + c1 sin e3    (Eq 4.25, variant "sine"),      c1 > 0

The heading loop is decoupled; the cross-track error is removed only through ω_d
(slow pole ≈ −(1 + c3) ω_d² / c2), so a straight line keeps a lateral offset.
Law signature: see ``nonholo.control.linearization``.
"""
from __future__ import annotations

from numba import njit

from nonholo.control.declare import ABOVE_MINUS_ONE, POSITIVE, Gain, control_law
from nonholo.control.tracking_errors import heading_error_sincos, tracking_errors
from nonholo.references.feedforward import REF_OMEGA, REF_V


@njit(inline="always", error_model="numpy")
def _driving_speed(c2, c3, e1, e2, v_d, omega_d):
    return v_d + c2 * e1 - c3 * omega_d * e2


@control_law("cascaded", title="Cascaded design", variant="linear",
             source="thesis §4.4 Eq 4.24-4.25; spec §3.3; Panteley, Lefeber, Loria & Nijmeijer 1998",
             gains={"c1": Gain(216.9, POSITIVE), "c2": Gain(1.355, POSITIVE), "c3": Gain(-0.414, ABOVE_MINUS_ONE)},
             stiffness=lambda g, v_d, omega_d: max(g["c1"], g["c2"], abs(g["c3"]) * omega_d))
@njit(error_model="numpy", fastmath=False)
def cascaded_linear_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    c1, c2, c3 = gains.c1, gains.c2, gains.c3
    v_d, omega_d = ref[REF_V], ref[REF_OMEGA]
    e1, e2, e3 = tracking_errors(x, y, theta, cos_theta, sin_theta, ref)
    return _driving_speed(c2, c3, e1, e2, v_d, omega_d), omega_d + c1 * e3, 0.0, 0.0


@control_law.variant("cascaded", "sine")
@njit(error_model="numpy", fastmath=False)
def cascaded_sine_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    c1, c2, c3 = gains.c1, gains.c2, gains.c3
    v_d, omega_d = ref[REF_V], ref[REF_OMEGA]
    e1, e2, e3 = tracking_errors(x, y, theta, cos_theta, sin_theta, ref)
    sin_e3, _ = heading_error_sincos(cos_theta, sin_theta, ref)
    return _driving_speed(c2, c3, e1, e2, v_d, omega_d), omega_d + c1 * sin_e3, 0.0, 0.0
