"""The robot program (thesis §2.6, §5.2; spec fleet.md §2): one robot's controller at the
control instants, its subscriptions to its parents and its state published to its own
subscribers, over any ``nonholo.comm`` transport (frames addressed by robot name) through
an authenticated ``SecureChannel``.

``lockstep`` runs on logical time: at control instant k the robot waits (bounded) for each
parent's state of instant k, computes its command with the compiled law of its kind (the
kernel's own functions, ``nonholo.fleet.step``), publishes its state, and moves its plant
over the output steps up to the next instant. Every queue is bounded: a parent runs at most
``WINDOW`` instants ahead of the slowest subscriber's acknowledged progress.
"""
from __future__ import annotations

import asyncio
import time
from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np

from nonholo.comm.channel import SecureChannel
from nonholo.comm.errors import CommError
from nonholo.errors import SimulationError
from nonholo.fleet import messages as msg
from nonholo.fleet.setup import BEARING, PAIR, ROOT, RobotSetup
from nonholo.fleet.step import follower_steps, plant_steps, root_step
from nonholo.sim import kernel as kn

WINDOW = 64          # instants a parent may run ahead of a subscriber's acknowledged progress
ACK_EVERY = 16       # a follower acknowledges its progress every this many instants
DEFAULT_WAIT_S = 20.0
SUBSCRIBE_RETRY_S = 0.25
PARENT_STATES = 2 * WINDOW + 2 * ACK_EVERY


class FleetError(SimulationError):
    """A robot program could not go on (a parent silent past the bound, a link closed)."""


@dataclass
class LinkTally:
    """Per peer: frames sent, received (accepted), rejected."""

    sent: Counter = field(default_factory=Counter)
    received: Counter = field(default_factory=Counter)
    rejected: Counter = field(default_factory=Counter)


class RobotProgram:
    """One robot: ``setup`` (its part of the scenario), ``plant`` (read pose, command v, ω;
    ``advance`` for lockstep), ``transport`` (send(frame, to=name), recv()), ``channel``
    (seals with this robot's key, opens its parents' and children's frames) and
    ``limits`` the actuator limits of every robot by name (a state beyond its sender's
    limits is not believed)."""

    def __init__(self, setup: RobotSetup, plant, transport, channel: SecureChannel, limits: dict,
                 wait_s: float = DEFAULT_WAIT_S) -> None:
        self.setup, self.plant, self.transport, self.channel = setup, plant, transport, channel
        self.limits, self.wait_s = limits, wait_s
        # Per parent, the states received and not yet superseded, oldest first (bounded:
        # a parent runs at most WINDOW instants ahead of this robot's acknowledged progress).
        self.inbox: dict[str, deque] = {p: deque(maxlen=PARENT_STATES) for p in setup.parents}
        self.latest: dict[str, msg.RobotState] = {}
        self.subscribers: set[str] = set()
        self.agreed: set[str] = set()
        self.progress = {child: -1 for child in setup.children}
        self.tally = LinkTally()
        self.seq = 0
        self._changed = asyncio.Event()
        n = setup.n_steps + 1
        self.states = np.zeros((n, 4))
        self.helds = np.zeros((n, kn.HELD_COUNT))
        self.elapsed_s = 0.0
        self.k = -1          # the newest output step in ``states`` (watched by observers)
        self.clock = None    # optional: awaited with the logical time at each control instant (pacing)
        _, self._xi_after = plant_steps(setup.contract)
        self._bearing, self._pair = follower_steps(setup.contract)
        self._root = root_step(setup.law, setup.gains, setup.contract) if setup.kind == ROOT else None
        self.branch = setup.branch

    # ------------------------------------------------------------------ messages
    async def _send(self, to: str, message) -> None:
        await self.transport.send(self.channel.pack(message), to=to)
        self.tally.sent[to] += 1

    def _accept(self, peer: str, frame: bytes) -> None:
        try:
            _, message = self.channel.unpack(frame)
        except CommError:
            self.tally.rejected[peer] += 1
            return
        sender = message.sender.name
        known = sender in self.setup.parents or sender in self.setup.children
        if not known or sender != peer:
            self.tally.rejected[peer] += 1
            return
        try:
            self._dispatch(sender, message)
        except CommError:
            self.tally.rejected[peer] += 1
            return
        self.tally.received[sender] += 1
        self._changed.set()

    def _dispatch(self, sender: str, message) -> None:
        performative = message.performative
        if sender in self.setup.children and performative == "subscribe":
            self.subscribers.add(sender)
            self._replies.append((sender, msg.act("agree", self.setup.name, sender, message.conversation_id,
                                                  in_reply_to=message.reply_with)))
        elif sender in self.setup.children and performative == "inform":
            self.progress[sender] = max(self.progress[sender], msg.read_progress(message))
        elif sender in self.setup.children and performative == "cancel":
            self.subscribers.discard(sender)
        elif sender in self.setup.parents and performative == "agree":
            self.agreed.add(sender)
        elif sender in self.setup.parents and performative == "inform":
            v_max, omega_max = self.limits[sender]
            state = msg.read_state(message, v_max, omega_max)
            queue = self.inbox[sender]
            if not queue or state.k > queue[-1].k:
                queue.append(state)
        else:
            raise CommError(f"{performative} from {sender} is not part of the fleet protocol")

    async def _receive(self) -> None:
        while True:
            peer, frame = await self.transport.recv()
            self._accept(peer, frame)
            while self._replies:
                to, reply = self._replies.pop(0)
                await self._send(to, reply)

    async def _wait(self, ready, what: str, bound: float | None = None) -> bool:
        """Wait until ``ready()``; FleetError after ``wait_s`` (or False after ``bound``)."""
        deadline = time.monotonic() + (self.wait_s if bound is None else bound)
        while not ready():
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                if bound is not None:
                    return False
                raise FleetError(f"robot {self.setup.name}: no {what} within {self.wait_s:g} s")
            self._changed.clear()
            try:
                await asyncio.wait_for(self._changed.wait(), remaining)
            except asyncio.TimeoutError:
                pass
        return True

    async def _subscribe(self) -> None:
        """FIPA-Subscribe to every parent, repeated until each agrees (bounded)."""
        deadline = time.monotonic() + self.wait_s
        agreed = lambda: all(p in self.agreed for p in self.setup.parents)  # noqa: E731
        while not agreed():
            if time.monotonic() > deadline:
                raise FleetError(f"robot {self.setup.name}: no agree from {', '.join(self.setup.parents)} "
                                 f"within {self.wait_s:g} s")
            for parent in self.setup.parents:
                if parent not in self.agreed:
                    await self._send(parent, msg.act("subscribe", self.setup.name, parent,
                                                     msg.conversation(self.setup.name, parent),
                                                     reply_with=f"{self.setup.name}-subscribe"))
            await self._wait(agreed, "agree", bound=SUBSCRIBE_RETRY_S)

    # ------------------------------------------------------------------ control
    def _use_states(self, k: int) -> None:
        """Each parent's newest state of an instant ≤ k (spec fleet.md §3); older ones go."""
        for parent, queue in self.inbox.items():
            while len(queue) > 1 and queue[1].k <= k:
                queue.popleft()
            if queue and queue[0].k <= k:
                self.latest[parent] = queue[0]

    def _command(self, k: int, x: float, y: float, theta: float, xi: float):
        """(v, ω, ξ̇, singular, sat v, sat ω) at control instant k (spec fleet.md §2.3)."""
        s = self.setup
        if s.kind == ROOT:
            return self._root(s.fields, x, y, theta, xi, s.rows, k, s.v_max, s.omega_max)
        target = s.targets[k]
        k1, k2, d = s.fields[kn.K1], s.fields[kn.K2], s.fields[kn.OFFSET_D]
        p1 = self.latest[s.parents[0]]
        if s.kind == BEARING:
            v, omega, sat_v, sat_w, self.branch = self._bearing(
                x, y, theta, p1.x, p1.y, p1.theta, p1.v, p1.omega, self.branch, target[0], target[1], target[2],
                target[3], k1, k2, d, s.v_max, s.omega_max)
            return v, omega, 0.0, 0.0, sat_v, sat_w
        assert s.kind == PAIR
        p2 = self.latest[s.parents[1]]
        v, omega, singular, sat_v, sat_w = self._pair(
            x, y, theta, p1.x, p1.y, p1.theta, p1.v, p2.x, p2.y, p2.theta, p2.v, target[0], target[1], target[2],
            target[3], k1, k2, d, s.sin_floor, s.v_max, s.omega_max)
        return v, omega, 0.0, singular, sat_v, sat_w

    async def run_lockstep(self) -> None:
        """The whole run on logical time; fills ``states`` and ``helds``."""
        self._replies: list = []
        receiver = asyncio.ensure_future(self._receive())
        try:
            await self._subscribe()
            s = self.setup
            await self._wait(lambda: self.subscribers >= set(s.children), "subscription from every follower")
            started = time.perf_counter()
            xi = float(s.start[3])
            held = (0.0,) * kn.HELD_COUNT
            for k in range(s.n_steps + 1):
                x, y, theta = self.plant.pose()
                if k % s.hold_every == 0:
                    instant = k // s.hold_every
                    if self.clock is not None:
                        await self.clock(k * s.dt)
                    await self._wait(lambda: all(self.progress[c] >= instant - WINDOW for c in s.children),
                                     "progress from the followers")
                    await self._wait(lambda: all(self.inbox[p] and self.inbox[p][-1].k >= k for p in s.parents),
                                     f"state of instant {k} from {', '.join(s.parents)}")
                    self._use_states(k)
                    v, omega, xi_dot, singular, sat_v, sat_w = self._command(k, x, y, theta, xi)
                    held = (v, omega, xi_dot, singular, sat_v, sat_w)
                    self.plant.command(v, omega)
                    await self._publish(k, x, y, theta, v, omega)
                    if s.parents and instant % ACK_EVERY == 0:
                        for parent in s.parents:
                            await self._send(parent, msg.act("inform", s.name, parent, msg.conversation(s.name, parent),
                                                             msg.progress_content(instant)))
                self.states[k] = x, y, theta, xi
                self.helds[k] = held
                self.k = k
                if k == s.n_steps:
                    break
                self.plant.advance(k)
                xi = self._xi_after(xi, held[kn.HELD_XI_DOT], s.dt, int(s.plan[k]))
            self.elapsed_s = time.perf_counter() - started
            for parent in s.parents:
                await self._send(parent, msg.act("cancel", s.name, parent, msg.conversation(s.name, parent)))
        finally:
            receiver.cancel()
            await asyncio.gather(receiver, return_exceptions=True)

    async def _publish(self, k: int, x: float, y: float, theta: float, v: float, omega: float) -> None:
        if not self.setup.children:
            return
        self.seq += 1
        state = msg.RobotState(self.setup.name, k, self.seq, k * self.setup.dt, x, y, theta, v, omega)
        content = state.to_content()
        for child in sorted(self.subscribers):
            await self._send(child, msg.act("inform", self.setup.name, child,
                                            msg.conversation(child, self.setup.name), content))
