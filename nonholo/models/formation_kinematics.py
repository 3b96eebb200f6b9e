"""Follower kinematics of the l–φ and l–l formations (spec follower-posture.md §2.1, §3.1).

Geometry (spec §1): the separation l is measured from the leader's axle midpoint to the
follower's castor point, a distance d ahead of the follower's axle; the bearing φ is the
direction of that vector in the leader's body frame; γ = θ_leader + φ − θ_follower.

    l̇ = v_f cos γ + d ω_f sin γ − v_l cos φ                       (l–φ and each l of l–l)
    φ̇ = (v_l sin φ − v_f sin γ + d ω_f cos γ) / l − ω_l            (l–φ only)
    θ̇_f = ω_f

``separation_rate`` and ``bearing_rate`` are the single definition of these kinematics.
Like ``nonholo.models.unicycle.unicycle_rates`` they take the trigonometric values as
arguments, so the same functions are compiled by numba for the simulator and called
through ``.py_func`` with sympy expressions by ``nonholo.analysis``.

The two composites below assemble whole link states for compiled code. They call the
primitives, so their ``.py_func`` cannot take sympy arguments (a compiled dispatcher would
be called); symbolic code composes the primitives the same way instead, and the analysis
test suite checks numerically that both compositions agree.
"""
from __future__ import annotations

from numba import njit

SEPARATION_BEARING_STATES = ("l", "phi", "theta_f")
SEPARATION_SEPARATION_STATES = ("l_1", "l_2", "theta_f")
FOLLOWER_INPUTS = ("v_f", "omega_f")


@njit(inline="always")
def separation_rate(v_f, omega_f, v_leader, d, cos_bearing, cos_gamma, sin_gamma):
    """l̇ of one leader–follower separation.

    The leader's angular velocity does not appear: turning a leader about its own axle
    midpoint does not change the distance to the follower's castor point.
    """
    return v_f * cos_gamma + d * omega_f * sin_gamma - v_leader * cos_bearing


@njit(inline="always")
def bearing_rate(v_f, omega_f, v_leader, omega_leader, separation, d, sin_bearing,
                 cos_gamma, sin_gamma):
    """φ̇ of the l–φ link (bearing measured in the leader's rotating body frame)."""
    return (v_leader * sin_bearing - v_f * sin_gamma + d * omega_f * cos_gamma) / separation \
        - omega_leader


@njit(inline="always")
def separation_bearing_rates(v_f, omega_f, v_leader, omega_leader, separation, d,
                             cos_bearing, sin_bearing, cos_gamma, sin_gamma):
    """(l̇, φ̇, θ̇_f) of an l–φ follower."""
    return (
        separation_rate(v_f, omega_f, v_leader, d, cos_bearing, cos_gamma, sin_gamma),
        bearing_rate(v_f, omega_f, v_leader, omega_leader, separation, d, sin_bearing,
                     cos_gamma, sin_gamma),
        omega_f,
    )


@njit(inline="always")
def separation_separation_rates(v_f, omega_f, v_leader_1, v_leader_2, d,
                                cos_bearing_1, cos_gamma_1, sin_gamma_1,
                                cos_bearing_2, cos_gamma_2, sin_gamma_2):
    """(l̇_1, l̇_2, θ̇_f) of an l–l follower of two leaders."""
    return (
        separation_rate(v_f, omega_f, v_leader_1, d, cos_bearing_1, cos_gamma_1, sin_gamma_1),
        separation_rate(v_f, omega_f, v_leader_2, d, cos_bearing_2, cos_gamma_2, sin_gamma_2),
        omega_f,
    )
