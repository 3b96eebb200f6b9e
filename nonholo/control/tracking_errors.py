"""Tracking error of every Chapter 4 law (thesis Eq 4.16; spec leader.md §1).

Position error desired − actual, rotated into the **robot** frame (actual heading θ);
heading error desired − actual, wrapped to (−π, π]:

    e1 =  cos θ (x_d − x) + sin θ (y_d − y)
    e2 = −sin θ (x_d − x) + cos θ (y_d − y)
    e3 = wrap(θ_d − θ)

and sin e3, cos e3 by the angle-difference identities (``heading_error_sincos``).
"""
from __future__ import annotations

from numba import njit

from nonholo.numerics import sincos, wrap_angle
from nonholo.references.feedforward import REF_THETA, REF_X, REF_Y


@njit(inline="always", error_model="numpy")
def tracking_errors(x, y, theta, cos_theta, sin_theta, ref):
    """(e1, e2, e3) of a robot at (x, y, θ) against the reference row ``ref``."""
    dx = ref[REF_X] - x
    dy = ref[REF_Y] - y
    e1 = cos_theta * dx + sin_theta * dy
    e2 = -sin_theta * dx + cos_theta * dy
    e3 = wrap_angle(ref[REF_THETA] - theta)
    return e1, e2, e3


@njit(inline="always", error_model="numpy")
def heading_error_sincos(cos_theta, sin_theta, ref):
    """(sin e3, cos e3) of e3 = θ_d − θ by the angle-difference identities, from the robot's
    cos θ and sin θ (which its kinematics need anyway) and the reference's sin θ_d, cos θ_d:
    one sin/cos of θ_d, the same for every robot of a batch at one instant (computed once per
    loop over them, and off a single run's chain of dependent operations), instead of one of
    each robot's e3. Equal to sin/cos of e3 to rounding (an absolute error below 3e-16)."""
    sin_d, cos_d = sincos(ref[REF_THETA])
    return sin_d * cos_theta - cos_d * sin_theta, cos_d * cos_theta + sin_d * sin_theta
