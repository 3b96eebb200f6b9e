"""A C² reference through timed waypoints (cubic spline in time per coordinate)."""
from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from nonholo.references.base import FORWARD, Reference

BOUNDARY_CONDITIONS = ("not-a-knot", "natural", "clamped", "periodic")


class WaypointReference(Reference):
    """p_d(t) through points (t_i, x_i, y_i), t_i strictly increasing.

    ``boundary``: spline end conditions (scipy names). "clamped" starts and ends at rest,
    which controllers needing v_d ≠ 0 reject; "periodic" needs the last point equal to
    the first.
    """

    kind = "waypoints"

    def __init__(self, points, boundary: str = "not-a-knot", direction: int = FORWARD):
        points = np.asarray(points, dtype=float)
        if points.ndim != 2 or points.shape[1] != 3 or points.shape[0] < 2:
            raise ValueError(f"waypoints must be a list of at least 2 [t, x, y] triples, got shape {points.shape}")
        if not np.all(np.isfinite(points)):
            raise ValueError("waypoints must be finite numbers")
        if np.any(np.diff(points[:, 0]) <= 0):
            raise ValueError("waypoint times must be strictly increasing")
        if boundary not in BOUNDARY_CONDITIONS:
            raise ValueError(f"boundary must be one of {', '.join(BOUNDARY_CONDITIONS)}, got {boundary!r}")
        if boundary == "periodic" and not np.allclose(points[0, 1:], points[-1, 1:]):
            raise ValueError("a periodic spline needs the last waypoint equal to the first")
        super().__init__(direction, float(points[-1, 0] - points[0, 0]))
        self.points = points
        self.boundary = boundary
        self._spline = CubicSpline(points[:, 0], points[:, 1:], bc_type=boundary, extrapolate=False)
        self._velocity = self._spline.derivative(1)
        self._acceleration = self._spline.derivative(2)

    @property
    def time_span(self) -> tuple[float, float]:
        return float(self.points[0, 0]), float(self.points[-1, 0])

    def flat_outputs(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        t0, t1 = self.time_span
        if t.size and (t.min() < t0 - 1e-9 or t.max() > t1 + 1e-9):
            raise ValueError(f"waypoint reference is defined on [{t0:g}, {t1:g}] s only")
        t = np.clip(t, t0, t1)
        return np.concatenate([self._spline(t).T, self._velocity(t).T, self._acceleration(t).T])

    def describe(self) -> dict:
        return {"kind": self.kind, "points": self.points.tolist(), "boundary": self.boundary,
                "direction": "forward" if self.direction == FORWARD else "backward"}
