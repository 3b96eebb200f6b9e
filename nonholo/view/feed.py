"""The live feed: the newest snapshot of a running fleet, latest wins.

A publisher (the fleet launcher's observer: on the fleet's event loop in process, on the
observer endpoint's thread for robot processes) replaces the snapshot;
readers (the page server's WebSocket loops, on their own thread) take the newest one when they
are ready for it. Nothing queues: a slow page skips snapshots, a fast fleet never waits. The
snapshot is serialized once per version, outside the publisher's hot path only when read.
"""
from __future__ import annotations

import json
import threading
import time

from nonholo.fleet.telemetry import program_pose, robot_status

OBSERVE_PERIOD_S = 0.05    # the launcher samples the fleet at 20 Hz (wall time)


class LatestFeed:
    """A thread-safe, single-slot, versioned store of the newest snapshot, plus the page's
    static part (``setup``: robots, links, reference path) and, once the run ends, the
    replay of the whole run (``final``)."""

    def __init__(self, setup: dict | None = None) -> None:
        self._lock = threading.Lock()
        self._setup = setup or {"mode": "live", "robots": [], "reference": None, "links": {}, "title": ""}
        self._snapshot: dict | None = None
        self._text: str | None = None
        self._final: dict | None = None
        self.version = 0
        self.published = 0

    def set_setup(self, setup: dict) -> None:
        with self._lock:
            self._setup = setup

    def publish(self, snapshot: dict) -> None:
        with self._lock:
            self._snapshot, self._text = snapshot, None
            self.version += 1
            self.published += 1

    def finish(self, final: dict | None) -> None:
        """The run is over: ``final`` (a replay page, or None) replaces the live page."""
        with self._lock:
            self._final = final
            self._snapshot = {**(self._snapshot or {}), "done": True}
            self._text = None
            self.version += 1

    def latest(self) -> tuple[int, str | None]:
        """(version, the newest snapshot as JSON text or None)."""
        with self._lock:
            if self._snapshot is not None and self._text is None:
                self._text = json.dumps(self._snapshot, separators=(",", ":"), allow_nan=False)
            return self.version, self._text

    def page(self) -> dict:
        with self._lock:
            return self._final if self._final is not None else self._setup


def live_setup(scenario, setups: dict, title: str = "") -> dict:
    """The static part of a live page: robots, links and the reference path."""
    from nonholo.view.data import link_table, robot_descriptors

    reference = None
    rows = next(iter(setups.values())).rows if setups else None
    if scenario.reference is not None and rows is not None and len(rows):
        step = max(1, len(rows) // 2000)
        reference = {"x": [round(float(v), 4) for v in rows[::step, 1]],
                     "y": [round(float(v), 4) for v in rows[::step, 2]]}
    return {"mode": "live", "robots": robot_descriptors(scenario), "reference": reference,
            "links": link_table(scenario), "title": title or scenario.name, "dt": scenario.dt}


class FleetObserver:
    """Builds ``feed`` snapshots of a running fleet from its robots' statuses
    (``nonholo.fleet.telemetry.robot_status``): per robot its newest pose and step and its
    state (starting, running, done or its watchdog's mode); per link parent→child the
    follower's output errors, the age of the newest parent state it holds, the newest latency
    (realtime), frames sent, received, rejected and in flight (sent, not yet received: in
    flight or lost; the run's report tells them apart at the end).

    In process the launcher calls it with the robot programs every ``period_s``; a fleet of
    robot processes sends each robot's status to ``status(name, status)`` (from the observer
    endpoint's thread, ``nonholo.fleet.telemetry``)."""

    period_s = OBSERVE_PERIOD_S

    def __init__(self, feed: LatestFeed) -> None:
        self.feed = feed
        self.started = time.monotonic()
        self.statuses: dict[str, dict] = {}
        self._lock = threading.Lock()

    def prepare(self, scenario, setups: dict) -> None:
        """Called by the launcher before the robots start."""
        self.feed.set_setup(live_setup(scenario, setups))
        self.started = time.monotonic()

    def __call__(self, programs) -> None:
        self.feed.publish(fleet_snapshot(programs, self.started))

    def status(self, name: str, status: dict) -> None:
        with self._lock:
            self.statuses[name] = status
            snapshot = merge_statuses(self.statuses, self.started)
        self.feed.publish(snapshot)


def fleet_snapshot(programs, started: float) -> dict:
    """A JSON-ready snapshot of robot programs in this process (``nonholo.fleet.robot.RobotProgram``):
    a follower's errors against its parents' poses at the same step."""
    by_name = {p.setup.name: p for p in programs}

    def parent_pose(parent: str, k: int):
        return program_pose(by_name[parent], k)
    return merge_statuses({p.setup.name: robot_status(p, parent_pose) for p in programs}, started)


def merge_statuses(statuses: dict, started: float) -> dict:
    """One snapshot of the robots' newest statuses (by name): a link's frames in flight are
    its parent's sent less its child's received and rejected."""
    robots, links, states = {}, {}, {}
    t = 0.0
    for name, status in statuses.items():
        x, y, theta = status["pose"]
        robots[name] = {"x": x, "y": y, "theta": theta, "v": status["v"], "omega": status["w"], "k": status["k"]}
        states[name] = status["state"]
        t = max(t, status["t"] or 0.0)
        for parent, link in status["links"].items():
            sent = statuses.get(parent, {}).get("sent", {}).get(name)
            in_flight = None if sent is None else max(0, sent - link["received"] - link["rejected"])
            links[f"{parent}->{name}"] = {**link, "sent": sent, "in_flight": in_flight}
    return {"t": round(t, 6), "wall_s": round(time.monotonic() - started, 3), "robots": robots, "links": links,
            "states": states, "done": False}
