"""Simulation results: arrays, metrics and plots."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from nonholo.references.feedforward import REF_COLUMNS
from nonholo.sim import kernel as k
from nonholo.sim.scenario import Scenario

TRAJECTORY_FIELDS = ("x", "y", "theta", "xi", "v", "omega")


def _none_if_inf(value: float):
    return None if math.isinf(value) else float(value)


@dataclass(frozen=True)
class Metrics:
    """Per-robot metrics (arrays over robots), sampled on the uniform grid t_k = k·dt.

    ``error_*``: position-error norm ‖(x_d − x, y_d − y)‖ (m): mean, std (ddof 0), var,
    rms, max, final. ``heading_*``: |wrap(θ_d − θ)| (rad): mean, rms, max, final.
    ``peak_v``, ``peak_omega``, ``rms_v``, ``rms_omega``: commands applied (after
    saturation); ``effort`` = duration · mean(v² + ω²). ``saturated_v``/``saturated_omega``:
    samples at which the limit clipped the command; ``singular``: samples at which a
    singularity guard acted (dynamic feedback |ξ| < ξ_min), ``first_singular`` its first
    time (inf if never).
    """

    error_mean: np.ndarray
    error_std: np.ndarray
    error_var: np.ndarray
    error_rms: np.ndarray
    error_max: np.ndarray
    error_final: np.ndarray
    heading_mean: np.ndarray
    heading_rms: np.ndarray
    heading_max: np.ndarray
    heading_final: np.ndarray
    peak_v: np.ndarray
    peak_omega: np.ndarray
    rms_v: np.ndarray
    rms_omega: np.ndarray
    effort: np.ndarray
    saturated_v: np.ndarray
    saturated_omega: np.ndarray
    singular: np.ndarray
    first_singular: np.ndarray

    @classmethod
    def from_stats(cls, stats: np.ndarray, samples: int, duration: float) -> "Metrics":
        var = stats[k.E_M2] / samples
        return cls(
            error_mean=stats[k.E_MEAN], error_std=np.sqrt(var), error_var=var,
            error_rms=np.sqrt(stats[k.E_SQ] / samples), error_max=stats[k.E_MAX], error_final=stats[k.E_FINAL],
            heading_mean=stats[k.H_SUM] / samples, heading_rms=np.sqrt(stats[k.H_SQ] / samples),
            heading_max=stats[k.H_MAX], heading_final=stats[k.H_FINAL],
            peak_v=stats[k.V_PEAK], peak_omega=stats[k.W_PEAK],
            rms_v=np.sqrt(stats[k.V_SQ] / samples), rms_omega=np.sqrt(stats[k.W_SQ] / samples),
            effort=duration * (stats[k.V_SQ] + stats[k.W_SQ]) / samples,
            saturated_v=stats[k.SAT_V].astype(np.int64), saturated_omega=stats[k.SAT_W].astype(np.int64),
            singular=stats[k.SINGULAR].astype(np.int64), first_singular=stats[k.FIRST_SINGULAR],
        )

    def robot(self, i: int, samples: int) -> dict:
        """JSON-ready metrics of robot ``i``."""
        return {
            "error": {s: float(getattr(self, f"error_{s}")[i]) for s in ("mean", "std", "var", "rms", "max", "final")},
            "heading_error": {s: float(getattr(self, f"heading_{s}")[i]) for s in ("mean", "rms", "max", "final")},
            "control": {"peak_v": float(self.peak_v[i]), "peak_omega": float(self.peak_omega[i]),
                        "rms_v": float(self.rms_v[i]), "rms_omega": float(self.rms_omega[i]),
                        "effort": float(self.effort[i])},
            "events": {"saturated_v_samples": int(self.saturated_v[i]),
                       "saturated_omega_samples": int(self.saturated_omega[i]),
                       "saturated_fraction": float(max(self.saturated_v[i], self.saturated_omega[i]) / samples),
                       "singular_samples": int(self.singular[i]),
                       "first_singular_time": _none_if_inf(self.first_singular[i])},
        }


@dataclass(frozen=True)
class SimulationResult:
    """What ``simulate`` returns.

    ``t`` (N+1,) the output grid; ``reference_rows`` (N+1, 10) the reference on it
    (columns ``REF_COLUMNS``); ``metrics`` per robot; trajectories (robots × N+1 arrays
    ``x, y, theta, xi, v, omega``) when recorded.
    """

    scenario: Scenario
    t: np.ndarray
    reference_rows: np.ndarray
    stats: np.ndarray
    record: np.ndarray | None
    substeps: np.ndarray
    elapsed_s: float
    metrics: Metrics = field(init=False)

    def __post_init__(self):
        object.__setattr__(self, "metrics", Metrics.from_stats(self.stats, self.t.size, float(self.t[-1])))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.scenario.robots)

    def index(self, robot: str | int) -> int:
        if isinstance(robot, int):
            return robot
        try:
            return self.names.index(robot)
        except ValueError:
            raise KeyError(f"no robot named {robot!r} (robots: {', '.join(self.names)})") from None

    def trajectory(self, name: str) -> np.ndarray:
        """(robots, N+1) array of ``x, y, theta, xi, v`` or ``omega``."""
        if self.record is None:
            raise ValueError("trajectories were not recorded (simulate(..., record=True))")
        return self.record[TRAJECTORY_FIELDS.index(name)].T

    def __getattr__(self, name):
        if name in TRAJECTORY_FIELDS:
            return self.trajectory(name)
        if name in REF_COLUMNS[1:]:
            return self.reference_rows[:, REF_COLUMNS.index(name)]
        raise AttributeError(name)

    def error_norm(self) -> np.ndarray:
        """(robots, N+1) position-error norm on the grid."""
        return np.hypot(self.x_d - self.x, self.y_d - self.y)

    def to_dict(self) -> dict:
        """JSON-ready summary: per robot its controller, gains and metrics."""
        samples = self.t.size
        robots = {}
        for i, robot in enumerate(self.scenario.robots):
            robots[robot.name] = {**self.metrics.robot(i, samples), **robot.controller.describe(),
                                  "start": list(robot.start), "substeps": int(self.substeps[i])}
        sc = self.scenario
        return {
            "scenario": sc.name,
            "simulation": {"duration": float(self.t[-1]), "dt": sc.dt, "steps": sc.n_steps, "method": sc.method,
                           "control_period": sc.control_period, "elapsed_s": self.elapsed_s},
            "reference": sc.reference.describe(),
            "robots": robots,
        }

    def plot(self, robots=None, path=None, max_robots: int = 8):
        """Desired vs actual path, error norm, v and ω over time (one figure).

        ``robots``: names or indices to show (default: the first ``max_robots``).
        ``path``: save to this file (PNG, PDF, SVG…) and close the figure.
        """
        from nonholo.sim.plotting import plot_result

        return plot_result(self, robots, path, max_robots)
