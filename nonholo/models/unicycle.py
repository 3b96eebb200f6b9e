"""The unicycle (differential-drive robot), thesis Eq 2.15 / spec leader.md §1.

State q = (x, y, θ), inputs (v, ω):

    ẋ = v cos θ,   ẏ = v sin θ,   θ̇ = ω.

``unicycle_rates`` is the single definition of these kinematics. It takes cos θ and sin θ
as arguments instead of calling a trigonometric library, so that the very same Python
function is compiled by numba for the simulator (with a vectorizable sincos) and called
with sympy expressions for symbolic analysis (``unicycle_rates.py_func``).
"""
from __future__ import annotations

import math

from numba import njit

from nonholo.numerics import sinc_of

STATES = ("x", "y", "theta")
INPUTS = ("v", "omega")


@njit(inline="always")
def unicycle_rates(v, omega, cos_theta, sin_theta):
    """(ẋ, ẏ, θ̇) of the unicycle for inputs (v, ω) at heading θ."""
    return v * cos_theta, v * sin_theta, omega


# IEEE arithmetic (no fast-math): the simulator's link step and the robot programs call it
# alike, and their runs must be equal (spec fleet.md §6).
@njit(cache=True, error_model="numpy")
def unicycle_arc(x, y, theta, v, omega, h):
    """The unicycle's exact pose after ``h`` seconds under constant (v, ω), in chord form:
    the chord v h sinc(ω h / 2) along the mean heading θ + ω h / 2 (no cancellation at small
    ω h, a segment at ω = 0). ``h`` = 0 gives the pose itself."""
    half = 0.5 * omega * h
    chord = v * h * sinc_of(half, math.sin(half))
    mid = theta + half
    return x + chord * math.cos(mid), y + chord * math.sin(mid), theta + omega * h
