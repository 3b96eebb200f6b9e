"""Telemetry: each robot's status, streamed to an observer (``nonholo fleet --view``,
``nonholo view SCENARIO --attach``), on the comm layers the robots' own links use.

A status is one robot's view of itself: its newest pose, v, ω and step, its state (starting,
running, done, or its watchdog's mode), per parent the link's output errors, the age of the
parent state it holds, the newest latency, frames received and rejected; per child the frames
sent. ``robot_status`` builds it from a robot program (in process the live page builds its
snapshots the same way, ``nonholo.view.feed``).

Wire: a robot started with ``--observe HOST:PORT`` keeps one authenticated stream link to the
observer (hub name ``observer``) and sends an ACL ``inform`` (ontology
``nonholo-telemetry-v1``, content JSON) through a sealed envelope every ``PERIOD_S``. Newest
wins: a status is built only once the previous one has left, so a slow observer gets fewer
statuses, never a queue; the sender is a task of its own, so the control loop never waits for
it; a link that accepts nothing for ``LIMITS.write_timeout`` is dropped and retried with
backoff. A robot's last status ("done") is sent at its end (it waits at most ``FINAL_WAIT_S``);
the observer of a fleet run reads what its robots sent before they ended (at most ``DRAIN_S``
once they have) before it stops, so that a slow observer still sees every robot done.

Keys: the link and its envelopes use, per robot, a key derived from its fleet key
(HMAC-SHA256 of ``KEY_LABEL``), so nothing a robot sends its observer can pass on a robot link,
nor the reverse. A client without the fleet's key file fails the hello: it gets the hub's
random challenge and nothing else; an endpoint without the keys never gets a status.
"""
from __future__ import annotations

import asyncio
import hashlib
import hmac
import json
import math
import random
import shutil
import tempfile
import threading
import time
from collections import Counter
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from nonholo.comm.channel import SecureChannel
from nonholo.comm.envelope import Opener, Sealer
from nonholo.comm.errors import CommError, ContentError
from nonholo.comm.message import ACLMessage, AgentID
from nonholo.comm.transports.base import TransportClosed
from nonholo.comm.transports.hello import HelloFailed, LinkAuth
from nonholo.comm.transports.stream import StreamLimits
from nonholo.comm.transports.tcp import connect_tcp, serve_tcp, tcp_port
from nonholo.fleet.keys import MAX_AGE_MS, keys_from_file, write_fleet_key_file
from nonholo.fleet.mesh import CONNECT_TIMEOUT_S, Backoff, split_address
from nonholo.sim.watchdog import FOLLOWING
from nonholo.models.formation_geometry import separation_bearing, wrap
from nonholo.sim.kernel import OFFSET_D

OBSERVER = "observer"
ONTOLOGY = "nonholo-telemetry-v1"
PERIOD_S = 0.05                # a robot's status at 20 Hz (wall time)
FINAL_WAIT_S = 1.0             # longest wait for the last status at the end of a run
DRAIN_S = 3.0                  # longest wait of an observer, once its robots have ended, for what they sent
START_TIMEOUT_S = 10.0
KEY_LABEL = b"nonholo observer link v1"
LIMITS = StreamLimits(write_timeout=2.0, send_queue_frames=4, inbox_frames_per_peer=8)
STATES = ("starting", "running", "done", "stopping")
LINK_NUMBERS = ("e1", "e2", "age_s", "latency_s")
LINK_COUNTS = ("received", "rejected")
STATUS_KEYS = {"k", "t", "pose", "v", "w", "state", "links", "sent"}
MAX_VALUE = 1.0e9


# ---------------------------------------------------------------------- the status
def number(value) -> float | None:
    """A finite value rounded for the page, or None (JSON has no NaN)."""
    return None if value is None or not math.isfinite(value) else round(float(value), 6)


def finite(value: float) -> float | None:
    """A finite value as it is, or None."""
    return float(value) if math.isfinite(value) else None


def program_pose(program, k: int) -> tuple[float, float, float]:
    """A robot program's pose at output step k (its start before the first step)."""
    if k < 0:
        return tuple(float(v) for v in program.setup.start[:3])
    x, y, theta, _ = program.states[k]
    return float(x), float(y), float(theta)


def program_step(program) -> int:
    """The newest output step a program has filled (-1 before the first): its ``k``; a
    realtime run counts its control instants."""
    k = int(getattr(program, "k", -1))
    if k < 0 and getattr(program, "realtime", False):
        if program.elapsed_s:          # the run is over
            return program.setup.n_steps
        instants = int(np.count_nonzero(program.ticks))
        k = min((instants - 1) * program.setup.hold_every, program.setup.n_steps) if instants else -1
    return k


def held_pose(program):
    """parent_pose for ``robot_status`` from the parent states a program holds."""
    def pose(parent: str, k: int):
        state = program.latest.get(parent)
        return None if state is None else (state.x, state.y, state.theta)
    return pose


def robot_state(program, k: int) -> str:
    guard = getattr(program, "guard", None)
    if guard is not None and program.setup.parents and guard.mode != FOLLOWING:
        return guard.mode
    return "done" if k >= program.setup.n_steps else ("running" if k >= 0 else "starting")


def link_errors(program, k: int, follower, parent_pose) -> tuple:
    """The follower's output errors z_d − z at step k (l, φ or l1, l2); None without parents' poses."""
    s = program.setup
    poses = [parent_pose(p, k) for p in s.parents]
    if k < 0 or not poses or any(p is None for p in poses):
        return None, None
    d = float(s.fields[OFFSET_D])
    target = s.targets[k]
    if len(poses) == 1:
        l, phi, _ = separation_bearing(poses[0], follower, d)
        return target[0] - float(l), float(wrap(target[1] - float(phi)))
    l1 = float(separation_bearing(poses[0], follower, d)[0])
    l2 = float(separation_bearing(poses[1], follower, d)[0])
    return target[0] - l1, target[1] - l2


def link_age(program, parent: str, k: int) -> float | None:
    """Age of the newest state of ``parent`` the program holds: on the wall clock since it
    arrived (realtime), in logical time (lockstep)."""
    if getattr(program, "realtime", False):
        arrived = program.arrival.get(parent)
        return None if arrived is None else program.clock() - arrived
    newest = program.latest.get(parent)
    return (k - newest.k) * program.setup.dt if newest is not None and k >= 0 else None


def robot_status(program, parent_pose=None) -> dict:
    """The JSON-ready status of a robot program (``nonholo.fleet.robot.RobotProgram``);
    ``parent_pose(parent, k)`` gives a parent's pose for the link errors (default: the
    parent states the program holds)."""
    s = program.setup
    k = program_step(program)
    x, y, theta = program_pose(program, k)
    v, w = (float(program.helds[k, 0]), float(program.helds[k, 1])) if k >= 0 else (0.0, 0.0)
    e1, e2 = link_errors(program, k, (x, y, theta), parent_pose or held_pose(program))
    latency = getattr(program, "latency", {})
    links = {p: {"e1": number(e1), "e2": number(e2), "age_s": number(link_age(program, p, k)),
                 "latency_s": number(latency[p][-1] if latency.get(p) else None),
                 "received": program.tally.received[p], "rejected": program.tally.rejected[p]}
             for p in s.parents}
    return {"k": k, "t": number(max(k, 0) * s.dt), "pose": [finite(x), finite(y), finite(theta)],
            "v": finite(v), "w": finite(w), "state": robot_state(program, k), "links": links,
            "sent": {c: program.tally.sent[c] for c in s.children}}


def status_message(name: str, status: dict) -> ACLMessage:
    return ACLMessage("inform", sender=AgentID(name), receivers=(AgentID(OBSERVER),), language="json",
                      ontology=ONTOLOGY, content=json.dumps(status, separators=(",", ":"), allow_nan=False))


def _optional(value, what: str):
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not abs(value) <= MAX_VALUE:
        raise ContentError(f"{what} must be a finite number or null")
    return float(value)


def _counts(value, names, what: str) -> dict:
    if not isinstance(value, dict) or not set(value) <= names:
        raise ContentError(f"{what} must be an object keyed by robots of the fleet")
    if any(type(n) is not int or not 0 <= n < 2**53 for n in value.values()):
        raise ContentError(f"{what} must hold counts")
    return dict(value)


def _link(value, parent: str) -> dict:
    if not isinstance(value, dict) or set(value) != {*LINK_NUMBERS, *LINK_COUNTS}:
        raise ContentError(f"links.{parent} must hold {', '.join(LINK_NUMBERS + LINK_COUNTS)}")
    link = {key: _optional(value[key], f"links.{parent}.{key}") for key in LINK_NUMBERS}
    return {**link, **_counts({key: value[key] for key in LINK_COUNTS}, set(LINK_COUNTS), f"links.{parent}")}


def read_status(message: ACLMessage, names: frozenset) -> dict:
    """A status from an opened message, checked field by field (ContentError otherwise)."""
    if message.performative != "inform" or message.ontology != ONTOLOGY:
        raise ContentError(f"expected an inform of {ONTOLOGY}")
    try:
        data = json.loads(message.content or "", parse_constant=lambda name: None)
    except (ValueError, RecursionError):
        raise ContentError("content is not valid JSON") from None
    if not isinstance(data, dict) or set(data) != STATUS_KEYS:
        raise ContentError(f"a status has exactly the keys {sorted(STATUS_KEYS)}")
    pose, k, links = data["pose"], data["k"], data["links"]
    if not isinstance(pose, list) or len(pose) != 3 or type(k) is not int or not -1 <= k < 2**53:
        raise ContentError("pose must be [x, y, theta] and k a step")
    if data["state"] not in STATES or not isinstance(links, dict) or not set(links) <= names:
        raise ContentError("state or links out of range")
    return {"k": k, "t": _optional(data["t"], "t"), "pose": [_optional(v, "pose") for v in pose],
            "v": _optional(data["v"], "v"), "w": _optional(data["w"], "w"), "state": data["state"],
            "links": {p: _link(value, p) for p, value in links.items()},
            "sent": _counts(data["sent"], names, "sent")}


# ---------------------------------------------------------------------- keys
def observer_secret(secret: bytes) -> bytes:
    """A robot's observer-link key, derived from its fleet key."""
    return hmac.digest(secret, KEY_LABEL, hashlib.sha256)


def observer_keys(keys: dict) -> dict:
    """{name: (sender id, key id, derived secret)} from a fleet's keys."""
    return {name: (sid, kid, observer_secret(secret)) for name, (sid, kid, secret) in keys.items()}


# ---------------------------------------------------------------------- robot side
async def _drain(client) -> None:
    """Read and ignore what the observer sends (keepalives); ends when the link closes."""
    try:
        while True:
            await client.recv()
    except (TransportClosed, CommError):
        return


class TelemetrySender:
    """Streams ``program``'s status to the observer at ``address`` (host, port), sealed
    with ``key`` (sender id, key id, fleet secret), while it runs; ``close()`` sends a
    last status (bounded) and stops."""

    def __init__(self, program, address: tuple[str, int], key: tuple[int, int, bytes],
                 period_s: float = PERIOD_S) -> None:
        sender_id, key_id, secret = observer_keys({"self": key})["self"]
        self.program, self.address, self.period_s = program, address, period_s
        self.auth = LinkAuth({key_id: secret}, key_id=key_id)
        self.channel = SecureChannel(Sealer(secret, key_id=key_id, sender_id=sender_id))
        self._stop = asyncio.Event()
        self._task: asyncio.Task | None = None

    def start(self) -> "TelemetrySender":
        self._task = asyncio.ensure_future(self._run())
        return self

    def frame(self) -> bytes:
        return self.channel.pack(status_message(self.program.setup.name, robot_status(self.program)))

    async def _run(self) -> None:
        backoff, rng = Backoff(), random.Random()
        while True:
            client = await self._connect()
            if client is not None:
                backoff.reset()
                try:
                    if await self._stream(client):
                        return
                except TransportClosed:
                    pass
                finally:
                    await client.close()
            if self._stop.is_set():   # one attempt after the stop: the last status ("done") if it can go
                return
            # the backoff ends early at the stop, so that the last status is tried at once
            stopped = asyncio.ensure_future(self._stop.wait())
            await asyncio.wait([stopped], timeout=backoff.next(rng))
            stopped.cancel()

    async def _connect(self):
        try:
            client = await connect_tcp(self.program.setup.name, *self.address, auth=self.auth,
                                       timeout=CONNECT_TIMEOUT_S, limits=LIMITS)
        except (OSError, HelloFailed, asyncio.TimeoutError):
            return None
        if client.peer != OBSERVER:
            await client.close()
            return None
        return client

    async def _stream(self, client) -> bool:
        """Send statuses until the link closes (False) or the last one has gone (True)."""
        drain = asyncio.ensure_future(_drain(client))
        try:
            while not drain.done():
                await client.send(self.frame())     # waits only while the socket is full
                if self._stop.is_set():
                    return True
                stopped = asyncio.ensure_future(self._stop.wait())
                await asyncio.wait([drain, stopped], timeout=self.period_s, return_when=asyncio.FIRST_COMPLETED)
                stopped.cancel()
            return False
        finally:
            drain.cancel()
            await asyncio.gather(drain, return_exceptions=True)

    async def close(self) -> None:
        if self._task is None:
            return
        self._stop.set()
        try:
            await asyncio.wait_for(asyncio.shield(self._task), FINAL_WAIT_S)
        except asyncio.TimeoutError:
            pass
        self._task.cancel()
        await asyncio.gather(self._task, return_exceptions=True)


def paced_clock(speed: float):
    """An awaitable clock: returns once wall time since its first call reaches t / speed."""
    start = []

    async def clock(t: float) -> None:
        if not start:
            start.append(time.monotonic())
        delay = start[0] + t / speed - time.monotonic()
        if delay > 0:
            await asyncio.sleep(delay)
    return clock


def watch_robot(program, observe: str | None, speed: float | None, key) -> TelemetrySender | None:
    """A robot process's hooks: pace its lockstep run at ``speed`` and, with ``observe``
    ("host:port"), stream its status there; the sender to close at the end, or None."""
    if speed:
        program.pace = paced_clock(speed)
    if observe is None:
        return None
    return TelemetrySender(program, split_address(observe, "--observe"), key).start()


# ---------------------------------------------------------------------- observer side
class ObserverHub:
    """The observer endpoint: accepts the robots of a fleet (``keys`` {name: (sender id,
    key id, fleet secret)}), each only under its own name and key, and hands every valid
    status to ``on_status(name, status)``; anything else is counted in ``rejected``."""

    def __init__(self, keys: dict, on_status) -> None:
        derived = observer_keys(keys)
        self.names = frozenset(keys)
        self.on_status = on_status
        self.auth = LinkAuth({kid: secret for _, kid, secret in derived.values()},
                             peer_key_ids={name: kid for name, (_, kid, _) in derived.items()})
        opener = Opener({kid: secret for _, kid, secret in derived.values()},
                        key_senders={kid: frozenset({sid}) for sid, kid, _ in derived.values()},
                        max_age_ms=MAX_AGE_MS)
        self.channel = SecureChannel(None, opener, senders={sid: name for name, (sid, _, _) in derived.items()})
        self.received: Counter = Counter()
        self.rejected = 0
        self.hub = None
        self._task: asyncio.Task | None = None

    async def start(self, host: str, port: int) -> int:
        self.hub = await serve_tcp(OBSERVER, host, port, auth=self.auth, limits=LIMITS)
        self._task = asyncio.ensure_future(self._pump())
        return tcp_port(self.hub)

    async def _pump(self) -> None:
        try:
            while True:
                self.accept(*await self.hub.recv())
        except TransportClosed:
            return

    def accept(self, peer: str, frame: bytes) -> None:
        try:
            _, message = self.channel.unpack(frame)
            if message.sender.name != peer:
                raise ContentError("a status must come over its robot's own link")
            status = read_status(message, self.names)
        except CommError:
            self.rejected += 1
            return
        self.received[peer] += 1
        self.on_status(peer, status)

    async def drain(self, timeout: float) -> bool:
        """Wait, at most ``timeout`` s, until every robot's link has closed and each status it
        sent has reached ``on_status``; True when all has. (A robot that has ended has closed
        its link; its statuses still in flight are read before the end of its stream.)"""
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout
        while self.hub.peers or not self.hub.inbox.empty():
            if loop.time() >= end:
                return False
            await asyncio.sleep(0.01)
        return True

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)
        if self.hub is not None:
            await self.hub.close()


class ObserverThread:
    """An ``ObserverHub`` on ``host:port`` (0: chosen by the OS), on a thread and event loop
    of its own, so that it never waits for its caller nor the caller for it."""

    def __init__(self, keys: dict, on_status, host: str = "127.0.0.1", port: int = 0) -> None:
        self.hub = ObserverHub(keys, on_status)
        self.host, self.port = host, port
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping: asyncio.Event | None = None
        self._drain_s = 0.0
        self._started = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._serve, name="nonholo-observer", daemon=True)

    @property
    def address(self) -> str:
        return f"[{self.host}]:{self.port}" if ":" in self.host else f"{self.host}:{self.port}"

    def start(self) -> "ObserverThread":
        """Bind and serve; OSError (one line) when it cannot."""
        self._thread.start()
        if not self._started.wait(START_TIMEOUT_S) or self._error is not None:
            self.stop()
            error = self._error
            raise OSError(f"cannot observe on {self.address}: "
                          f"{getattr(error, 'strerror', None) or error or 'timeout'}")
        return self

    def _serve(self) -> None:
        loop = self._loop = asyncio.new_event_loop()
        try:
            loop.run_until_complete(self._main())
        except BaseException as exc:   # reported to start(); the thread must end quietly
            self._error = exc
            self._started.set()
        finally:
            loop.close()

    async def _main(self) -> None:
        self._stopping = asyncio.Event()
        self.port = await self.hub.start(self.host, self.port)
        self._started.set()
        try:
            await self._stopping.wait()
            if self._drain_s > 0:
                await self.hub.drain(self._drain_s)
        finally:
            await self.hub.close()

    def stop(self, drain_s: float = 0.0) -> None:
        """Stop serving. ``drain_s`` > 0: first wait (at most that long) for the statuses
        that robots which have ended sent before their end (see ``ObserverHub.drain``)."""
        self._drain_s = max(0.0, float(drain_s))
        loop, stopping = self._loop, self._stopping
        if loop is not None and stopping is not None and self._thread.is_alive():
            try:
                loop.call_soon_threadsafe(stopping.set)
            except RuntimeError:   # the loop has just closed
                return
        if self._thread.is_alive():
            self._thread.join(START_TIMEOUT_S + self._drain_s)


@contextmanager
def watched_processes(observer, names, keys: Path | None, observe: str | None, speed: float | None):
    """For a fleet of robot processes: yields (key file, options for every robot). With an
    ``observer`` (its ``status(name, status)`` takes each robot's status) an observer
    endpoint on 127.0.0.1 (OS-chosen port) is served while the block runs, with a fresh
    key file in a private directory unless ``keys``; ``observe``: the robots send to that
    address instead; ``speed``: the robots pace their lockstep run at it."""
    options = ["--speed", repr(float(speed))] if speed else []
    if observer is None:
        yield keys, options + (["--observe", observe] if observe else [])
        return
    private = None
    try:
        if keys is None:
            private = Path(tempfile.mkdtemp(prefix="nonholo-observer-"))
            keys = private / "fleet.keys"
            write_fleet_key_file(keys, names)
        endpoint = ObserverThread(keys_from_file(keys, names, names), observer.status).start()
        try:
            yield keys, options + ["--observe", endpoint.address]
        except BaseException:
            endpoint.stop()
            raise
        # the robots have ended: their last statuses ("done") still in flight reach the observer
        endpoint.stop(drain_s=DRAIN_S)
    finally:
        if private is not None:
            shutil.rmtree(private, ignore_errors=True)
