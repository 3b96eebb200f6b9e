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
from dataclasses import dataclass, field, replace

import numpy as np

from nonholo.comm.channel import SecureChannel
from nonholo.comm.errors import CommError
from nonholo.errors import SimulationError
from nonholo.fleet import messages as msg
from nonholo.sim.links import IDEAL, link_draws, link_schedule
from nonholo.fleet.setup import BEARING, PAIR, ROOT, RobotSetup
from nonholo.fleet.step import follower_steps, plant_steps, root_step
from nonholo.models.unicycle import unicycle_arc
from nonholo.sim.watchdog import FOLLOWING, WatchdogConfig, WatchdogState, watchdog_step
from nonholo.sim import kernel as kn

WINDOW = 64          # instants a parent may run ahead of a subscriber's acknowledged progress
ACK_EVERY = 16       # a follower acknowledges its progress every this many instants
DEFAULT_WAIT_S = 20.0
SUBSCRIBE_RETRY_S = 0.25
PARENT_STATES = 2 * WINDOW + 2 * ACK_EVERY
HEARTBEAT_EVERY = 5       # realtime: a follower's progress inform (its heartbeat) every this many instants
SUBSCRIBER_LOST_S = 0.5   # realtime: a follower silent this long is reported lost
LATENCY_SAMPLES = 100_000
END_WAIT_S = 1.0          # realtime: longest wait for the followers' cancel at the end


class FleetError(SimulationError):
    """A robot program could not go on (a parent silent past the bound, a link closed)."""


@dataclass
class LinkTally:
    """Per peer: frames sent, received (accepted), rejected."""

    sent: Counter = field(default_factory=Counter)
    received: Counter = field(default_factory=Counter)
    rejected: Counter = field(default_factory=Counter)
    lost: Counter = field(default_factory=Counter)      # states the link model dropped at the send
    states_sent: Counter = field(default_factory=Counter)
    states_received: Counter = field(default_factory=Counter)


@dataclass(frozen=True)
class LinkPlan:
    """The link model of one run as a robot needs it: ``model(parent, child)`` and ``seed``."""

    model: object = lambda parent, child: IDEAL
    seed: int = 0


@dataclass(frozen=True)
class Failover:
    """Leader failover (realtime): when the root ``order[0]`` has been silent ``after_s``,
    ``order[1]`` tracks the reference with the root's law from where it stands and the
    root's other followers follow it instead. ``setups``: every robot's setup by name;
    ``relink(name)``: have the transport connect to robot ``name`` (None: already linked)."""

    order: tuple[str, ...]
    setups: dict
    after_s: float = 0.3
    relink: object = None


def quantiles(values) -> dict:
    """p50, p99 and max of ``values`` (None when empty)."""
    values = np.asarray(values, dtype=float)
    if not values.size:
        return {"p50": None, "p99": None, "max": None}
    return {"p50": float(np.percentile(values, 50)), "p99": float(np.percentile(values, 99)),
            "max": float(values.max())}


def predicted(state: msg.RobotState, age: float) -> msg.RobotState:
    """A parent's ``state`` with its pose advanced along the exact arc of its command over
    ``age`` s (spec fleet.md §3, ``[network] predict``)."""
    x, y, theta = unicycle_arc(state.x, state.y, state.theta, state.v, state.omega, age)
    return replace(state, x=x, y=y, theta=theta)


class RobotProgram:
    """One robot: ``setup`` (its part of the scenario), ``plant`` (read pose, command v, ω;
    ``advance`` for lockstep), ``transport`` (send(frame, to=name), recv()), ``channel``
    (seals with this robot's key, opens its parents' and children's frames) and
    ``limits`` the actuator limits of every robot by name (a state beyond its sender's
    limits is not believed)."""

    def __init__(self, setup: RobotSetup, plant, transport, channel: SecureChannel, limits: dict,
                 wait_s: float = DEFAULT_WAIT_S, links: LinkPlan | None = None,
                 watchdog: WatchdogConfig | None = None, failover: Failover | None = None) -> None:
        self.failover = failover
        self.setup, self.plant, self.transport, self.channel = setup, plant, transport, channel
        self.limits, self.wait_s = limits, wait_s
        self.watchdog = watchdog or WatchdogConfig()
        instants = len(setup.control_steps)
        period = setup.dt * setup.hold_every
        links = links or LinkPlan()
        # The link model, drawn by both ends alike: per child, the delay of each of this
        # robot's states (realtime: it leaves after it, in order unless reorder) and whether
        # the child never gets it; per parent the newest usable message at each instant.
        draws = {c: link_draws(links.model(setup.name, c), links.seed, setup.name, c, instants)
                 for c in setup.children}
        self.delays = {c: delays for c, (delays, _) in draws.items()}
        self.drops = {c: lost for c, (_, lost) in draws.items()}
        self.schedule = {p: link_schedule(links.model(p, setup.name), links.seed, p, setup.name, instants, period)
                         for p in setup.parents}
        self.reorder = {c: links.model(setup.name, c).reorder for c in setup.children}
        self._due: dict[str, float] = {}
        self._delayed: set[asyncio.Task] = set()
        self.ages = {p: np.full(instants, np.nan) for p in setup.parents}
        self.events: list[dict] = []
        self.on_event = None          # on_event(robot name, event dict), e.g. to log it
        self.ticks = np.zeros(instants)
        self.clock = time.monotonic
        self.realtime = False
        self.parent_epoch: dict[str, int] = {}
        self.arrival: dict[str, float] = {}          # realtime: when the newest state of a parent came
        self.latency = {p: deque(maxlen=LATENCY_SAMPLES) for p in setup.parents}
        self.heard: dict[str, float] = {}            # realtime: when a follower was last heard
        self.start_clock = 0.0
        # Per parent, the states received and not yet superseded, oldest first (bounded:
        # a parent runs at most WINDOW instants ahead of this robot's acknowledged progress).
        self.inbox: dict[str, deque] = {p: deque(maxlen=PARENT_STATES) for p in setup.parents}
        self.latest: dict[str, msg.RobotState] = {}
        self.predict = False   # lockstep: parents' messages advanced over their age (run_lockstep)
        self.stopped_periods = 0.0   # control periods (within the run) spent stopping or stopped
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
        self.guard = WatchdogState()   # the watchdog's state at the last control instant
        self.pace = None     # optional: awaited with the logical time at each control instant (a viewer's pacing)
        _, self._xi_after = plant_steps(setup.contract)
        self._bearing, self._pair = follower_steps(setup.contract)
        self._root = root_step(setup.law, setup.gains, setup.contract) if setup.kind == ROOT else None
        self.branch = setup.branch

    # ------------------------------------------------------------------ messages
    async def _send(self, to: str, message) -> None:
        await self._send_frame(to, self.channel.pack(message))

    async def _send_frame(self, to: str, frame: bytes) -> None:
        await self.transport.send(frame, to=to)
        self.tally.sent[to] += 1

    def _accept(self, peer: str, frame: bytes, arrived: float | None = None) -> None:
        """Open a frame from ``peer`` and act on it; ``arrived``: when the transport read it
        (``self.clock``'s time; default now)."""
        arrived = self.clock() if arrived is None else arrived
        try:
            opened, message = self.channel.unpack(frame)
        except CommError:
            self.tally.rejected[peer] += 1
            return
        sender = message.sender.name
        known = sender in self.setup.parents or sender in self.setup.children
        # a frame sealed for another robot (a sibling's state replayed here) is not ours
        addressed = any(receiver.name == self.setup.name for receiver in message.receivers or ())
        if not known or sender != peer or not addressed:
            self.tally.rejected[peer] += 1
            return
        try:
            self._dispatch(sender, message, opened.epoch, arrived)
        except CommError:
            self.tally.rejected[peer] += 1
            return
        self.tally.received[sender] += 1
        self._changed.set()

    def _dispatch(self, sender: str, message, epoch: int, arrived: float) -> None:
        performative = message.performative
        if sender in self.setup.children:
            self.heard[sender] = arrived
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
            if self.parent_epoch.setdefault(sender, epoch) != epoch:
                # A new boot of the parent (the envelope's epoch; a replayed old epoch is
                # rejected by the channel): its states restart, those of the old boot go.
                self.parent_epoch[sender] = epoch
                queue.clear()
                self.latest.pop(sender, None)
                self._event({"t": self._run_time(), "event": "parent-restarted", "robot": sender})
            self.tally.states_received[sender] += 1
            if not queue or state.k > queue[-1].k:
                queue.append(state)
                if self.realtime:   # one-way latency: the send stamp to the frame's arrival
                    self.arrival[sender] = arrived
                    self.latency[sender].append(arrived - state.t)
        else:
            raise CommError(f"{performative} from {sender} is not part of the fleet protocol")

    async def _receive(self) -> None:
        while True:
            peer, frame, arrived = await self.transport.recv_stamped()
            self._accept(peer, frame, arrived)
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

    def warm_up(self) -> None:
        """Compile (or load from the cache) every compiled step the control loop calls, with
        the robot's start and stand-in parent states, and forget the results: on a cold
        cache a realtime loop's first instants would otherwise run seconds late."""
        s = self.setup
        x, y, theta, xi = (float(value) for value in s.start[:4])
        latest, branch = dict(self.latest), self.branch
        try:
            for parent in s.parents:
                self.latest[parent] = msg.RobotState(parent, 0, 0, 0.0, x - 1.0, y - 1.0, theta, 0.0, 0.0)
            self._command(0, x, y, theta, xi)
            unicycle_arc(x, y, theta, 0.0, 0.0, 0.0)
            watchdog_step(self.watchdog, WatchdogState(), 0.0, True, 0.0, 0.0, s.dt * s.hold_every)
        finally:
            self.latest, self.branch = latest, branch

    def _guarded(self, guard: WatchdogState, age: float, new: bool, command: tuple, period: float, k: int, t: float,
                 at: float | None = None) -> tuple[WatchdogState, tuple]:
        """The watchdog's step at the control instant of output step ``k`` (spec fleet.md
        §5): its next state and the command to hold, the law's ``command`` or, while
        stopping, the ramp to zero. A stop or resume is recorded at run time ``t`` (and
        monotonic time ``at``, realtime)."""
        guard, v, omega, event = watchdog_step(self.watchdog, guard, age, new, command[0], command[1], period)
        self.guard = guard   # explicit data, for observers
        if guard.mode != FOLLOWING:   # the part of the instant's period in the run (0 at its end)
            every = self.setup.hold_every
            self.stopped_periods += (min(k + every, self.setup.n_steps) - k) / every
        if event is not None:
            stamp = {} if at is None else {"at": at}
            self._event({"t": t, "event": event, "age": age if age != float("inf") else None, **stamp})
        if guard.mode != FOLLOWING:
            command = (v, omega, 0.0, 0.0, 0.0, 0.0)
        return guard, command

    def _take_states(self, instant: int) -> tuple[float, bool]:
        """Each parent's message of the instant its link schedule names usable at
        ``instant`` (spec fleet.md §3); older ones go. Returns (age in s of the oldest in use,
        ``math.inf`` when a parent has none; whether any is newer than at the last instant)."""
        s = self.setup
        period = s.dt * s.hold_every
        age, new = 0.0, False
        for parent, queue in self.inbox.items():
            j = int(self.schedule[parent][instant])
            if j < 0:
                age = float("inf")
                continue
            step = j * s.hold_every
            while len(queue) > 1 and queue[1].k <= step:
                queue.popleft()
            if queue and queue[0].k <= step:
                previous = self.latest.get(parent)
                self.latest[parent] = queue[0]
                new = new or previous is None or queue[0].k > previous.k
            else:
                age = float("inf")
                continue
            used = (instant - self.latest[parent].k // s.hold_every) * period
            self.ages[parent][instant] = used
            age = max(age, used)
            if self.predict:
                self.latest[parent] = predicted(self.latest[parent], used)
        return age, new

    def _ready(self, instant: int) -> bool:
        """Every parent's scheduled message of ``instant`` has arrived (frames of a link
        arrive in order, so a later one means it has; a lost one is never scheduled)."""
        for parent in self.setup.parents:
            j = self.schedule[parent][instant]
            queue = self.inbox[parent]
            if j >= 0 and not (queue and queue[-1].k >= j * self.setup.hold_every):
                return False
        return True

    async def run_lockstep(self, predict: bool = False) -> None:
        """The whole run on logical time; fills ``states`` and ``helds``. With ``predict`` a
        parent's message is used advanced along its command's arc over its age, as the
        centralized simulator does (``nonholo.sim.linkstep``)."""
        self.predict = predict
        self._replies: list = []
        receiver = asyncio.ensure_future(self._receive())
        try:
            s = self.setup
            await self._wait(lambda: self.subscribers >= set(s.children), "subscription from every follower")
            await self._subscribe()
            started = time.perf_counter()
            xi = float(s.start[3])
            held = (0.0,) * kn.HELD_COUNT
            guard = WatchdogState()
            period = s.dt * s.hold_every
            for k in range(s.n_steps + 1):
                x, y, theta = self.plant.pose()
                if k % s.hold_every == 0:
                    instant = k // s.hold_every
                    self.ticks[instant] = time.perf_counter()
                    if self.pace is not None:   # a viewer's pacing (nonholo.view)
                        await self.pace(k * s.dt)
                    if not all(self.progress[c] >= instant - WINDOW for c in s.children):
                        await self._wait(lambda: all(self.progress[c] >= instant - WINDOW for c in s.children),
                                         "progress from the followers")
                    if not self._ready(instant):
                        await self._wait(lambda: self._ready(instant),
                                         f"state of instant {k} from {', '.join(s.parents)}")
                    age, new = self._take_states(instant)
                    if len(self.latest) == len(s.parents):
                        command = self._command(k, x, y, theta, xi)
                    else:
                        command = (0.0,) * kn.HELD_COUNT
                    if s.parents:
                        guard, command = self._guarded(guard, age, new, command, period, k, instant * period)
                    held = command
                    v, omega = held[0], held[1]
                    self.plant.command(v, omega)
                    await self._publish(k, instant, x, y, theta, v, omega)
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
            # Every follower has had every state once it cancels: only then may this robot
            # close its links (bounded: a follower that is gone does not hold it).
            await self._wait(lambda: not self.subscribers, "cancel from every follower", bound=self.wait_s)
        finally:
            receiver.cancel()
            await asyncio.gather(receiver, return_exceptions=True)

    def _take_over(self, lost: str, now: float) -> None:
        """Leader ``lost`` is gone (spec: failover): the successor becomes the root with its
        law and reference; the other followers of ``lost`` follow the successor."""
        f, s = self.failover, self.setup
        successor = f.order[f.order.index(lost) + 1]
        root = f.setups[lost]
        self.inbox.pop(lost, None)
        self.latest.pop(lost, None)
        if s.name == successor:
            others = tuple(c for c in root.children if c != s.name)
            self.setup = replace(s, kind=ROOT, parents=(), children=s.children + others, law=root.law,
                                 gains=root.gains, fields=root.fields.copy(), contract=root.contract, rows=root.rows)
            self._root = root_step(root.law, root.gains, root.contract)
            for child in others:
                self.progress[child] = -1
                self.heard[child] = now
                self.drops[child] = np.zeros(len(self.ticks), dtype=bool)   # ideal links
                self.delays[child] = np.zeros(len(self.ticks))
                self.reorder[child] = False
            self._event({"t": now - self.start_clock, "event": "took-over", "robot": lost, "at": now})
        else:
            self.setup = replace(s, parents=(successor,))
            self.inbox[successor] = deque(maxlen=PARENT_STATES)
            self.ages[successor] = np.full(len(self.ticks), np.nan)
            self.latency[successor] = deque(maxlen=LATENCY_SAMPLES)
            if f.relink is not None:
                f.relink(successor)
            self._event({"t": now - self.start_clock, "event": "new-parent", "robot": successor, "at": now})

    def _event(self, event: dict) -> None:
        """Record a watchdog or link event (and tell ``on_event``, if set, at once)."""
        self.events.append(event)
        if self.on_event is not None:
            self.on_event(self.setup.name, event)

    def _run_time(self) -> float:
        return self.clock() - self.start_clock if self.start_clock else 0.0

    async def run_realtime(self, predict: bool = False, end_wait_s: float = END_WAIT_S, on_start=None) -> None:
        """The run on the wall clock (spec fleet.md §5): output samples every dt, control
        every control period; the plant moves by itself between commands; a follower uses
        its parents' newest states (zero-order hold, or with ``predict`` extrapolated along
        the exact arc over their age) under the watchdog, and resubscribes to a silent parent."""

        self.realtime = True
        self._replies = []
        self.warm_up()   # before it subscribes: its parents start their clocks only after that
        receiver = asyncio.ensure_future(self._receive())
        s = self.setup
        try:
            await self._wait(lambda: self.subscribers >= set(s.children), "subscription from every follower")
            await self._subscribe()
            if s.parents:
                await self._wait(lambda: all(self.inbox[p] for p in s.parents), "first state from the parents")
            clock = self.clock
            period = s.dt * s.hold_every
            start = self.start_clock = clock()
            if on_start is not None:
                on_start(start)
            started = time.perf_counter()
            xi = float(s.start[3])
            held = (0.0,) * kn.HELD_COUNT
            guard = WatchdogState()
            last_control = start
            last_subscribe = start
            seen = {p: -1 for p in s.parents}
            for child in s.children:
                self.heard[child] = start
            for k in range(s.n_steps + 1):
                delay = start + k * s.dt - clock()
                if delay > 0:
                    await asyncio.sleep(delay)
                else:
                    await asyncio.sleep(0)      # let frames in even when late
                now = clock()
                x, y, theta = self.plant.pose()
                if k % s.hold_every == 0:
                    instant = k // s.hold_every
                    self.ticks[instant] = now
                    lost = self.failover.order[0] if self.failover else None
                    if lost in s.parents and now - self.arrival.get(lost, start) > self.failover.after_s:
                        self._take_over(lost, now)
                        s = self.setup
                        seen.update({p: -1 for p in s.parents})
                        if s.kind == ROOT:
                            xi = held[0]      # the dynamic-feedback law's ξ is the speed it holds
                    xi += held[kn.HELD_XI_DOT] * (now - last_control)
                    last_control = now
                    age, new = 0.0, False
                    for parent in s.parents:
                        queue = self.inbox[parent]
                        if not queue:
                            age = float("inf")
                            continue
                        state = queue[-1]
                        used = now - self.arrival.get(parent, -float("inf"))
                        new = new or state.seq != seen[parent]
                        seen[parent] = state.seq
                        self.ages[parent][instant] = used
                        age = max(age, used)
                        if predict:
                            # over the age the watchdog measures (spec fleet.md §3, §5): since the
                            # arrival, on this robot's clock (the sender's `t` is another machine's)
                            state = predicted(state, max(used, 0.0))
                        self.latest[parent] = state
                    if s.parents and age > self.watchdog.stale_after and now - last_subscribe > SUBSCRIBE_RETRY_S:
                        last_subscribe = now    # a silent parent may have restarted: subscribe again
                        for parent in s.parents:
                            await self._send(parent, msg.act("subscribe", s.name, parent,
                                                             msg.conversation(s.name, parent),
                                                             reply_with=f"{s.name}-subscribe"))
                    command = self._command(k, x, y, theta, xi) if all(self.inbox[p] for p in s.parents) \
                        else (0.0,) * kn.HELD_COUNT
                    if s.parents:
                        guard, command = self._guarded(guard, age, new, command, period, k, now - start, now)
                    held = command
                    self.plant.command(held[0], held[1])
                    await self._publish(k, instant, x, y, theta, held[0], held[1], t=clock())
                    if s.parents and instant % HEARTBEAT_EVERY == 0:
                        for parent in s.parents:
                            await self._send(parent, msg.act("inform", s.name, parent, msg.conversation(s.name, parent),
                                                             msg.progress_content(instant)))
                    for child in sorted(self.subscribers):
                        if now - self.heard.get(child, now) > SUBSCRIBER_LOST_S:
                            self.subscribers.discard(child)
                            self._event({"t": now - start, "event": "lost-subscriber", "robot": child,
                                                "at": now})
                self.states[k] = x, y, theta, xi
                self.helds[k] = held
            self.elapsed_s = time.perf_counter() - started
            for parent in s.parents:
                await self._send(parent, msg.act("cancel", s.name, parent, msg.conversation(s.name, parent)))
            await self._wait(lambda: not self.subscribers, "cancel from every follower", bound=end_wait_s)
        finally:
            receiver.cancel()
            for task in self._delayed:
                task.cancel()
            await asyncio.gather(receiver, *self._delayed, return_exceptions=True)

    async def _publish(self, k: int, instant: int, x: float, y: float, theta: float, v: float,
                       omega: float, t: float | None = None) -> None:
        """Send this robot's state of output step ``k`` to every subscriber: every frame is
        sealed first, then all are written back to back (a follower late in the order does
        not wait for the others' sealing); a state the link model delays leaves later."""
        if not self.setup.children:
            return
        self.seq += 1
        state = msg.RobotState(self.setup.name, k, self.seq, k * self.setup.dt if t is None else t, x, y, theta, v,
                               omega)
        content = state.to_content()
        now = []
        for child in sorted(self.subscribers):
            if self.drops[child][instant]:
                self.tally.lost[child] += 1   # the link model loses it on the way
                continue
            frame = self.channel.pack(msg.act("inform", self.setup.name, child,
                                              msg.conversation(child, self.setup.name), content))
            delay = self.delays[child][instant] if self.realtime else 0.0
            if delay > 0:
                self._send_later(child, frame, delay)
            else:
                now.append((child, frame))
        for child, frame in now:
            await self._send_frame(child, frame)
            self.tally.states_sent[child] += 1

    def _send_later(self, child: str, frame: bytes, delay: float) -> None:
        """Send a state frame after its drawn ``delay`` (in order unless the link reorders)."""
        due = self.clock() + delay
        if not self.reorder[child]:
            due = max(due, self._due.get(child, 0.0))
        self._due[child] = due
        task = asyncio.ensure_future(self._send_state_at(child, frame, due))
        self._delayed.add(task)
        task.add_done_callback(self._delayed.discard)

    async def _send_state_at(self, child: str, frame: bytes, due: float) -> None:
        """Send a state when its drawn delay is over (realtime link model; at most
        delay/T of them wait per child, as delay + jitter ≤ 24 T)."""
        await asyncio.sleep(max(0.0, due - self.clock()))
        await self._send_frame(child, frame)
        self.tally.states_sent[child] += 1

    def report(self) -> dict:
        """What this robot measured: per peer frames sent, received, rejected, lost by the
        link model; per parent the age of the state used at each instant; watchdog events;
        the control loop's period (wall clock)."""
        periods = np.diff(self.ticks[self.ticks > 0])
        return {"name": self.setup.name, "parents": list(self.setup.parents),
                "children": list(self.setup.children), "loop_s": self.elapsed_s,
                "sent": dict(self.tally.sent), "received": dict(self.tally.received),
                "rejected": dict(self.tally.rejected), "lost": dict(self.tally.lost),
                "states_sent": dict(self.tally.states_sent), "states_received": dict(self.tally.states_received),
                "ages": {p: [float(a) for a in ages[~np.isnan(ages)]] for p, ages in self.ages.items()},
                "age_times": {p: [float(i * self.setup.dt * self.setup.hold_every)
                                  for i in np.flatnonzero(~np.isnan(ages))] for p, ages in self.ages.items()},
                "latency": {p: list(samples) for p, samples in self.latency.items()},
                "events": list(self.events), "stopped_periods": float(self.stopped_periods),
                "transport": self.transport.stats(),
                "period": {"mean": float(periods.mean()) if periods.size else None,
                           "std": float(periods.std()) if periods.size else None,
                           "p99": float(np.percentile(periods, 99)) if periods.size else None,
                           "max": float(periods.max()) if periods.size else None}}
