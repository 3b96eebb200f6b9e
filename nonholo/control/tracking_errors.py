"""Tracking error of every Chapter 4 law (thesis Eq 4.16; spec leader.md §1).

Position error desired − actual, rotated into the **robot** frame (actual heading θ);
heading error desired − actual, wrapped to (−π, π]:

    e1 =  cos θ (x_d − x) + sin θ (y_d − y)
    e2 = −sin θ (x_d − x) + cos θ (y_d − y)
    e3 = wrap(θ_d − θ)
"""
from __future__ import annotations

from numba import njit

from nonholo.numerics import wrap_angle
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
