"""The one result type of every run: trajectories per robot, tracking, posture and formation
metrics, events, JSON, a tidy per-sample table, figures."""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field

import numpy as np

from nonholo.control.posture import HEADING_CONTROLLED
from nonholo.references.feedforward import REF_COLUMNS
from nonholo.sim import kernel as k
from nonholo.sim.scenario import Follower, Robot, Scenario
from nonholo.sim.targets import target_segments, target_table

TRAJECTORY_FIELDS = {"x": k.REC_X, "y": k.REC_Y, "theta": k.REC_THETA, "xi": k.REC_XI, "v": k.REC_V,
                     "omega": k.REC_OMEGA}
HEADING_NOTE = ("the dynamic-feedback posture law regulates the position only: the final heading is not "
                "controlled (the robot arrives along the goal's x-axis, heading θ_g or θ_g + π)")
# Columns of the tidy table: (name, unit, record field).
TABLE_COLUMNS = (("x", "m", k.REC_X), ("y", "m", k.REC_Y), ("theta", "rad", k.REC_THETA), ("xi", "", k.REC_XI),
                 ("v", "m/s", k.REC_V), ("omega", "rad/s", k.REC_OMEGA), ("error_1", "", k.REC_ERR1),
                 ("error_2", "", k.REC_ERR2))


# Settling: from a change until the error of the changed output stays within this fraction of its size.
SETTLING_BAND = 0.02


def settling_time(t: np.ndarray, error: np.ndarray, at: float, band: float, until: float = np.inf) -> float | None:
    """Seconds from ``at`` until |error| stays ≤ ``band`` over the samples in (at, until];
    None if the last sample of the window is still outside the band."""
    window = (t > at + 1e-9 * max(1.0, abs(at))) & (t <= until + 1e-9 * max(1.0, abs(until)))
    outside = np.flatnonzero(np.abs(error[window]) > band)
    if outside.size == 0:
        return 0.0
    times = t[window]
    return None if outside[-1] == times.size - 1 else float(times[outside[-1] + 1] - at)


def _none_if_inf(value: float):
    return None if math.isinf(value) else float(value)


@dataclass(frozen=True)
class Metrics:
    """Per-robot metrics (arrays over robots, and over batch members for a batch), sampled
    on the uniform grid t_k = k·dt.

    ``error_*``: a root's position-error norm ‖(x_d − x, y_d − y)‖ (m) — to the reference, or
    to the goal for a posture root — and a follower's first output error |z1 − z1_d|: mean,
    std (ddof 0), var, rms, max, final. ``heading_*``: a root's |wrap(θ_d − θ)| (rad), a
    follower's |z2 − z2_d|: mean, rms, max, final. ``peak_v``, ``peak_omega``, ``rms_v``,
    ``rms_omega``: commands applied (after saturation); ``effort`` = duration · mean(v² + ω²).
    ``saturated_v``/``saturated_omega``: samples at which the limit clipped v / ω, ``saturated``
    those at which it clipped either (or both);
    ``singular``: samples at which a singularity guard acted, ``first_singular`` its first
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
    saturated: np.ndarray
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
            saturated=stats[k.SAT_ANY].astype(np.int64),
            singular=stats[k.SINGULAR].astype(np.int64), first_singular=stats[k.FIRST_SINGULAR],
        )

    def robot(self, i: int, samples: int) -> dict:
        """JSON-ready metrics of robot ``i`` (arrays over robots)."""
        return {
            "error": {s: float(getattr(self, f"error_{s}")[i]) for s in ("mean", "std", "var", "rms", "max", "final")},
            "heading_error": {s: float(getattr(self, f"heading_{s}")[i]) for s in ("mean", "rms", "max", "final")},
            "control": {"peak_v": float(self.peak_v[i]), "peak_omega": float(self.peak_omega[i]),
                        "rms_v": float(self.rms_v[i]), "rms_omega": float(self.rms_omega[i]),
                        "effort": float(self.effort[i])},
            "events": {"saturated_v_samples": int(self.saturated_v[i]),
                       "saturated_omega_samples": int(self.saturated_omega[i]),
                       "saturated_fraction": float(self.saturated[i] / samples),
                       "singular_samples": int(self.singular[i]),
                       "first_singular_time": _none_if_inf(self.first_singular[i])},
        }


@dataclass(frozen=True)
class SimulationResult:
    """What ``simulate`` returns.

    ``t`` (N+1,) the output grid; ``reference_rows`` (N+1, 10) the reference on it (columns
    ``REF_COLUMNS``; None without a reference); ``stats`` (STAT_COUNT, robots, members) the
    kernel's running statistics; ``pair_stats`` (PAIR_COUNT, formations, members) the
    closest pair of each connected formation; ``record`` (rows, N+1, robots, members) when
    recorded (``nonholo.sim.kernel.REC_*``: the robot rows, then the link rows of a follower
    only when the scenario has followers); ``substeps`` (robots,) the most RK4 sub-steps per
    output step used (over the members of a batch; ``member_substeps`` (robots, members)
    each member's own); ``rk4_steps`` the RK4 steps integrated
    over every robot of every member, runs again with more sub-steps included (what the
    sub-step plan cost: robots × output steps for one step each; 0 for ``solve_ivp``; for a
    fleet's trajectories, the steps its robots integrated on the plan they were given).
    ``metrics`` per robot. Accessors take ``member`` (the scenario of a batch, default 0).
    """

    scenarios: tuple[Scenario, ...]
    t: np.ndarray
    reference_rows: np.ndarray | None
    stats: np.ndarray
    pair_stats: np.ndarray
    record: np.ndarray | None
    substeps: np.ndarray
    elapsed_s: float
    rk4_steps: int = 0
    member_substeps: np.ndarray | None = None
    metrics: Metrics = field(init=False, repr=False)

    def __post_init__(self):
        if self.member_substeps is None:
            object.__setattr__(self, "member_substeps", np.repeat(self.substeps[:, None], len(self.scenarios), axis=1))
        stats = self.stats[:, :, 0] if len(self.scenarios) == 1 else self.stats
        object.__setattr__(self, "metrics", Metrics.from_stats(stats, self.t.size, float(self.t[-1])))

    # ------------------------------------------------------------------ access
    @property
    def scenario(self) -> Scenario:
        return self.scenarios[0]

    formation = scenario      # the thesis's word for a scenario with followers
    formations = property(lambda self: list(self.scenarios))

    @property
    def names(self) -> tuple[str, ...]:
        return self.scenario.names

    def index(self, robot: str | int) -> int:
        if isinstance(robot, (int, np.integer)):
            return int(robot)
        try:
            return self.names.index(robot)
        except ValueError:
            raise KeyError(f"no robot named {robot!r} (robots: {', '.join(self.names)})"[:300]) from None

    def _recorded(self) -> np.ndarray:
        if self.record is None:
            raise ValueError("trajectories were not recorded (simulate(..., record=True))")
        return self.record

    def field(self, index: int, member: int = 0) -> np.ndarray:
        """(robots, N+1) array of record field ``index`` (``nonholo.sim.kernel.REC_*``)."""
        return self._recorded()[index, :, :, member].T

    def trajectory(self, name: str, member: int = 0) -> np.ndarray:
        """(robots, N+1) array of ``x, y, theta, xi, v`` or ``omega``."""
        return self.field(TRAJECTORY_FIELDS[name], member)

    def __getattr__(self, name):
        if name in TRAJECTORY_FIELDS:
            return self.trajectory(name)
        if name in REF_COLUMNS[1:] and self.reference_rows is not None:
            return self.reference_rows[:, REF_COLUMNS.index(name)]
        raise AttributeError(name)

    def error_norm(self, member: int = 0) -> np.ndarray:
        """(robots, N+1) position-error norm of the roots (to the reference or the goal)."""
        return np.abs(self.field(k.REC_ERR1, member))

    def _link_field(self, index: int, robot, member: int) -> np.ndarray:
        """A follower's link row over time (zeros for a robot of a scenario without followers,
        whose record has no link rows)."""
        record = self._recorded()
        if record.shape[0] <= index:
            return np.zeros(record.shape[1])
        return record[index, :, self.index(robot), member]

    def outputs(self, robot, member: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """The link outputs (l, φ) or (l1, l2) of a follower over time (φ continuous)."""
        return self._link_field(k.REC_OUT1, robot, member), self._link_field(k.REC_OUT2, robot, member)

    def output_errors(self, robot, member: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Signed output errors z_d − z of a follower over time, desired minus actual as every
        error (spec README; φ on its continuous branch)."""
        i = self.index(robot)
        return self._recorded()[k.REC_ERR1, :, i, member], self._recorded()[k.REC_ERR2, :, i, member]

    def output_rates(self, robot, member: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(l̇, φ̇) or (l̇1, l̇2) from the follower kinematics at the applied commands."""
        return self._link_field(k.REC_RATE1, robot, member), self._link_field(k.REC_RATE2, robot, member)

    def sin_gamma_difference(self, robot, member: int = 0) -> np.ndarray:
        return self._link_field(k.REC_SIN_GAMMA, robot, member)

    # ------------------------------------------------------------------ metrics
    def _stat(self, name: int, i: int, member: int) -> float:
        return float(self.stats[name, i, member])

    def _events(self, i: int, member: int) -> dict:
        samples = self.t.size
        sat_v, sat_w, sat = (self._stat(name, i, member) for name in (k.SAT_V, k.SAT_W, k.SAT_ANY))
        out = {"saturated_v_samples": int(sat_v), "saturated_omega_samples": int(sat_w),
               "saturated_fraction": sat / samples, "saturated_samples": int(sat),
               "singular_samples": int(self._stat(k.SINGULAR, i, member)),
               "first_singular_time": _none_if_inf(self._stat(k.FIRST_SINGULAR, i, member))}
        scenario = self.scenarios[member]
        if scenario.network is not None and scenario.hold_every and scenario.robots[i].parents:
            # a follower under a link model: its watchdog (spec fleet.md §5)
            out["watchdog_stops"] = int(self._stat(k.WATCHDOG_STOPS, i, member))
            out["watchdog_stopped_s"] = self._stat(k.WATCHDOG_STOPPED, i, member) * scenario.dt * scenario.hold_every
        return out

    def _control(self, i: int, member: int) -> dict:
        samples, s = self.t.size, lambda name: self._stat(name, i, member)
        return {"peak_v": s(k.V_PEAK), "peak_v_time": s(k.V_PEAK_T), "peak_omega": s(k.W_PEAK),
                "peak_omega_time": s(k.W_PEAK_T), "rms_v": math.sqrt(s(k.V_SQ) / samples),
                "rms_omega": math.sqrt(s(k.W_SQ) / samples), "effort": float(self.t[-1]) * (s(k.V_SQ) + s(k.W_SQ)) / samples}

    def _robot_metrics(self, robot, member: int) -> dict:
        i = self.index(robot)
        return Metrics.from_stats(self.stats[:, i:i + 1, member], self.t.size, float(self.t[-1])).robot(0, self.t.size)

    def tracking_metrics(self, robot, member: int = 0) -> dict:
        """Position-error norm statistics of a tracking root (m)."""
        return self._robot_metrics(robot, member)["error"]

    def heading_metrics(self, robot, member: int = 0) -> dict:
        return self._robot_metrics(robot, member)["heading_error"]

    def posture_metrics(self, robot, member: int = 0) -> dict:
        i = self.index(robot)
        root = self.scenarios[member].robots[i]
        out = {"goal": list(root.goal), "position_error": {"final": self._stat(k.E_FINAL, i, member),
                                                           "max": self._stat(k.E_MAX, i, member)},
               "heading_error": {"final": self._stat(k.H_FINAL, i, member)},
               "heading_controlled": HEADING_CONTROLLED.get(root.controller.name, True)}
        if not out["heading_controlled"]:
            out["note"] = HEADING_NOTE
        return out

    def follower_metrics(self, robot, member: int = 0) -> dict:
        """JSON-ready ``formation`` block of one follower."""
        i = self.index(robot)
        follower = self.scenarios[member].robots[i]
        s = lambda name: self._stat(name, i, member)  # noqa: E731
        samples = self.t.size
        out = {"law": follower.law, "leaders": list(follower.leaders)}
        first, second = follower.outputs
        out[f"{first}_error"] = {"mean": s(k.E_MEAN), "max": s(k.E_MAX), "final": s(k.E_FINAL)}
        out[f"{second}_error"] = {"mean": s(k.H_SUM) / samples, "max": s(k.H_MAX), "final": s(k.H_FINAL)}
        # per change of targets (none: nothing to settle); changes but no record to measure them: None
        if not follower.changes:
            out["settling"] = []
        else:
            out["settling"] = self._settling(follower, i, member) if self.record is not None else None
        near = s(k.NEAR)
        safety = {"min_distance": near if math.isfinite(near) else None,
                  "min_distance_time": s(k.NEAR_T) if math.isfinite(near) else None,
                  "time_below_2d": s(k.BELOW_2D) * self.scenarios[member].dt,
                  "peak_v": s(k.V_PEAK), "peak_v_time": s(k.V_PEAK_T), "peak_omega": s(k.W_PEAK),
                  "peak_omega_time": s(k.W_PEAK_T), "saturated_samples": self._events(i, member)["saturated_samples"]}
        if follower.law != "separation-bearing":
            safety.update(min_abs_sin_gamma_difference=s(k.MIN_SIN), min_abs_sin_gamma_time=s(k.MIN_SIN_T),
                          singular_samples=int(s(k.SINGULAR)), sin_gamma_sign_changes=int(s(k.SIN_CROSSINGS)))
        out["safety"] = safety
        return out

    def _settling(self, follower: Follower, i: int, member: int) -> list[dict]:
        errors = self.output_errors(i, member)
        targets = target_table(follower, self.t)   # z_d(t) less its constant branch offset
        entries = []
        segments = target_segments(follower)
        for change in follower.changes:
            entry = {"at": change.at, "mode": change.mode}
            following = [c.at for c in follower.changes if c.at > change.at]
            until = following[0] if following else math.inf
            for output, name in enumerate(follower.outputs):
                segment = next((seg for seg in segments[output] if seg[0] == change.at), None)
                if segment is None:
                    entry[f"{name}_disturbance"] = float(np.abs(errors[output][self.t > change.at]).max())
                else:
                    band = SETTLING_BAND * abs(segment[2] - segment[1])
                    # the output against its new target, z − z_d,end = (z_d(t) − z_d,end) − (z_d − z): a
                    # step's error, and a ramp's distance to where it goes (within the band from 0.86
                    # of the smoothstep on, for an exact follower: settling before the ramp's end)
                    away = targets[:, output] - segment[2] - errors[output]
                    entry[f"{name}_settling_time"] = settling_time(self.t, away, change.at, band, until)
                    entry[f"{name}_target"] = segment[2]
            entries.append(entry)
        return entries

    def safety(self, member: int = 0) -> dict:
        """The closest pair of axle centres within any connected formation, its time, and
        the samples during which a pair was closer than 2d (d the largest castor offset)."""
        scenario = self.scenarios[member]
        pairs = self.pair_stats[:, :, member]
        finite = np.isfinite(pairs[k.CLOSEST])
        if not finite.any():
            return {"min_distance": None}
        c = int(np.argmin(np.where(finite, pairs[k.CLOSEST], np.inf)))
        d = max([f.d for f in scenario.followers] or [0.0])
        return {"min_distance": float(pairs[k.CLOSEST, c]),
                "min_distance_pair": [self.names[int(pairs[k.CLOSEST_I, c])], self.names[int(pairs[k.CLOSEST_J, c])]],
                "min_distance_time": float(pairs[k.CLOSEST_T, c]), "two_d": 2 * d,
                "time_below_2d": float(np.nanmax(pairs[k.BELOW_ANY])) * scenario.dt}

    def robot_summary(self, i: int, member: int = 0) -> dict:
        robot = self.scenarios[member].robots[i]
        start = [float(v) for v in (self.record[:3, 0, i, member] if self.record is not None else
                                    self.scenarios[member].initial_poses()[i])]
        out = {"role": "leader" if isinstance(robot, Robot) else "follower", "start": start,
               "substeps": int(self.member_substeps[i, member]), "control": self._control(i, member),
               "events": self._events(i, member)}
        if isinstance(robot, Robot):
            out.update(robot.controller.describe())
            if robot.posture:
                out["posture"] = self.posture_metrics(i, member)
            else:
                metrics = self._robot_metrics(i, member)
                out["error"], out["heading_error"] = metrics["error"], metrics["heading_error"]
        else:
            out.update({"formation_law": robot.law, "gains": {"k1": robot.k1, "k2": robot.k2}, "d": robot.d,
                        "targets": dict(zip(robot.outputs, robot.targets))})
            out["formation"] = self.follower_metrics(i, member)
        return out

    def to_dict(self, member: int = 0) -> dict:
        """JSON-ready summary of one scenario of the batch."""
        scenario = self.scenarios[member]
        simulation = {"duration": float(self.t[-1]), "dt": scenario.dt, "steps": scenario.n_steps,
                      "method": scenario.method, "control_period": scenario.held_period,
                      "max_substeps": int(self.member_substeps[:, member].max()), "rk4_steps": self.rk4_steps,
                      "elapsed_s": self.elapsed_s,
                      "batch": len(self.scenarios)}
        if scenario.network is not None and not scenario.network.ideal:
            simulation["link_model"] = scenario.network.describe()   # spec fleet.md §3–5
        return {
            "scenario": scenario.name,
            "simulation": simulation,
            "reference": scenario.reference.describe() if scenario.reference is not None else None,
            "piconet": scenario.piconet,
            "order": [self.names[i] for i in scenario.order()],
            "robots": {robot.name: self.robot_summary(i, member) for i, robot in enumerate(scenario.robots)},
            "safety": self.safety(member),
        }

    # ------------------------------------------------------------------ exports
    def table(self, member: int = 0, every: int = 1):
        """Tidy per-sample rows (one per robot and sample): ``(header, rows)`` with the
        columns ``t, robot, role, x, y, theta, xi, v, omega, error_1, error_2`` (units in
        ``TABLE_COLUMNS``); ``every`` keeps one sample in that many. The errors depend on the
        role: a root's (tracking or posture) position error norm ‖p_d − p‖ in m and heading error
        wrap(θ_d − θ) in rad; a follower's output errors z_d − z (l_d − l in m and φ_d − φ in rad,
        or l1_d − l1 and l2_d − l2 in m), signed as ``output_errors``."""
        record = self._recorded()[:, ::every, :, member]
        times = self.t[::every]
        header = ["t", "robot", "role"] + [c[0] for c in TABLE_COLUMNS]
        rows = []
        for i, robot in enumerate(self.scenarios[member].robots):
            role = "follower" if isinstance(robot, Follower) else ("posture" if robot.posture else "tracking")
            values = record[[c[2] for c in TABLE_COLUMNS], :, i].T
            rows += [[t, robot.name, role, *row] for t, row in zip(times.tolist(), values.tolist())]
        return header, rows

    def write_csv(self, path, member: int = 0, every: int = 1, digits: int = 9):
        """The tidy table as CSV (``pandas.read_csv(path)`` gives one row per robot and
        sample); the header names each column with its unit, e.g. ``x_m``."""
        header, rows = self.table(member, every)
        units = {"t": "s", **{c[0]: c[1] for c in TABLE_COLUMNS}}
        header = [f"{h}_{units[h]}" if units.get(h) else h for h in header]
        with open(path, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(header)
            for row in rows:
                writer.writerow([f"{v:.{digits}g}" if isinstance(v, float) else v for v in row])
        return path

    # ------------------------------------------------------------------ display
    def __repr__(self) -> str:
        s = self.scenario
        kinds = f"{len(s.roots)} root(s), {len(s.followers)} follower(s)"
        batch = f", batch of {len(self.scenarios)}" if len(self.scenarios) > 1 else ""
        return (f"<SimulationResult {s.name!r}: {kinds}{batch}, {self.t[-1]:.6g} s in {s.n_steps} steps of "
                f"{s.dt:g} s, {'recorded' if self.record is not None else 'statistics only'}>")

    def _repr_html_(self) -> str:
        from nonholo.sim.plotting import result_html

        return result_html(self)

    def plot(self, path=None, robots=None, member: int = 0, max_robots: int = 8, snapshots: int = 6):
        """One figure: paths (with formation snapshots when there are followers), errors,
        v and ω over time. ``robots``: names or indices to show (default: the first
        ``max_robots``); ``path``: save to this file (PNG, PDF, SVG…) and close it."""
        from nonholo.sim.plotting import plot_result

        return plot_result(self, path, robots, member, max_robots, snapshots)

    def write_gif(self, path, member: int = 0, frames: int = 120, fps: int = 20, trail: float = 20.0,
                  progress: bool = False):
        """Animated GIF of the run (matplotlib PillowWriter)."""
        from nonholo.sim.plotting import animate

        return animate(self, path, member, frames, fps, trail, progress)
