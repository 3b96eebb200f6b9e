"""The ``[network]`` table of a scenario: how a fleet's robots reach each other, their
keys, the link model (spec fleet.md §3–4) and the watchdog (§5). The link model's fields
(seed, delay, jitter, loss, reorder, links, the watchdog's) are read by
``nonholo.sim.links.read_link_settings``, for the centralized simulator
(``Scenario.network``) and for the fleet alike; this module reads the rest and bounds the
delays (in control periods: a lockstep robot's inboxes are bounded).

    [network]
    transport = "tcp"              # tcp | zenoh | inproc
    keys = "fleet.keys"            # key file (mode 0600): key id i+1 is robot i's key
    seed = 7                       # the link model's seed
    delay = 0.0                    # link defaults: fixed delay (s), jitter (s), loss
    jitter = 0.0
    loss = 0.0
    stale_after = 0.1              # watchdog (s); resume_after fresh states; decelerations
    resume_after = 3
    decel_v = 2.0
    decel_omega = 8.0
    predict = false                # advance each parent's state along its arc over the state's age
    failover = false               # realtime: the leader's successor takes over when it is lost
    order = ["leader", "f1"]       # the leader, then its successor (a direct l-phi follower)
    failover_after = 0.3           # s of the leader's silence before the successor takes over
    [network.addresses]            # where a robot with followers listens
    leader = "192.168.1.10:7400"   # tcp host:port, or a Zenoh endpoint "tcp/host:port"
    [[network.links]]              # per-link overrides
    parent = "leader"
    child = "f1"
    delay = 0.04
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

from nonholo.errors import InputFileError, ScenarioError
from nonholo.sim import links as link_fields
from nonholo.sim.links import IDEAL, LinkModel, LinkSettings, read_link_settings
from nonholo.sim.watchdog import WatchdogConfig
from nonholo.sim.files import load_scenario
from nonholo.sim.scenario import Scenario
from nonholo.tomlfile import describe_value, read_toml

TRANSPORTS = ("tcp", "zenoh", "inproc")
MODES = ("lockstep", "realtime")   # logical time, or the wall clock
FIELDS = {"transport", "keys", "addresses", "failover", "order", "failover_after", *link_fields.FIELDS}
MAX_DELAY_PERIODS = 24   # delay + jitter, in control periods (bounded lockstep inboxes)


@dataclass(frozen=True)
class NetworkConfig:
    transport: str = "tcp"
    keys: Path | None = None
    seed: int = 0
    watchdog: WatchdogConfig = WatchdogConfig()
    predict: bool = False
    addresses: dict = field(default_factory=dict)
    default: LinkModel = IDEAL
    links: dict = field(default_factory=dict)   # (parent, child) -> LinkModel
    failover: bool = False
    order: tuple = ()                           # failover: the leader, then its successor
    failover_after: float = 0.3                 # s of the leader's silence before the successor takes over

    def link(self, parent: str, child: str) -> LinkModel:
        return self.links.get((parent, child), self.default)

    @property
    def link_settings(self) -> LinkSettings | None:
        """The link model as the centralized simulator takes it (``Scenario.network``;
        None when every link is ideal)."""
        settings = LinkSettings(self.seed, self.default, tuple(self.links.items()), self.watchdog, self.predict)
        return None if settings.ideal else settings


class _Fields:
    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, name: str, problem: str):
        raise ScenarioError(self.source, name, problem)

    def number(self, data: dict, key: str, where: str, default: float, high: float) -> float:
        value = data.get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                or not 0 <= value <= high:
            self.fail(f"{where}.{key}", f"expected a number in [0, {high:g}], got {describe_value(value)}")
        return float(value)

    def table(self, data, where: str, allowed) -> dict:
        if not isinstance(data, dict):
            self.fail(where, f"expected a table, got {describe_value(data)}")
        unknown = sorted(set(data) - set(allowed))
        if unknown:
            self.fail(f"{where}.{unknown[0]}"[:80], f"unknown field (expected one of: {', '.join(sorted(allowed))})")
        return data

    def bound_delay(self, model: LinkModel, where: str, period: float) -> None:
        if model.delay + model.jitter > MAX_DELAY_PERIODS * period * (1 + 1e-9):
            self.fail(f"{where}.delay", f"delay + jitter = {model.delay + model.jitter:g} s exceeds "
                                        f"{MAX_DELAY_PERIODS} control periods ({MAX_DELAY_PERIODS * period:g} s)")


def network_config(data, scenario: Scenario, source: str = "<scenario>") -> NetworkConfig:
    """The ``[network]`` table ``data`` (a dict, possibly empty) checked against ``scenario``;
    ``ScenarioError`` naming the field on any problem."""
    f = _Fields(source)
    data = f.table(data, "network", FIELDS)
    period = scenario.control_period or scenario.dt
    transport = data.get("transport", "tcp")
    if transport not in TRANSPORTS:
        f.fail("network.transport", f"unknown value {describe_value(transport)} (valid: {', '.join(TRANSPORTS)})")
    keys = data.get("keys")
    if keys is not None and (not isinstance(keys, str) or not keys or len(keys) > 4096):
        f.fail("network.keys", f"expected the path of a key file, got {describe_value(keys)}")
    edges = {(p, r.name) for r in scenario.robots for p in r.parents}
    settings = read_link_settings(data, edges, f.fail)
    f.bound_delay(settings.default, "network", period)
    for i, (_, model) in enumerate(settings.links):
        f.bound_delay(model, f"network.links[{i}]", period)
    seed, watchdog, default, links = settings.seed, settings.watchdog, settings.default, dict(settings.links)
    predict = settings.predict
    names = set(scenario.names)
    addresses = f.table(data.get("addresses", {}), "network.addresses", names)
    for name, address in addresses.items():
        if not isinstance(address, str) or not address or len(address) > 300:
            f.fail(f"network.addresses.{name}", f"expected \"host:port\", got {describe_value(address)}")
    failover = data.get("failover", False)
    if not isinstance(failover, bool):
        f.fail("network.failover", f"expected true or false, got {describe_value(failover)}")
    order = data.get("order", list(scenario.names))
    if "order" in data or failover:
        if not isinstance(order, list) or len(order) < 2 or not all(isinstance(n, str) for n in order) \
                or not set(order) <= names or len(set(order)) != len(order):
            f.fail("network.order", "expected a list of at least two distinct robot names")
    after = f.number(data, "failover_after", "network", 0.3, 60)
    if failover:
        roots = [r.name for r in scenario.robots if not r.parents]
        by_name = {r.name: r for r in scenario.robots}
        if roots != [order[0]]:
            f.fail("network.order", f"failover needs one leader, first in the order (roots: {', '.join(roots)})")
        for robot in scenario.robots:
            if order[0] in robot.parents and getattr(robot, "law", None) != "separation-bearing":
                f.fail("network.failover", f"{robot.name} follows the leader with an l-l law; failover hands "
                                           "only l-phi followers over to the successor")
        if order[0] not in by_name[order[1]].parents:
            f.fail("network.order", f"the successor {order[1]} must follow the leader {order[0]} directly")
        if after <= watchdog.stale_after:
            f.fail("network.failover_after", "must exceed stale_after (the followers stop first)")
    return NetworkConfig(transport, Path(keys) if keys else None, seed, watchdog, predict, dict(addresses),
                         default, links, failover, tuple(order), after)


def with_overrides(scenario: Scenario, duration=None, dt=None, control_period=None) -> Scenario:
    """The scenario with [simulation] duration, dt, control_period replaced where given."""
    changes = {k: v for k, v in (("duration", duration), ("dt", dt), ("control_period", control_period))
               if v is not None}
    if changes:
        changes["steps"] = None
    return replace(scenario, **changes) if changes else scenario


def load_fleet(path, overrides: dict | None = None) -> tuple[Scenario, NetworkConfig]:
    """A scenario file, with ``overrides`` ({"duration", "dt", "control_period"}, see
    ``with_overrides``) applied, and its ``[network]`` table (defaults when absent), checked
    against the scenario as run (delays are bounded in control periods)."""
    scenario = with_overrides(load_scenario(path), **(overrides or {}))
    try:
        data = read_toml(Path(path))
    except InputFileError as exc:   # load_scenario read it a moment ago
        raise ScenarioError(str(path), "", exc.problem) from None
    config = network_config(data.get("network", {}), scenario, str(path))
    if config.keys is not None and not config.keys.is_absolute():
        config = replace(config, keys=Path(path).parent / config.keys)
    return scenario, config
