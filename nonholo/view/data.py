"""What the page shows of a finished run, from any of its sources: a ``SimulationResult``, an
MCAP recording (``nonholo.view.record``) or the ``--out`` directory of ``nonholo run``
(``result.json`` + ``trajectories.csv``).

A ``Replay`` holds, on one time grid, each robot's pose, command and its two errors (a
follower's link output errors z_d − z, l and φ or l1 and l2; a root's position error and
heading error), the reference point and the robots' roles and parents.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nonholo.errors import NonholoInputError

MAX_PAGE_FRAMES = 4000   # frames sent to a replay page (evenly decimated beyond this)
TABLE_FILE, SUMMARY_FILE = "trajectories.csv", "result.json"
CSV_COLUMNS = ("t_s", "robot", "x_m", "y_m", "theta_rad", "v_m/s", "omega_rad/s", "error_1", "error_2")
MAX_CSV_ROWS = 20_000_000


@dataclass
class Replay:
    """A run on one grid. ``robots``: per robot ``{"name", "role", "parents", "outputs"}``
    (``outputs`` the names of its two errors); ``t`` (T,); ``pose`` (T, R, 3) x, y, θ;
    ``command`` (T, R, 2) v, ω; ``errors`` (T, R, 2); ``reference`` (T, 3) x_d, y_d, θ_d or
    None; ``summary`` the run's JSON summary (or None); ``links`` per link its statistics."""

    robots: list[dict]
    t: np.ndarray
    pose: np.ndarray
    command: np.ndarray
    errors: np.ndarray
    reference: np.ndarray | None = None
    summary: dict | None = None
    links: dict | None = None

    @property
    def names(self) -> list[str]:
        return [r["name"] for r in self.robots]

    def page(self, max_frames: int = MAX_PAGE_FRAMES) -> dict:
        """The JSON the page draws: columns per robot, at most ``max_frames`` frames."""
        step = max(1, math.ceil(self.t.size / max_frames))
        keep = np.arange(0, self.t.size, step)
        if keep[-1] != self.t.size - 1:
            keep = np.append(keep, self.t.size - 1)

        def column(values):   # JSON has no NaN: a diverged sample is null (the page skips it)
            return [round(v, 6) if math.isfinite(v) else None for v in np.asarray(values, dtype=float).tolist()]

        robots = []
        for i, robot in enumerate(self.robots):
            robots.append({**robot, "x": column(self.pose[keep, i, 0]), "y": column(self.pose[keep, i, 1]),
                           "theta": column(self.pose[keep, i, 2]), "v": column(self.command[keep, i, 0]),
                           "omega": column(self.command[keep, i, 1]), "e1": column(self.errors[keep, i, 0]),
                           "e2": column(self.errors[keep, i, 1])})
        reference = None
        if self.reference is not None:
            reference = {"x": column(self.reference[keep, 0]), "y": column(self.reference[keep, 1])}
        return {"mode": "replay", "t": column(self.t[keep]), "robots": robots, "reference": reference,
                "links": self.links or {}, "title": (self.summary or {}).get("scenario", "")}


def robot_descriptors(scenario) -> list[dict]:
    """Per robot of a scenario: name, role, parents and the names of its two errors."""
    out = []
    for robot in scenario.robots:
        leaders = list(getattr(robot, "leaders", ()))
        if leaders:
            outputs = list(robot.outputs)
            out.append({"name": robot.name, "role": "follower", "parents": leaders, "outputs": outputs,
                        "law": robot.law})
        else:
            out.append({"name": robot.name, "role": "posture" if robot.posture else "tracking", "parents": [],
                        "outputs": ["position", "heading"], "law": robot.controller.name})
    return out


def from_result(result, every: int = 1, summary: dict | None = None) -> Replay:
    """The replay of a recorded ``SimulationResult`` (every ``every``-th sample)."""
    from nonholo.sim import kernel as k

    record = result.record
    if record is None:
        raise ValueError("the run was not recorded (simulate(..., record=True))")
    sel = slice(None, None, every)
    last = result.t.size - 1
    idx = np.arange(result.t.size)[sel]
    if idx[-1] != last:
        idx = np.append(idx, last)
    rec = record[:, :, :, 0][:, idx]                  # (fields, T, R)
    pose = np.stack([rec[k.REC_X], rec[k.REC_Y], rec[k.REC_THETA]], axis=-1)
    command = np.stack([rec[k.REC_V], rec[k.REC_OMEGA]], axis=-1)
    errors = np.stack([rec[k.REC_ERR1], rec[k.REC_ERR2]], axis=-1)
    reference = None
    if result.reference_rows is not None:
        from nonholo.references.feedforward import REF_COLUMNS

        cols = [REF_COLUMNS.index(c) for c in ("x_d", "y_d", "theta_d")]
        reference = result.reference_rows[idx][:, cols]
    return Replay(robot_descriptors(result.scenario), result.t[idx], pose, command, errors, reference,
                  summary if summary is not None else result.to_dict(), link_table(result.scenario))


def link_table(scenario) -> dict:
    """Per formation link ``parent->child``: its law and the follower's output names."""
    links = {}
    for robot in scenario.followers:
        for parent in robot.leaders:
            links[f"{parent}->{robot.name}"] = {"parent": parent, "child": robot.name, "law": robot.law}
    return links


def from_outdir(directory: Path) -> Replay:
    """The replay of ``nonholo run --out DIR``: ``result.json`` and ``trajectories.csv``
    (no reference path: it is not in those files)."""
    directory = Path(directory)
    summary_path, table_path = directory / SUMMARY_FILE, directory / TABLE_FILE
    for path in (summary_path, table_path):
        if not path.is_file():
            raise NonholoInputError(f"{directory}: no {path.name} (expected the --out directory of nonholo run)")
    try:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
        robots_summary = summary["robots"]
        if not isinstance(robots_summary, dict) or not robots_summary:
            raise KeyError("robots")
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        raise NonholoInputError(f"{summary_path}: not a nonholo result ({type(exc).__name__}: "
                                f"{str(exc)[:80]})") from None
    names = list(robots_summary)
    robots = []
    for name, entry in robots_summary.items():
        formation = entry.get("formation") if isinstance(entry, dict) else None
        if formation:
            outputs = [key[:-6] for key in formation if key.endswith("_error")][:2] or ["e1", "e2"]
            robots.append({"name": name, "role": "follower", "parents": list(formation.get("leaders", [])),
                           "outputs": outputs, "law": formation.get("law", "")})
        else:
            robots.append({"name": name, "role": "posture" if "posture" in entry else "tracking", "parents": [],
                           "outputs": ["position", "heading"], "law": entry.get("controller", "")})
    columns: dict[str, list] = {name: [] for name in names}
    try:
        with open(table_path, newline="", encoding="utf-8") as handle:
            reader = csv.reader(handle)
            header = next(reader)
            missing = [c for c in CSV_COLUMNS if c not in header]
            if missing:
                raise NonholoInputError(f"{table_path}: no column {missing[0]} (expected the trajectories.csv of "
                                        f"nonholo run)")
            at = [header.index(c) for c in CSV_COLUMNS]
            for line, row in enumerate(reader, start=2):
                if line > MAX_CSV_ROWS:
                    raise NonholoInputError(f"{table_path}: more than {MAX_CSV_ROWS} rows")
                try:
                    values = [row[i] for i in at]
                    series = columns[values[1]]
                    series.append([float(values[0])] + [float(v) for v in values[2:]])
                except (IndexError, KeyError, ValueError):
                    raise NonholoInputError(f"{table_path}: line {line}: expected numbers and a robot of "
                                            f"{SUMMARY_FILE}") from None
    except (OSError, UnicodeDecodeError, StopIteration, csv.Error) as exc:
        raise NonholoInputError(f"{table_path}: cannot read it ({type(exc).__name__})") from None
    lengths = {len(v) for v in columns.values()}
    if len(lengths) != 1 or 0 in lengths:
        raise NonholoInputError(f"{table_path}: every robot needs the same, non-empty list of samples")
    data = np.array([columns[name] for name in names])        # (R, T, 8)
    t = data[0, :, 0]
    if not np.all(np.diff(t) > 0) or not np.allclose(data[:, :, 0], t):
        raise NonholoInputError(f"{table_path}: sample times must increase and agree between robots")
    pose = data[:, :, 1:4].transpose(1, 0, 2)
    command = data[:, :, 4:6].transpose(1, 0, 2)
    errors = data[:, :, 6:8].transpose(1, 0, 2)
    links = {f"{p}->{r['name']}": {"parent": p, "child": r["name"], "law": r["law"]}
             for r in robots for p in r["parents"]}
    return Replay(robots, t, pose, command, errors, None, summary, links)
