"""The link model (spec fleet.md §3–4): per link, a delay (fixed plus seeded jitter) and a
loss probability, drawn from a generator of its own in message order; and a scenario's
link settings (``LinkSettings``: the seed, the default and per-link models, the watchdog),
read from the link fields of its ``[network]`` table.

One pure draw serves both sides of the equality contract: the centralized sampled-data
simulator applies it to the states it passes from parent to child (``Scenario.network``,
``nonholo.sim.simulator``), a fleet's robots to the frames they send
(``nonholo.fleet.robot``), so both see the same usable-message sequence.

Message j of a link is the parent's state of control instant j (t_j = j T). Its draw is
``(delay_j, lost_j)``; it becomes usable at the first instant t_k ≥ t_j + delay_j, that is
``k = j + ceil(delay_j / T − 1e-9)`` (the tolerance keeps a delay of exactly 2T at two
instants despite rounding). Without ``reorder`` a message is never usable before the one
sent before it (the instant is raised to the previous usable one, as a FIFO link does).
A lost message is never usable. With ``predict`` a follower uses a parent's message advanced
along the exact unicycle arc of its command over the message's age (spec fleet.md §3,
``nonholo.models.unicycle.unicycle_arc``).
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from nonholo.sim.watchdog import POSITIVE_FIELDS, TICK_TOLERANCE, WatchdogConfig
from nonholo.tomlfile import describe_value

LOST = -1               # usable instant of a lost message


@dataclass(frozen=True)
class LinkModel:
    """``delay`` s fixed, plus jitter uniform in [0, ``jitter``] s; ``loss`` probability in
    [0, 1); ``reorder`` lets a later message overtake an earlier one."""

    delay: float = 0.0
    jitter: float = 0.0
    loss: float = 0.0
    reorder: bool = False

    def __post_init__(self) -> None:
        for name in ("delay", "jitter"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 3600:
                raise ValueError(f"{name} must be a number of seconds in [0, 3600], got {value!r}")
        if isinstance(self.loss, bool) or not isinstance(self.loss, (int, float)) or not 0 <= self.loss < 1:
            raise ValueError(f"loss must be a probability in [0, 1), got {self.loss!r}")
        if not isinstance(self.reorder, bool):
            raise ValueError(f"reorder must be true or false, got {self.reorder!r}")

    @property
    def ideal(self) -> bool:
        return self.delay == 0 and self.jitter == 0 and self.loss == 0


IDEAL = LinkModel()


def link_generator(seed: int, parent: str, child: str) -> np.random.Generator:
    """The generator of link ``parent → child`` under ``seed`` (independent of every other
    link and of the order in which links are created)."""
    digest = hashlib.sha256(f"{parent}\x00{child}".encode("utf-8")).digest()
    words = [int.from_bytes(digest[i:i + 4], "little") for i in range(0, 16, 4)]
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([int(seed) & (2**64 - 1), *words])))


def link_draws(model: LinkModel, seed: int, parent: str, child: str, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``(delays, lost)`` of messages 0..count−1 of link ``parent → child``: delays in
    seconds (float array), lost flags (bool array). Prefix-stable: message j's draw does
    not depend on ``count``. Each message takes two uniform numbers, (jitter, loss)."""
    uniforms = link_generator(seed, parent, child).random((int(count), 2))
    delays = model.delay + model.jitter * uniforms[:, 0]
    lost = uniforms[:, 1] < model.loss
    return delays, lost


def usable_instants(model: LinkModel, seed: int, parent: str, child: str, count: int,
                    period: float) -> np.ndarray:
    """Per message j (0..count−1), the control instant from which it is usable, or ``LOST``."""
    delays, lost = link_draws(model, seed, parent, child, count)
    ticks = np.ceil(delays / period - TICK_TOLERANCE).astype(np.int64)
    usable = np.arange(count, dtype=np.int64) + np.maximum(ticks, 0)
    if not model.reorder:
        kept = ~lost
        usable[kept] = np.maximum.accumulate(usable[kept]) if kept.any() else usable[kept]
    usable[lost] = LOST
    return usable


def newest_usable(usable: np.ndarray, instants: int) -> np.ndarray:
    """Per control instant k (0..instants−1), the index j of the newest message usable at
    k (the largest j with ``0 <= usable[j] <= k``), or −1 when none is."""
    newest = np.full(instants, -1, dtype=np.int64)
    usable = np.asarray(usable)
    ok = (usable >= 0) & (usable < instants)
    np.maximum.at(newest, usable[ok], np.flatnonzero(ok))
    return np.maximum.accumulate(newest) if instants else newest


def link_schedule(model: LinkModel, seed: int, parent: str, child: str, instants: int,
                  period: float) -> np.ndarray:
    """The usable-message sequence of a link over ``instants`` control instants: per k,
    the newest usable message index (−1: none yet). Both the fleet and the centralized
    simulator call this."""
    return newest_usable(usable_instants(model, seed, parent, child, instants, period), instants)



# ---------------------------------------------------------------------- a scenario's settings
LINK_FIELDS = ("delay", "jitter", "loss", "reorder")
WATCHDOG_FIELDS = ("stale_after", "resume_after", "decel_v", "decel_omega")
WATCHDOG_HIGH = {"stale_after": 3600, "decel_v": 1e6, "decel_omega": 1e6}   # s, m/s², rad/s²
# The fields of a scenario's [network] table that the link model reads (the fleet reads the
# rest: transport, keys, addresses, failover, ...).
FIELDS = ("seed", "links", "predict", *LINK_FIELDS, *WATCHDOG_FIELDS)


@dataclass(frozen=True)
class LinkSettings:
    """The link model of a sampled-data run: ``seed``, ``default`` the model of every link,
    ``links`` per-link overrides as ``((parent, child), LinkModel)`` pairs, ``watchdog`` the
    followers' watchdog, ``predict`` whether followers advance a parent's message along its
    arc over the message's age. ``Scenario(network=...)`` carries them; scenarios that differ only
    in them (seed, delay, loss, watchdog) simulate together as one batch."""

    seed: int = 0
    default: LinkModel = IDEAL
    links: tuple = ()
    watchdog: WatchdogConfig = field(default_factory=WatchdogConfig)
    predict: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or not 0 <= self.seed < 2**63:
            raise ValueError(f"seed must be an integer in 0..2^63, got {self.seed!r}")
        links = tuple(self.links.items()) if isinstance(self.links, dict) else tuple(self.links)
        for item in links:
            if not (isinstance(item, tuple) and len(item) == 2 and isinstance(item[1], LinkModel)
                    and isinstance(item[0], tuple) and len(item[0]) == 2 and all(isinstance(n, str) for n in item[0])):
                raise ValueError(f"links must be ((parent, child), LinkModel) pairs, got {item!r}"[:200])
        object.__setattr__(self, "links", links)
        if not isinstance(self.default, LinkModel) or not isinstance(self.watchdog, WatchdogConfig):
            raise ValueError("default must be a LinkModel and watchdog a WatchdogConfig")
        if not isinstance(self.predict, bool):
            raise ValueError(f"predict must be true or false, got {self.predict!r}")

    def link(self, parent: str, child: str) -> LinkModel:
        return next((model for edge, model in self.links if edge == (parent, child)), self.default)

    @property
    def ideal(self) -> bool:
        """No delay, jitter or loss on any link: the plain sampled-data run (every state
        used at its own instant, age 0: the watchdog never acts and a prediction moves nothing)."""
        return self.default.ideal and all(model.ideal for _, model in self.links)

    def describe(self) -> dict:
        return {"seed": int(self.seed), **asdict(self.default),
                "links": {f"{p}->{c}": asdict(m) for (p, c), m in self.links}, "watchdog": asdict(self.watchdog),
                "predict": self.predict}


def _number(data: dict, key: str, where: str, default: float, high: float, fail) -> float:
    value = data.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or not 0 <= value <= high:
        fail(f"{where}.{key}", f"expected a number in [0, {high:g}], got {describe_value(value)}")
    return float(value)


def _link_model(data: dict, where: str, base: LinkModel, fail) -> LinkModel:
    delay = _number(data, "delay", where, base.delay, 3600, fail)
    jitter = _number(data, "jitter", where, base.jitter, 3600, fail)
    loss = _number(data, "loss", where, base.loss, 0.99, fail)
    reorder = data.get("reorder", base.reorder)
    if not isinstance(reorder, bool):
        fail(f"{where}.reorder", f"expected true or false, got {describe_value(reorder)}")
    return LinkModel(delay, jitter, loss, reorder)


def read_link_settings(data: dict, edges, fail) -> LinkSettings:
    """The link fields (``FIELDS``) of a ``[network]`` table ``data`` (a dict), per-link
    overrides checked against ``edges`` ({(parent, child)}); other fields are not looked at.
    ``fail(field, problem)`` raises on any problem (it names the field, e.g.
    ``network.links[0].delay``)."""
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
        fail("network.seed", f"expected an integer in 0..2^63, got {describe_value(seed)}")
    resume = data.get("resume_after", 3)
    if isinstance(resume, bool) or not isinstance(resume, int) or not 1 <= resume <= 1000:
        fail("network.resume_after", f"expected an integer in 1..1000, got {describe_value(resume)}")
    limits, defaults = {}, WatchdogConfig()
    for name in POSITIVE_FIELDS:
        limits[name] = _number(data, name, "network", getattr(defaults, name), WATCHDOG_HIGH[name], fail)
        if limits[name] <= 0:
            fail(f"network.{name}", "must be positive")
    watchdog = WatchdogConfig(resume_after=resume, **limits)
    predict = data.get("predict", False)
    if not isinstance(predict, bool):
        fail("network.predict", f"expected true or false, got {describe_value(predict)}")
    default = _link_model(data, "network", IDEAL, fail)
    items = data.get("links", [])
    if not isinstance(items, list):
        fail("network.links", "expected [[network.links]] tables")
    links: dict = {}
    allowed = {"parent", "child", *LINK_FIELDS}
    for i, item in enumerate(items):
        where = f"network.links[{i}]"
        if not isinstance(item, dict):
            fail(where, f"expected a table, got {describe_value(item)}")
        unknown = sorted(set(item) - allowed)
        if unknown:
            fail(f"{where}.{unknown[0]}"[:80], f"unknown field (expected one of: {', '.join(sorted(allowed))})")
        edge = (item.get("parent"), item.get("child"))
        for key, value in zip(("parent", "child"), edge):
            if not isinstance(value, str):
                fail(f"{where}.{key}", f"expected a robot's name, got {describe_value(value)}")
        if edge not in edges:
            fail(where, f"no link {edge[0][:40]!r} -> {edge[1][:40]!r} in the formation "
                        "(parent and child must name a robot and one of its followers)")
        if edge in links:
            fail(where, f"link {edge[0]} -> {edge[1]} given twice")
        links[edge] = _link_model(item, where, default, fail)
    return LinkSettings(seed, default, tuple(links.items()), watchdog, predict)


def group_schedules(settings: list, names: list, parents: np.ndarray, instants: int,
                    period: float) -> tuple[np.ndarray, int]:
    """The usable-message schedules of a group of copies for the simulator's link step:
    ``settings[b]`` (``LinkSettings`` or None) and ``names[b]`` (robot names, group order)
    of copy b, ``parents`` (2, R) the group's parent slots. Returns ``(schedule, depth)``:
    ``schedule`` (instants, 2, R, B) the index of the newest message usable per link at each
    instant (−1: none; ``link_schedule``), and ``depth`` how many instants of sent messages
    the step must keep (the largest age of a message when it comes into use, plus one)."""
    n_robots, n_batch = parents.shape[1], len(settings)
    schedule = np.full((instants, 2, n_robots, n_batch), -1, dtype=np.int64)
    every = np.arange(instants, dtype=np.int64)
    depth = 1
    for b, (links, robot_names) in enumerate(zip(settings, names)):
        for r in range(n_robots):
            for slot in range(2):
                p = parents[slot, r]
                if p < 0:
                    continue
                model = links.link(robot_names[p], robot_names[r]) if links is not None else IDEAL
                if model.ideal:
                    schedule[:, slot, r, b] = every
                    continue
                used = link_schedule(model, links.seed, robot_names[p], robot_names[r], instants, period)
                schedule[:, slot, r, b] = used
                arrived = (used >= 0) & (used != np.concatenate(([-1], used[:-1])))
                if arrived.any():
                    depth = max(depth, int((every - used)[arrived].max()) + 1)
    return schedule, depth
