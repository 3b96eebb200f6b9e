"""Formation and posture metrics on the uniform output grid t_k = k·dt (small pure
functions over recorded arrays; spec follower-posture.md §2.4, §4, §6).

* link output errors |z − z_d| (l–φ: l and φ on its continuous branch, radians; l–l: l1,
  l2): mean, max, final;
* settling time after each change: the time from ``at`` until the error of the changed
  output stays within ``SETTLING_BAND`` (2 %) of the change's size; for outputs the change
  does not touch, the largest deviation after it ("disturbance");
* safety: the minimum axle-centre distance over all pairs of robots, the time during which
  some pair is closer than 2d, peak |v| and |ω| demands, min |sin(γ1 − γ2)| of l–l links;
* posture: distance to the goal (final, max) and final heading error |wrap(θ − θ_g)|.
"""
from __future__ import annotations

import numpy as np

from nonholo.models.formation_geometry import wrap

SETTLING_BAND = 0.02


def error_summary(error: np.ndarray) -> dict:
    """Mean, max and final of |error| along the last axis but one (time is axis 0)."""
    magnitude = np.abs(error)
    return {"mean": magnitude.mean(axis=0), "max": magnitude.max(axis=0), "final": magnitude[-1]}


def settling_time(t: np.ndarray, error: np.ndarray, at: float, band: float, until: float = np.inf) -> float | None:
    """Seconds from ``at`` until |error| stays ≤ ``band`` over the samples in (at, until];
    None if the last sample of the window is still outside the band."""
    window = (t > at + 1e-9 * max(1.0, abs(at))) & (t <= until + 1e-9 * max(1.0, abs(until)))
    outside = np.flatnonzero(np.abs(error[window]) > band)
    if outside.size == 0:
        return 0.0
    times = t[window]
    if outside[-1] == times.size - 1:
        return None
    return float(times[outside[-1] + 1] - at)


def pair_distances(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Axle-centre distances (N+1, pairs) of every pair of robots; x, y are (robots, N+1)."""
    pairs = [(i, j) for i in range(x.shape[0]) for j in range(i + 1, x.shape[0])]
    if not pairs:
        return np.full((x.shape[1], 0), np.inf), pairs
    first, second = np.array(pairs).T
    return np.hypot(x[first] - x[second], y[first] - y[second]).T, pairs


def peak_with_time(t: np.ndarray, values: np.ndarray) -> tuple[float, float]:
    """(max |values|, the time it occurs)."""
    k = int(np.argmax(np.abs(values)))
    return float(abs(values[k])), float(t[k])


def goal_errors(x, y, theta, goal) -> tuple[np.ndarray, np.ndarray]:
    """Distance to the goal and |wrap(θ − θ_g)| along a trajectory."""
    return np.hypot(x - goal[0], y - goal[1]), np.abs(wrap(theta - goal[2]))
