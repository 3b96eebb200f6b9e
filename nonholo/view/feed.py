"""The live feed: the newest snapshot of a running fleet, latest wins.

A publisher (the fleet launcher's observer, on the fleet's event loop) replaces the snapshot;
readers (the page server's WebSocket loops, on their own thread) take the newest one when they
are ready for it. Nothing queues: a slow page skips snapshots, a fast fleet never waits. The
snapshot is serialized once per version, outside the publisher's hot path only when read.
"""
from __future__ import annotations

import json
import math
import threading
import time

from nonholo.models.formation_geometry import separation_bearing, wrap
from nonholo.sim.kernel import OFFSET_D

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


def _newest(samples):
    """The newest of a program's latency samples (realtime runs measure them), or None."""
    return samples[-1] if samples else None


def _number(value) -> float | None:
    return None if value is None or not math.isfinite(value) else round(float(value), 6)


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
    """Samples a running fleet (its robot programs) into ``feed`` snapshots: per robot its
    newest pose and step; per link parent→child the follower's output errors, the age of the
    newest parent state it holds (logical time), frames sent, received, rejected and in flight
    (sent, not yet received: in flight or lost; the run's report tells them apart at the end),
    the latency when the program measures one (``latency_s`` per parent); per robot its
    state (``watchdog`` when the program has one, else running/done)."""

    period_s = OBSERVE_PERIOD_S

    def __init__(self, feed: LatestFeed) -> None:
        self.feed = feed
        self.started = time.monotonic()

    def prepare(self, scenario, setups: dict) -> None:
        """Called by the launcher before the robots start."""
        self.feed.set_setup(live_setup(scenario, setups))
        self.started = time.monotonic()

    def __call__(self, programs) -> None:
        self.feed.publish(fleet_snapshot(programs, self.started))


def _pose(program, k: int):
    if k < 0:
        return tuple(float(v) for v in program.setup.start[:3])
    x, y, theta, _ = program.states[k]
    return float(x), float(y), float(theta)


def fleet_snapshot(programs, started: float) -> dict:
    """A JSON-ready snapshot of robot programs (``nonholo.fleet.robot.RobotProgram``)."""
    by_name = {p.setup.name: p for p in programs}
    robots, links, states = {}, {}, {}
    t = 0.0
    for program in programs:
        s = program.setup
        k = int(getattr(program, "k", -1))
        x, y, theta = _pose(program, k)
        v, omega = (float(program.helds[k, 0]), float(program.helds[k, 1])) if k >= 0 else (0.0, 0.0)
        robots[s.name] = {"x": x, "y": y, "theta": theta, "v": v, "omega": omega, "k": k}
        t = max(t, k * s.dt)
        guard = getattr(program, "guard", None)   # the watchdog's state (nonholo.sim.watchdog)
        stopping = guard is not None and s.parents and guard.mode != "following"
        states[s.name] = "stopping" if stopping else ("done" if k >= s.n_steps else ("running" if k >= 0 else "starting"))
        if not s.parents:
            continue
        errors = (None, None)
        if k >= 0:
            d = float(s.fields[OFFSET_D])
            follower = (x, y, theta)
            parents = [by_name[p] for p in s.parents]
            target = s.targets[k]
            if len(parents) == 1:
                l, phi, _ = separation_bearing(_pose(parents[0], k), follower, d)
                errors = (float(l) - target[0], float(wrap(float(phi) - target[1])))
            else:
                l1 = float(separation_bearing(_pose(parents[0], k), follower, d)[0])
                l2 = float(separation_bearing(_pose(parents[1], k), follower, d)[0])
                errors = (l1 - target[0], l2 - target[1])
        for parent in s.parents:
            sender = by_name[parent]
            newest = program.latest.get(parent)
            received = program.tally.received[parent]
            sent = sender.tally.sent[s.name]
            links[f"{parent}->{s.name}"] = {
                "e1": _number(errors[0]), "e2": _number(errors[1]),
                "age_s": _number((k - newest.k) * s.dt) if newest is not None and k >= 0 else None,
                "latency_s": _number(_newest(getattr(program, "latency", {}).get(parent))),
                "sent": sent, "received": received, "rejected": program.tally.rejected[parent],
                "in_flight": max(0, sent - received - program.tally.rejected[parent])}
    return {"t": round(t, 6), "wall_s": round(time.monotonic() - started, 3), "robots": robots, "links": links,
            "states": states, "done": False}
