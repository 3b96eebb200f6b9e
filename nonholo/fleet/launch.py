"""Start every robot of a scenario and gather one result (``nonholo fleet``).

``inproc``: every robot program in this process on one event loop, frames through the
in-process transport (deterministic; for tests and for lockstep figures). The result is
the simulator's own ``SimulationResult``, scored from the robots' trajectories and held
commands by the kernel's statistics code, plus a ``network`` section.
"""
from __future__ import annotations

import asyncio
import secrets
import time
from dataclasses import dataclass

import numpy as np

from nonholo.comm.channel import SecureChannel
from nonholo.comm.envelope import Opener, Sealer
from nonholo.comm.transports.inproc import InProcNetwork
from nonholo.errors import NonholoInputError
from nonholo.fleet.plant import SimulatedUnicycle
from nonholo.fleet.robot import RobotProgram
from nonholo.fleet.setup import robot_setups
from nonholo.sim import kernel as kn
from nonholo.sim.scenario import Scenario
from nonholo.sim.simulator import planned_groups, score_states

TRANSPORTS = ("inproc",)
MODES = ("lockstep",)
KEY_BYTES = 32


@dataclass
class FleetRun:
    """A fleet run: the simulator's result of the robots' trajectories and the network report."""

    result: object
    network: dict

    def to_dict(self) -> dict:
        summary = self.result.to_dict()
        summary["network"] = self.network
        return summary


def fleet_keys(names) -> dict[str, tuple[int, int, bytes]]:
    """Per robot (sender id, key id, secret): one key per sender (spec comm.md §3.1)."""
    return {name: (i + 1, i + 1, secrets.token_bytes(KEY_BYTES)) for i, name in enumerate(names)}


def robot_channel(name: str, peers, keys: dict) -> SecureChannel:
    """Seals with ``name``'s key; opens only ``peers``' frames, each bound to its name."""
    sender_id, key_id, secret = keys[name]
    opener = Opener({keys[p][1]: keys[p][2] for p in peers},
                    key_senders={keys[p][1]: frozenset({keys[p][0]}) for p in peers}, max_age_ms=60_000)
    return SecureChannel(Sealer(secret, key_id=key_id, sender_id=sender_id), opener,
                         senders={keys[p][0]: p for p in peers})


def run_fleet(scenario: Scenario, transport: str = "inproc", mode: str = "lockstep",
              wait_s: float = 20.0, observer=None, speed: float | None = None) -> FleetRun:
    """Run the fleet. ``observer``: a callable given the robot programs every
    ``observer.period_s`` s of wall time while they run and once at the end (it must not
    block: a live view publishes a snapshot), whose ``prepare(scenario, setups)``, if any, is
    called before the robots start; ``speed``: pace the logical time at this many
    times wall time (None: as fast as the robots go)."""
    if transport not in TRANSPORTS:
        raise NonholoInputError(f"transport must be one of {', '.join(TRANSPORTS)}, got {transport!r}")
    if mode not in MODES:
        raise NonholoInputError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    planned = planned_groups(scenario)
    setups = robot_setups(scenario, planned)
    started = time.perf_counter()
    if observer is not None and hasattr(observer, "prepare"):
        observer.prepare(scenario, setups)
    programs = asyncio.run(_inproc_lockstep(scenario, setups, wait_s, observer, speed))
    elapsed = time.perf_counter() - started
    n = scenario.n_steps + 1
    states = np.zeros((n, 4, len(scenario.robots)))
    helds = np.zeros((n, kn.HELD_COUNT, len(scenario.robots)))
    for program in programs:
        states[:, :, program.setup.index] = program.states
        helds[:, :, program.setup.index] = program.helds
    result = score_states(scenario, planned, states, helds, elapsed)
    return FleetRun(result, network_report(programs, transport, mode, elapsed, scenario))


async def _inproc_lockstep(scenario: Scenario, setups: dict, wait_s: float, observer=None,
                           speed: float | None = None) -> list[RobotProgram]:
    network = InProcNetwork()
    keys = fleet_keys(scenario.names)
    limits = {r.name: (r.v_max, r.omega_max) for r in scenario.robots}
    programs = []
    for name, setup in setups.items():
        plant = SimulatedUnicycle(setup.start, setup.dt, setup.plan, setup.contract)
        channel = robot_channel(name, setup.parents + setup.children, keys)
        programs.append(RobotProgram(setup, plant, network.endpoint(name), channel, limits, wait_s))
    if speed:
        clock = paced_clock(speed)
        for program in programs:
            program.clock = clock
    tasks = [asyncio.ensure_future(p.run_lockstep()) for p in programs]
    if observer is not None:
        tasks.append(asyncio.ensure_future(_observe(observer, programs)))
    try:
        await asyncio.gather(*tasks[:len(programs)])
        if observer is not None:
            observer(programs)
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    return programs


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


async def _observe(observer, programs) -> None:
    """Hand the programs to ``observer`` every ``observer.period_s`` until cancelled."""
    while True:
        observer(programs)
        await asyncio.sleep(observer.period_s)


def network_report(programs, transport: str, mode: str, elapsed: float, scenario: Scenario) -> dict:
    """Per link (parent → child): frames sent, received, rejected; per robot its loop figures."""
    links = {}
    by_name = {p.setup.name: p for p in programs}
    for program in programs:
        for child in program.setup.children:
            receiver = by_name[child]
            name = program.setup.name
            links[f"{name}->{child}"] = {"sent": program.tally.sent[child], "received": receiver.tally.received[name],
                                         "lost": program.tally.sent[child] - receiver.tally.received[name]
                                         - receiver.tally.rejected[name],
                                         "rejected": receiver.tally.rejected[name]}
    instants = len(range(0, scenario.n_steps + 1, scenario.hold_every))
    return {"transport": transport, "mode": mode, "control_period": scenario.control_period,
            "elapsed_s": elapsed, "control_steps": instants,
            "control_steps_per_s": instants / elapsed if elapsed > 0 else None, "links": links,
            "robots": {p.setup.name: {"parents": list(p.setup.parents), "children": list(p.setup.children),
                                      "loop_s": p.elapsed_s} for p in programs}}
