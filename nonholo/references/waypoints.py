"""A C² reference through timed waypoints (cubic spline in time per coordinate).

The spline is defined between the first and the last waypoint times and never
extrapolated: a run starts at t = 0, so the first waypoint must be at t <= 0, and asking
for a time past the last waypoint (a duration longer than the waypoints, or a grid whose
last step ends after them) is an ``InfeasibleReferenceError`` that says which time was
asked and how to fix it.
"""
from __future__ import annotations

import numbers

import numpy as np

from nonholo.errors import InfeasibleReferenceError, ScenarioError
from nonholo.references.base import FORWARD, Reference
from nonholo.tomlfile import describe_value

BOUNDARY_CONDITIONS = ("not-a-knot", "natural", "clamped", "periodic")
PERIODIC_TOLERANCE = 1e-9
"""A periodic spline's last point may differ from its first by this fraction of the path's
extent (rounding); it is then made equal."""


class WaypointReference(Reference):
    """p_d(t) through points (t_i, x_i, y_i), t_i strictly increasing, t_0 <= 0.

    ``boundary``: spline end conditions (scipy names). "clamped" starts and ends at rest,
    which controllers needing v_d ≠ 0 reject; "periodic" needs the last point equal to
    the first. Problems are ``ScenarioError`` whose ``field`` is ``points[i]`` or
    ``boundary``.
    """

    kind = "waypoints"

    def __init__(self, points, boundary: str = "not-a-knot", direction: int = FORWARD):
        points = _points(points)
        if not isinstance(boundary, str) or boundary not in BOUNDARY_CONDITIONS:
            _fail("boundary", f"expected one of {', '.join(BOUNDARY_CONDITIONS)}, got {describe_value(boundary)}")
        if boundary == "periodic":
            first, last = points[0, 1:], points[-1, 1:]
            extent = max(1.0, float(np.ptp(points[:, 1:])))
            if np.max(np.abs(last - first)) > PERIODIC_TOLERANCE * extent:
                _fail("boundary", f"'periodic' needs the last waypoint's position equal to the first, got "
                                  f"({first[0]:g}, {first[1]:g}) and ({last[0]:g}, {last[1]:g}): close the path "
                                  "or use another boundary")
            points[-1, 1:] = first
        super().__init__(direction, float(points[-1, 0]))
        self.points = points
        self.boundary = boundary
        from scipy.interpolate import CubicSpline   # here: scipy costs every command 0.3 s to import

        try:
            with np.errstate(all="ignore"):  # an overflow is reported below
                self._spline = CubicSpline(points[:, 0], points[:, 1:], bc_type=boundary, extrapolate=False)
        except ValueError as exc:  # not reached after the checks above; kept so scipy's wording is never bare
            _fail("points", f"no cubic spline through these points: {exc}")
        if not np.isfinite(self._spline.c).all():
            _fail("points", "the spline through these points overflows: time steps too short for the distances")
        self._velocity = self._spline.derivative(1)
        self._acceleration = self._spline.derivative(2)

    @property
    def time_span(self) -> tuple[float, float]:
        return float(self.points[0, 0]), float(self.points[-1, 0])

    def flat_outputs(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        t0, t1 = self.time_span
        slack = 1e-9 * max(1.0, abs(t0), abs(t1))
        if t.size and (t.min() < t0 - slack or t.max() > t1 + slack):
            asked = float(t.max() if t.max() > t1 + slack else t.min())
            raise InfeasibleReferenceError(
                f"the waypoints cover t = {t0:g} to {t1:g} s but the reference is needed at t = {asked:.6g} s: "
                f"add a waypoint at t >= {asked:.6g} s, or shorten the run (its last step ends at "
                "round(duration/dt)*dt)")
        t = np.clip(t, t0, t1)
        return np.concatenate([self._spline(t).T, self._velocity(t).T, self._acceleration(t).T])

    def describe(self) -> dict:
        return {"kind": self.kind, "points": self.points.tolist(), "boundary": self.boundary,
                "direction": "forward" if self.direction == FORWARD else "backward"}


def _fail(field: str, problem: str):
    raise ScenarioError("waypoints reference", field, problem)


def _points(points) -> np.ndarray:
    """The waypoints as an (n, 3) float array, each problem naming the point."""
    if isinstance(points, np.ndarray) and points.ndim == 2 and points.shape[1] == 3 and points.dtype.kind in "iuf":
        array = points.astype(float)
    else:
        if not isinstance(points, (list, tuple, np.ndarray)):
            _fail("points", f"expected a list of [t, x, y] points, got {describe_value(points)}")
        for i, point in enumerate(points):
            if not (isinstance(point, (list, tuple, np.ndarray)) and len(point) == 3
                    and all(isinstance(v, numbers.Real) and not isinstance(v, bool) for v in point)):
                _fail(f"points[{i}]", f"expected [t, x, y], three numbers, got {describe_value(point)}")
        array = np.array(points, dtype=float).reshape(-1, 3)
    if len(array) < 2:
        _fail("points", f"expected at least 2 points [t, x, y], got {len(array)}")
    bad = np.flatnonzero(~np.isfinite(array).all(axis=1))
    if bad.size:
        _fail(f"points[{bad[0]}]", f"expected finite numbers, got {array[bad[0]].tolist()}")
    steps = np.diff(array[:, 0])
    back = np.flatnonzero(steps <= 0)
    if back.size:
        i = back[0] + 1
        _fail(f"points[{i}]", f"time {array[i, 0]:g} s is not after the previous waypoint's {array[i - 1, 0]:g} s: "
                              "waypoint times must be strictly increasing")
    if array[0, 0] > 0:
        _fail("points[0]", f"the first waypoint is at t = {array[0, 0]:g} s but a run starts at t = 0: "
                           "add a waypoint at t <= 0")
    return array
