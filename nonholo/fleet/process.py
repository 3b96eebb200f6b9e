"""One robot program as its own OS process (``nonholo robot``): its plant, its links over
TCP or Zenoh, and at the end a trace file the launcher gathers (states, held commands and
the robot's report).

Trace file: a NumPy ``.npz`` with ``states`` (N+1, 4), ``helds`` (N+1, HELD_COUNT) and
``report`` (the JSON text of ``RobotProgram.report()``).
"""
from __future__ import annotations

import asyncio
import json
import os
import socket
import sys
from dataclasses import dataclass

import numpy as np

from nonholo.errors import NonholoInputError
from nonholo.fleet.config import NetworkConfig
from nonholo.fleet.keys import keys_from_file, robot_channel
from nonholo.fleet.mesh import RobotLinks, split_address
from nonholo.fleet.plant import SimulatedUnicycle, WallClockUnicycle
from nonholo.fleet.robot import DEFAULT_WAIT_S, Failover, LinkPlan, RobotProgram
from nonholo.fleet.setup import robot_setups
from nonholo.fleet.telemetry import watch_robot
from nonholo.sim.scenario import Scenario


@dataclass(frozen=True)
class RobotOptions:
    """How robot ``name`` reaches the others: ``listen`` "host:port" (with followers),
    ``connect`` {parent: "host:port"}, ``keys`` the key file."""

    name: str
    keys: str
    listen: str | None = None
    connect: tuple[tuple[str, str], ...] = ()
    wait_s: float = DEFAULT_WAIT_S
    listen_fd: int | None = None    # a listening socket inherited from the launcher
    mode: str = "lockstep"          # lockstep | realtime
    transport: str = "tcp"          # tcp | zenoh (addresses then Zenoh endpoints, "tcp/host:port")
    observe: str | None = None      # "host:port" of an observer to stream the robot's status to
    speed: float | None = None      # lockstep: pace logical time at this many times wall time


ZENOH_PROTOCOLS = ("tcp", "udp", "tls", "quic")


def zenoh_endpoint(text: str, field: str) -> str:
    """A Zenoh endpoint ``PROTOCOL/HOST:PORT`` (PROTOCOL one of ``ZENOH_PROTOCOLS``), checked
    here so that a malformed one is one line, not an error from inside Zenoh."""
    protocol, _, address = text.partition("/")
    if protocol not in ZENOH_PROTOCOLS or not address:
        raise NonholoInputError(f"{field}: expected a Zenoh endpoint PROTOCOL/HOST:PORT (PROTOCOL one of "
                                f"{', '.join(ZENOH_PROTOCOLS)}), got {text!r:.80}")
    split_address(address, field)
    return text


def resolve_addresses(scenario: Scenario, config: NetworkConfig, options: RobotOptions, setup) -> tuple:
    """(listen address or None, {parent: (host, port)}) from options, then [network.addresses]."""
    given = dict(options.connect)
    unknown = sorted(set(given) - set(setup.parents if not config.failover else scenario.names))
    if unknown:
        raise NonholoInputError(f"--connect: {unknown[0]!r} is not a parent of {options.name!r} "
                                f"(parents: {', '.join(setup.parents) or 'none'})")
    parents = {}
    for parent in setup.parents:
        text = given.get(parent, config.addresses.get(parent))
        if text is None:
            raise NonholoInputError(f"network.addresses.{parent}: no address for {options.name!r}'s parent "
                                    f"{parent!r} (give it there or --connect {parent}=HOST:PORT)")
        parents[parent] = zenoh_endpoint(text, f"address of {parent}") if options.transport == "zenoh" else \
            split_address(text, f"address of {parent}")
    listen = None
    if setup.children or (config.failover and options.name in config.order[1:2]):
        if options.listen_fd is not None:
            try:
                listening = socket.socket(fileno=options.listen_fd)
            except OSError as exc:
                raise NonholoInputError(f"--listen-fd {options.listen_fd}: not an open socket ({exc.strerror})") \
                    from None
            if listening.getsockopt(socket.SOL_SOCKET, socket.SO_ACCEPTCONN) == 0:
                listening.detach()
                raise NonholoInputError(f"--listen-fd {options.listen_fd}: not a listening socket")
            return listening, parents
        text = options.listen or config.addresses.get(options.name)
        if text is None:
            raise NonholoInputError(f"network.addresses.{options.name}: {options.name!r} has followers and needs "
                                    "an address to listen on (or --listen HOST:PORT)")
        listen = zenoh_endpoint(text, "--listen") if options.transport == "zenoh" else split_address(text, "--listen")
    return listen, parents


async def run_robot(scenario: Scenario, config: NetworkConfig, options: RobotOptions, announce=None) -> RobotProgram:
    """Run robot ``options.name`` over TCP; ``announce(port)`` once it listens."""
    setups = robot_setups(scenario)
    if options.name not in setups:
        raise NonholoInputError(f"--name: no robot {options.name!r} in the scenario "
                                f"(robots: {', '.join(scenario.names)})"[:200])
    setup = setups[options.name]
    listen, parents = resolve_addresses(scenario, config, options, setup)
    failover = config.failover and options.mode == "realtime"
    peers = setup.parents + setup.children
    if failover:   # any robot may become a peer
        peers = tuple(n for n in scenario.names if n != options.name)
    keys = keys_from_file(options.keys, scenario.names, (options.name, *peers))
    plant = make_plant(setup, options.mode)
    limits = {r.name: (r.v_max, r.omega_max) for r in scenario.robots}
    links = make_links(scenario, options, peers if failover else setup.children, keys, listen, parents)
    handover = None
    if failover:
        addresses = {**config.addresses, **dict(options.connect)}

        def relink(name: str) -> None:
            if isinstance(links, RobotLinks) and name in addresses:
                links.add_parent(name, split_address(addresses[name], f"address of {name}"))
        handover = Failover(config.order, setups, config.failover_after, relink)
    program = RobotProgram(setup, plant, links, robot_channel(options.name, peers, keys), limits, options.wait_s,
                           LinkPlan(config.link, config.seed), config.watchdog, handover)
    program.on_event = log_event
    telemetry = watch_robot(program, options.observe, options.speed, keys[options.name])
    try:
        port = await links.start() if isinstance(links, RobotLinks) else None
        if announce is not None:
            announce(port)
        await run_program(program, options.mode, config, on_start=announce_running(options.name))
    finally:
        if telemetry is not None:
            await telemetry.close()
        await links.close()
    return program


def make_links(scenario: Scenario, options: RobotOptions, accepted, keys: dict, listen, parents: dict):
    """The robot's transport: ``RobotLinks`` over TCP, or a Zenoh peer listening on its
    endpoint (with followers) and connecting to its parents' (no link-level key: every frame
    is still authenticated by its envelope)."""
    if options.transport != "zenoh":
        return RobotLinks(options.name, {n: (k[1], k[2]) for n, k in keys.items()}, tuple(accepted), parents,
                          listen)
    try:
        from nonholo.comm.transports.zenoh import ZenohTransport, peer_config
    except ImportError:
        raise NonholoInputError("transport zenoh: install the extra nonholo[zenoh]") from None
    return ZenohTransport(options.name, scenario.name, peer_config([listen] if listen else [], list(parents.values())))


def log_event(name: str, event: dict) -> None:
    """One stderr line per watchdog or link event, as it happens."""
    about = f" {event['robot']}" if "robot" in event else ""
    print(f"robot {name}: {event['event']}{about} at t = {event['t']:.3f} s", file=sys.stderr, flush=True)


def announce_running(name: str):
    """Say on stderr when the control loop starts (``robot NAME: running at T s ...``, T on
    this machine's monotonic clock, the stamp of the robot's states), for whoever watches."""
    def announce(t: float) -> None:
        print(f"robot {name}: running at {t:.6f} s on this machine's monotonic clock", file=sys.stderr, flush=True)
    return announce


def make_plant(setup, mode: str):
    """The simulated unicycle: on logical time (lockstep) or on the wall clock (realtime)."""
    if mode == "realtime":
        return WallClockUnicycle(setup.start)
    return SimulatedUnicycle(setup.start, setup.dt, setup.plan, setup.contract)


async def run_program(program: RobotProgram, mode: str, config: NetworkConfig, on_start=None) -> None:
    """Run ``program`` in ``mode``; ``on_start(t)`` when a realtime loop starts (monotonic clock)."""
    if mode == "realtime":
        await program.run_realtime(predict=config.predict, on_start=on_start)
    else:
        await program.run_lockstep(predict=config.predict)


def write_trace(path, program: RobotProgram) -> None:
    report = program.report()
    temporary = f"{path}.part"
    with open(temporary, "wb") as handle:
        np.savez(handle, states=program.states, helds=program.helds, report=np.array(json.dumps(report)))
    os.replace(temporary, path)


def read_trace(path) -> tuple[np.ndarray, np.ndarray, dict]:
    with np.load(path, allow_pickle=False) as data:
        return data["states"], data["helds"], json.loads(str(data["report"]))


def robot_main(scenario: Scenario, config: NetworkConfig, options: RobotOptions, trace: str | None,
               announce=None) -> RobotProgram:
    program = asyncio.run(run_robot(scenario, config, options, announce))
    if trace:
        write_trace(trace, program)
    return program
