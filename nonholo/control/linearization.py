"""Approximate linearization (thesis §4.3, Eq 4.16–4.23; spec leader.md §3.1) and the
nonlinear Samson-type design (thesis §4.6, Eq 4.27–4.31; spec §3.2), after
De Luca, Oriolo & Vendittelli (2001). Both share the gain schedule

    a = sqrt(ω_d² + b v_d²),   k1 = k3 = 2ζa,   k2 = b|v_d|,

which places the frozen-time poles of the linearized error dynamics at −2ζa and
−ζa ± a·sqrt(ζ² − 1).

Every law in this package has the signature
``law(x, y, θ, cos θ, sin θ, ξ, ref, gains) -> (v, ω, ξ̇, singular)`` for one robot:
``ref`` the reference row (a tuple indexed by ``references.feedforward.REF_COLUMNS``),
``gains`` its gain tuple (a namedtuple read by name, ``gains.zeta``; see
``nonholo.control.declare``), ``ξ`` the dynamic
compensator state (unused by static laws, which return ξ̇ = 0) and ``singular`` 1.0
where a singularity guard acted. Arguments are scalars and tuples only, so the
simulator's loop over robots stays free of reference counting and vectorizes.
"""
from __future__ import annotations

import math

from numba import njit

from nonholo.control.declare import POSITIVE, UNIT_INTERVAL, Gain, control_law
from nonholo.control.tracking_errors import heading_error_sincos, tracking_errors
from nonholo.numerics import sinc_of
from nonholo.references.feedforward import REF_OMEGA, REF_V


GAINS = {"zeta": Gain(0.5, UNIT_INTERVAL), "b": Gain(2.0, POSITIVE)}


def scheduled_rate(g, v_d, omega_d):
    """Stiffness: the fastest frozen-time pole, 2ζa + b v_d."""
    return 2 * g["zeta"] * math.sqrt(omega_d**2 + g["b"] * v_d**2) + g["b"] * v_d


@njit(inline="always", error_model="numpy")
def _scheduled_gain(zeta, b, v_d, omega_d):
    """k1 = k3 = 2ζ·sqrt(ω_d² + b v_d²) (spec §3.1, erratum 7)."""
    return 2.0 * zeta * math.sqrt(omega_d * omega_d + b * v_d * v_d)


@control_law("approximate-linearization", title="Approximate linearization",
             source="thesis §4.3 Eq 4.16-4.23; spec §3.1; De Luca, Oriolo & Vendittelli 2001",
             gains=GAINS, stiffness=scheduled_rate)
@njit(error_model="numpy", fastmath=False)
def approximate_linearization_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    """v = v_d cos e3 + k1 e1,  ω = ω_d + b v_d e2 + k3 e3  (k2 sign(v_d) = b v_d)."""
    zeta, b = gains.zeta, gains.b
    v_d, omega_d = ref[REF_V], ref[REF_OMEGA]
    e1, e2, e3 = tracking_errors(x, y, theta, cos_theta, sin_theta, ref)
    k = _scheduled_gain(zeta, b, v_d, omega_d)
    _, cos_e3 = heading_error_sincos(cos_theta, sin_theta, ref)
    return v_d * cos_e3 + k * e1, omega_d + b * v_d * e2 + k * e3, 0.0, 0.0


@control_law("nonlinear", title="Nonlinear (Samson-type) design",
             source="thesis §4.6 Eq 4.27-4.31; spec §3.2; Samson & Ait-Abderrahim 1991",
             gains=GAINS, stiffness=scheduled_rate)
@njit(error_model="numpy", fastmath=False)
def nonlinear_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    """v = v_d cos e3 + k1 e1,  ω = ω_d + k4 v_d (sin e3 / e3) e2 + k3 e3,  k4 = b.

    Lyapunov V = (k4/2)(e1² + e2²) + e3²/2, V̇ = −k1 k4 e1² − k3 e3² (erratum 10).
    """
    zeta, b = gains.zeta, gains.b
    v_d, omega_d = ref[REF_V], ref[REF_OMEGA]
    e1, e2, e3 = tracking_errors(x, y, theta, cos_theta, sin_theta, ref)
    k = _scheduled_gain(zeta, b, v_d, omega_d)
    sin_e3, cos_e3 = heading_error_sincos(cos_theta, sin_theta, ref)
    return v_d * cos_e3 + k * e1, omega_d + b * v_d * sinc_of(e3, sin_e3) * e2 + k * e3, 0.0, 0.0
