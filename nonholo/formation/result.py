"""Formation simulation results: recorded arrays, metrics, JSON, figures and GIFs."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nonholo.control.posture import HEADING_CONTROLLED
from nonholo.formation import kernel as fk
from nonholo.formation import metrics
from nonholo.formation.model import SEPARATION_BEARING, Follower, Formation, Leader
from nonholo.formation.schedule import target_segments
from nonholo.references.feedforward import REF_THETA, REF_X, REF_Y

TRAJECTORY_FIELDS = {"x": fk.REC_X, "y": fk.REC_Y, "theta": fk.REC_THETA, "xi": fk.REC_XI, "v": fk.REC_V,
                     "omega": fk.REC_OMEGA}
HEADING_NOTE = ("the dynamic-feedback posture law regulates the position only: the final heading is not "
                "controlled (the robot arrives along the goal's x-axis, heading θ_g or θ_g + π)")


@dataclass(frozen=True)
class FormationResult:
    """What ``simulate_formation`` returns.

    ``t`` (N+1,) the output grid; ``record`` (RECORD_FIELDS, N+1, robots, batch) with the
    fields ``kernel.REC_*``; ``reference_rows`` (N+1, 10) the leader reference on the grid
    (None for posture leaders); ``substeps`` (N,) the RK4 sub-steps used per output step.
    Array accessors take ``member`` (the formation of a batch, default 0).
    """

    formations: list[Formation]
    t: np.ndarray
    record: np.ndarray
    reference_rows: np.ndarray | None
    substeps: np.ndarray
    elapsed_s: float

    @property
    def formation(self) -> Formation:
        return self.formations[0]

    @property
    def names(self) -> tuple[str, ...]:
        return self.formation.names

    def index(self, robot: str | int) -> int:
        return robot if isinstance(robot, int) else self.names.index(robot)

    def field(self, index: int, member: int = 0) -> np.ndarray:
        """(robots, N+1) array of record field ``index``."""
        return self.record[index, :, :, member].T

    def trajectory(self, name: str, member: int = 0) -> np.ndarray:
        """(robots, N+1) array of ``x, y, theta, xi, v`` or ``omega``."""
        return self.field(TRAJECTORY_FIELDS[name], member)

    def outputs(self, robot, member: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """The link outputs (l, φ) or (l1, l2) of a follower over time."""
        i = self.index(robot)
        return self.record[fk.REC_OUT1, :, i, member], self.record[fk.REC_OUT2, :, i, member]

    def output_errors(self, robot, member: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Signed output errors z − z_d of a follower over time (φ on its continuous branch)."""
        i = self.index(robot)
        return self.record[fk.REC_ERR1, :, i, member], self.record[fk.REC_ERR2, :, i, member]

    def output_rates(self, robot, member: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(l̇, φ̇) or (l̇1, l̇2) from the follower kinematics at the applied commands."""
        i = self.index(robot)
        return self.record[fk.REC_RATE1, :, i, member], self.record[fk.REC_RATE2, :, i, member]

    def sin_gamma_difference(self, robot, member: int = 0) -> np.ndarray:
        return self.record[fk.REC_SIN_GAMMA, :, self.index(robot), member]

    # ------------------------------------------------------------------ metrics
    def follower_metrics(self, robot, member: int = 0) -> dict:
        """JSON-ready ``formation`` block of one follower."""
        follower = self.formations[member].robot(robot) if isinstance(robot, str) else self.formations[member].robots[robot]
        i = self.index(follower.name)
        errors = self.output_errors(i, member)
        out = {"law": follower.law, "leaders": list(follower.leaders)}
        for name, error in zip(follower.outputs, errors):
            out[f"{name}_error"] = {k: float(v) for k, v in metrics.error_summary(error).items()}
        out["settling"] = self._settling(follower, errors)
        x, y = self.trajectory("x", member), self.trajectory("y", member)
        others = [j for j in range(len(self.names)) if j != i]
        distance = np.hypot(x[others] - x[i], y[others] - y[i]) if others else np.full((1, self.t.size), np.inf)
        peak_v, peak_v_time = metrics.peak_with_time(self.t, self.trajectory("v", member)[i])
        peak_w, peak_w_time = metrics.peak_with_time(self.t, self.trajectory("omega", member)[i])
        safety = {"min_distance": float(distance.min()), "min_distance_time": float(self.t[np.argmin(distance.min(axis=0))]),
                  "time_below_2d": float(np.count_nonzero(distance.min(axis=0) < 2 * follower.d) * self.formation.dt),
                  "peak_v": peak_v, "peak_v_time": peak_v_time, "peak_omega": peak_w, "peak_omega_time": peak_w_time,
                  "saturated_samples": int(np.count_nonzero(self.record[fk.REC_SATURATED, :, i, member]))}
        if follower.law != SEPARATION_BEARING:
            sin_difference = np.abs(self.sin_gamma_difference(i, member))
            k = int(np.argmin(sin_difference))
            safety.update(min_abs_sin_gamma_difference=float(sin_difference[k]), min_abs_sin_gamma_time=float(self.t[k]),
                          singular_samples=int(np.count_nonzero(self.record[fk.REC_SINGULAR, :, i, member])))
        out["safety"] = safety
        return out

    def _settling(self, follower: Follower, errors) -> list[dict]:
        entries = []
        segments = target_segments(follower)
        for change in follower.changes:
            entry = {"at": change.at, "mode": change.mode}
            following = [c.at for c in follower.changes if c.at > change.at]
            until = following[0] if following else math.inf
            for output, name in enumerate(follower.outputs):
                segment = next((s for s in segments[output] if s[0] == change.at), None)
                if segment is None:
                    entry[f"{name}_disturbance"] = float(np.abs(errors[output][self.t > change.at]).max())
                else:
                    band = metrics.SETTLING_BAND * abs(segment[2] - segment[1])
                    entry[f"{name}_settling_time"] = metrics.settling_time(self.t, errors[output], change.at, band, until)
                    entry[f"{name}_target"] = segment[2]
            entries.append(entry)
        return entries

    def safety(self, member: int = 0) -> dict:
        """Formation-wide safety figures: closest pair of axle centres, time below 2d."""
        formation = self.formations[member]
        x, y = self.trajectory("x", member), self.trajectory("y", member)
        distances, pairs = metrics.pair_distances(x, y)
        if not pairs:
            return {"min_distance": None}
        k, p = np.unravel_index(int(np.argmin(distances)), distances.shape)
        d = max([f.d for f in formation.followers] or [0.0])
        closest = distances.min(axis=1)
        return {"min_distance": float(distances[k, p]), "min_distance_pair": [self.names[pairs[p][0]], self.names[pairs[p][1]]],
                "min_distance_time": float(self.t[k]), "two_d": 2 * d,
                "time_below_2d": float(np.count_nonzero(closest < 2 * d) * formation.dt)}

    def posture_metrics(self, robot, member: int = 0) -> dict:
        leader = self.formations[member].robot(robot) if isinstance(robot, str) else self.formations[member].robots[robot]
        i = self.index(leader.name)
        distance, heading = metrics.goal_errors(self.trajectory("x", member)[i], self.trajectory("y", member)[i],
                                                self.trajectory("theta", member)[i], leader.goal)
        out = {"goal": list(leader.goal), "position_error": {"final": float(distance[-1]), "max": float(distance.max())},
               "heading_error": {"final": float(heading[-1])},
               "heading_controlled": HEADING_CONTROLLED[leader.controller.name]}
        if not out["heading_controlled"]:
            out["note"] = HEADING_NOTE
        return out

    def tracking_metrics(self, robot, member: int = 0) -> dict:
        i = self.index(robot)
        rows = self.reference_rows
        error = np.hypot(rows[:, REF_X] - self.trajectory("x", member)[i], rows[:, REF_Y] - self.trajectory("y", member)[i])
        heading = np.abs(metrics.wrap(rows[:, REF_THETA] - self.trajectory("theta", member)[i]))
        return {"mean": float(error.mean()), "std": float(error.std()), "max": float(error.max()),
                "final": float(error[-1]), "heading_final": float(heading[-1])}

    def robot_summary(self, i: int, member: int = 0) -> dict:
        robot = self.formations[member].robots[i]
        peak_v, _ = metrics.peak_with_time(self.t, self.trajectory("v", member)[i])
        peak_w, _ = metrics.peak_with_time(self.t, self.trajectory("omega", member)[i])
        out = {"role": "leader" if isinstance(robot, Leader) else "follower",
               "start": [float(s) for s in self.record[:3, 0, i, member]],
               "control": {"peak_v": peak_v, "peak_omega": peak_w}}
        if isinstance(robot, Leader):
            out.update(robot.controller.describe())
            singular = self.record[fk.REC_SINGULAR, :, i, member]
            out["events"] = {"singular_samples": int(np.count_nonzero(singular)),
                             "first_singular_time": float(self.t[np.argmax(singular > 0)]) if singular.any() else None,
                             "saturated_samples": int(np.count_nonzero(self.record[fk.REC_SATURATED, :, i, member]))}
            if robot.posture:
                out["posture"] = self.posture_metrics(i, member)
            else:
                out["error"] = self.tracking_metrics(i, member)
        else:
            out.update({"formation_law": robot.law, "gains": {"k1": robot.k1, "k2": robot.k2}, "d": robot.d,
                        "targets": dict(zip(robot.outputs, robot.targets))})
            out["formation"] = self.follower_metrics(i, member)
        return out

    def to_dict(self, member: int = 0) -> dict:
        """JSON-ready summary of one formation of the batch."""
        formation = self.formations[member]
        return {
            "scenario": formation.name,
            "simulation": {"duration": float(self.t[-1]), "dt": formation.dt, "steps": formation.n_steps,
                           "method": formation.method, "max_substeps": int(self.substeps.max()),
                           "elapsed_s": self.elapsed_s, "batch": len(self.formations)},
            "reference": formation.reference.describe() if formation.reference is not None else None,
            "piconet": formation.piconet,
            "order": [self.names[i] for i in formation.order()],
            "robots": {robot.name: self.robot_summary(i, member) for i, robot in enumerate(formation.robots)},
            "safety": self.safety(member),
        }

    # ------------------------------------------------------------------ figures
    def plot(self, path=None, member: int = 0, snapshots: int = 6):
        """Paths with formation snapshots, output errors, v and ω (one figure)."""
        from nonholo.formation.plotting import plot_formation

        return plot_formation(self, path, member, snapshots)

    def write_gif(self, path, member: int = 0, frames: int = 120, fps: int = 20, trail: float = 20.0):
        """Animated GIF of the formation (matplotlib PillowWriter)."""
        from nonholo.formation.plotting import animate_formation

        return animate_formation(self, path, member, frames, fps, trail)
