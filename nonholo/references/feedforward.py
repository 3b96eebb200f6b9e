"""Flatness feedforward of the unicycle (thesis Eq 5.1–5.3, spec leader.md §2).

The flat output is the position p_d(t) = (x_d, y_d); heading and inputs follow
algebraically from its first two derivatives, for a direction of motion s = ±1:

    v_d = s·sqrt(ẋ_d² + ẏ_d²)
    θ_d = atan2(s·ẏ_d, s·ẋ_d)                      (four-quadrant, in [−π, π]: −π for ẏ_d = −0.0)
    ω_d = (ẋ_d ÿ_d − ẏ_d ẍ_d) / (ẋ_d² + ẏ_d²)      (independent of s)

θ_d enters the laws only through wrapped differences and its sine and cosine, so atan2's −π
for a signed zero (the same heading as π) is kept as it comes.

The simulator evaluates a reference into a *table*: one row per time at which the
control law is evaluated, with the columns below. Compiled laws index rows by these
constants.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

REF_T, REF_X, REF_Y, REF_DX, REF_DY, REF_DDX, REF_DDY, REF_THETA, REF_V, REF_OMEGA = range(10)
REF_COLUMNS = ("t", "x_d", "y_d", "dx_d", "dy_d", "ddx_d", "ddy_d", "theta_d", "v_d", "omega_d")


@njit(cache=True, error_model="numpy", fastmath=False)
def _fill_rows(t, flat, theta_d, direction, rows):
    """The table's rows in one pass: t, the flat outputs, θ_d (given: numpy's arctan2 is SIMD),
    v_d and ω_d. IEEE arithmetic without fused multiply-adds: the numbers numpy gives for
    the same expressions, bit for bit."""
    for i in range(t.size):
        dx, dy, ddx, ddy = flat[2, i], flat[3, i], flat[4, i], flat[5, i]
        speed_sq = dx * dx + dy * dy
        rows[i, 0], rows[i, 1], rows[i, 2], rows[i, 3], rows[i, 4] = t[i], flat[0, i], flat[1, i], dx, dy
        rows[i, 5], rows[i, 6], rows[i, 7] = ddx, ddy, theta_d[i]
        rows[i, 8] = direction * math.sqrt(speed_sq)
        rows[i, 9] = (dx * ddy - dy * ddx) / speed_sq if speed_sq > 0.0 else 0.0


def table_rows(t: np.ndarray, flat: np.ndarray, direction: int = 1, rows: np.ndarray | None = None) -> np.ndarray:
    """Reference table rows (``REF_COLUMNS``) at times ``t`` (1-D) from the flat outputs there
    (``flat``: (6, len(t)) x_d, y_d, ẋ_d, ẏ_d, ẍ_d, ÿ_d), written to ``rows`` if given.

    θ_d = atan2(s·ẏ_d, s·ẋ_d), v_d = s·|ṗ_d|, ω_d = (ẋ_d ÿ_d − ẏ_d ẍ_d)/|ṗ_d|²; where the
    speed vanishes θ_d is undefined and ω_d is 0/0, returned as 0 (callers that need
    v_d ≠ 0 reject such references beforehand, see ``Reference.check_speed``)."""
    t = np.ascontiguousarray(t, dtype=float)
    flat = np.ascontiguousarray(flat, dtype=float)
    if rows is None:
        rows = np.empty((t.size, len(REF_COLUMNS)))
    if t.ndim != 1 or flat.shape != (6, t.size) or rows.shape != (t.size, len(REF_COLUMNS)):
        raise ValueError(f"table_rows: times (n,), flat outputs (6, n) and rows (n, {len(REF_COLUMNS)}) expected, "
                         f"got {t.shape}, {flat.shape} and {rows.shape}")
    # (s·ẏ_d is exact for s = ±1: the same angles, signed zeros included)
    theta_d = np.arctan2(flat[3], flat[2]) if direction == 1 else np.arctan2(direction * flat[3], direction * flat[2])
    _fill_rows(t, flat, theta_d, direction, rows)
    return rows


def feedforward(dx, dy, ddx, ddy, direction: int = 1):
    """(θ_d, v_d, ω_d) from the flat-output derivatives (arrays or scalars, broadcast), as in
    ``table_rows``."""
    dx, dy, ddx, ddy = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (dx, dy, ddx, ddy)))
    flat = np.zeros((6, dx.size))
    flat[2:] = [a.ravel() for a in (dx, dy, ddx, ddy)]
    rows = table_rows(np.zeros(dx.size), flat, direction)
    return tuple(rows[:, column].reshape(dx.shape)[()] for column in (REF_THETA, REF_V, REF_OMEGA))
