"""The unicycle (differential-drive robot), thesis Eq 2.15 / spec leader.md §1.

State q = (x, y, θ), inputs (v, ω):

    ẋ = v cos θ,   ẏ = v sin θ,   θ̇ = ω.

``unicycle_rates`` is the single definition of these kinematics. It takes cos θ and sin θ
as arguments instead of calling a trigonometric library, so that the very same Python
function is compiled by numba for the simulator (with a vectorizable sincos) and called
with sympy expressions for symbolic analysis (``unicycle_rates.py_func``).
"""
from __future__ import annotations

from numba import njit

STATES = ("x", "y", "theta")
INPUTS = ("v", "omega")


@njit(inline="always")
def unicycle_rates(v, omega, cos_theta, sin_theta):
    """(ẋ, ẏ, θ̇) of the unicycle for inputs (v, ω) at heading θ."""
    return v * cos_theta, v * sin_theta, omega
