"""Flatness feedforward of the unicycle (thesis Eq 5.1–5.3, spec leader.md §2).

The flat output is the position p_d(t) = (x_d, y_d); heading and inputs follow
algebraically from its first two derivatives, for a direction of motion s = ±1:

    v_d = s·sqrt(ẋ_d² + ẏ_d²)
    θ_d = atan2(s·ẏ_d, s·ẋ_d)                      (four-quadrant, wrapped to (−π, π])
    ω_d = (ẋ_d ÿ_d − ẏ_d ẍ_d) / (ẋ_d² + ẏ_d²)      (independent of s)

The simulator evaluates a reference into a *table*: one row per time at which the
control law is evaluated, with the columns below. Compiled laws index rows by these
constants.
"""
from __future__ import annotations

import numpy as np

REF_T, REF_X, REF_Y, REF_DX, REF_DY, REF_DDX, REF_DDY, REF_THETA, REF_V, REF_OMEGA = range(10)
REF_COLUMNS = ("t", "x_d", "y_d", "dx_d", "dy_d", "ddx_d", "ddy_d", "theta_d", "v_d", "omega_d")


def feedforward(dx, dy, ddx, ddy, direction: int = 1):
    """(θ_d, v_d, ω_d) from the flat-output derivatives (arrays or scalars).

    Where the speed vanishes θ_d is undefined and ω_d is 0/0; there ω_d is returned as 0
    (callers that need v_d ≠ 0 reject such references beforehand, see
    ``Reference.check_speed``).
    """
    dx, dy, ddx, ddy = (np.asarray(a, dtype=float) for a in (dx, dy, ddx, ddy))
    speed_sq = dx * dx + dy * dy
    v_d = direction * np.sqrt(speed_sq)
    theta_d = np.arctan2(direction * dy, direction * dx)
    with np.errstate(invalid="ignore", divide="ignore"):
        omega_d = np.where(speed_sq > 0.0, (dx * ddy - dy * ddx) / np.where(speed_sq > 0.0, speed_sq, 1.0), 0.0)
    return theta_d, v_d, omega_d

