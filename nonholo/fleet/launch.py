"""Start every robot of a scenario and gather one result (``nonholo fleet``).

``tcp`` (default): one ``nonholo robot`` process per robot on this machine, each robot with
followers serving them over authenticated TCP (``nonholo.fleet.spawn``, ``mesh``); there
is no central hub. ``inproc``: every robot program in this process on one event loop,
frames through the in-process transport (deterministic; for tests and for lockstep
figures). The result is the simulator's own ``SimulationResult``, scored from the robots'
trajectories and held commands by the kernel's statistics code, plus a ``network`` section.
"""
from __future__ import annotations

import asyncio
import importlib.util
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from nonholo.comm.transports.inproc import InProcNetwork
from nonholo.errors import NonholoInputError
from nonholo.fleet.config import MODES, TRANSPORTS, NetworkConfig
from nonholo.fleet.keys import fleet_keys, keys_from_file, robot_channel
from nonholo.fleet.report import link_timelines
from nonholo.fleet.process import make_plant, read_trace, run_program
from nonholo.fleet.robot import LinkPlan, RobotProgram, quantiles
from nonholo.fleet.setup import robot_setups
from nonholo.fleet.spawn import start_robot_processes
from nonholo.fleet.telemetry import paced_clock, watched_processes
from nonholo.sim import kernel as kn
from nonholo.sim.links import LinkSettings
from nonholo.sim.scenario import Scenario
from nonholo.sim.simulator import planned_groups, score_states


@dataclass
class FleetRun:
    """A fleet run: the simulator's result of the robots' trajectories and the network report."""

    result: object
    network: dict
    timelines: dict | None = None   # per link the age of the state used over time; events (not in JSON)

    def to_dict(self) -> dict:
        summary = self.result.to_dict()
        summary["network"] = self.network
        return summary


def check_observe(observe: str | None, transport: str) -> None:
    """An observer endpoint is for robot processes: NonholoInputError with an in-process fleet."""
    if observe is not None and transport == "inproc":
        raise NonholoInputError("--observe: robot processes send their status there; with --transport inproc "
                                "use --view")


def run_fleet(scenario: Scenario, transport: str = "tcp", mode: str = "lockstep", wait_s: float = 20.0,
              config: NetworkConfig | None = None, source: Path | None = None,
              overrides: dict | None = None, observer=None, speed: float | None = None,
              observe: str | None = None, on_start=None) -> FleetRun:
    """Run ``scenario`` as a fleet. Robot processes (``tcp``) read the scenario from the
    file ``source`` with ``overrides`` ({"duration", "dt", "control_period"}) applied, which
    must give ``scenario``.

    ``observer`` (a live view; ``nonholo.view.feed.FleetObserver``): its
    ``prepare(scenario, setups)``, if any, is called before the robots start; in process it
    is called with the robot programs every ``observer.period_s`` s of wall time while they
    run and once at the end; robot processes send their statuses to an observer endpoint
    that hands each to ``observer.status(name, status)`` (``nonholo.fleet.telemetry``). It
    must not block: a live view publishes a snapshot. ``speed``: pace the logical time of a
    lockstep run at this many times wall time (None: as fast as the robots go).
    ``observe`` ("host:port", robot processes only): the robots send their statuses there,
    to a viewer attached there (``nonholo view --attach``). ``on_start()``, if given, is called
    once the inputs are checked, before the robots start."""
    if transport not in TRANSPORTS:
        raise NonholoInputError(f"transport must be one of {', '.join(TRANSPORTS)}, got {transport!r}")
    if mode not in MODES:
        raise NonholoInputError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    check_observe(observe, transport)
    if transport == "zenoh" and importlib.util.find_spec("zenoh") is None:   # before 8 robots fail with it
        raise NonholoInputError("the zenoh transport needs the Python module 'zenoh': "
                                "python3 -m pip install 'nonholo[zenoh]'")
    if config is None:   # the scenario's own link model (Scenario.network), if any
        links = scenario.network or LinkSettings()
        config = NetworkConfig(transport=transport, seed=links.seed, watchdog=links.watchdog, default=links.default,
                               links=dict(links.links), predict=links.predict)
    if scenario.network != config.link_settings:
        # The centralized run the fleet equals plans its sub-steps with the links the robots apply.
        scenario = replace(scenario, network=config.link_settings)
    planned = planned_groups(scenario)
    setups = robot_setups(scenario, planned)
    started = time.perf_counter()
    n = scenario.n_steps + 1
    states = np.zeros((n, 4, len(scenario.robots)))
    helds = np.zeros((n, kn.HELD_COUNT, len(scenario.robots)))
    index = {name: i for i, name in enumerate(scenario.names)}
    reports = []
    if transport != "inproc":
        if source is None:
            raise NonholoInputError(f"transport {transport}: robot processes need the scenario file")
        if config.keys is not None:   # a bad key file is bad input, found before any process starts
            keys_from_file(config.keys, scenario.names, scenario.names)
    if on_start is not None:
        on_start()
    if observer is not None and hasattr(observer, "prepare"):
        observer.prepare(scenario, setups)
    if transport == "inproc":
        for program in asyncio.run(_inproc(scenario, setups, config, mode, wait_s, observer, speed)):
            states[:, :, program.setup.index] = program.states
            helds[:, :, program.setup.index] = program.helds
            reports.append(program.report())
    else:
        run_s = wait_s + 30.0 + 0.01 * n * len(scenario.robots)
        if mode == "realtime":
            run_s += scenario.duration
        elif speed:
            run_s += scenario.duration / speed
        pace = speed if mode == "lockstep" else None
        with watched_processes(observer, scenario.names, config.keys, observe, pace) as (keys, options):
            robots = start_robot_processes(Path(source), scenario, keys, overrides or {}, wait_s,
                                           extra={name: ["--mode", mode, *options] for name in scenario.names},
                                           transport=transport,
                                           failover=config.order if config.failover and mode == "realtime" else ())
            try:   # whatever happens (a failure, Ctrl-C, SIGTERM), every process is reaped and the folder goes
                robots.wait(run_s)
                robots.stop_all()
                for name in scenario.names:
                    robot_states, robot_helds, report = read_trace(robots.workdir / f"{name}.npz")
                    states[:, :, index[name]] = robot_states
                    helds[:, :, index[name]] = robot_helds
                    reports.append(report)
            finally:
                robots.discard()
    elapsed = time.perf_counter() - started
    by_name = {r["name"]: r for r in reports}
    watchdog = np.array([[sum(e.get("event") == "stop" for e in by_name[name]["events"]),
                          by_name[name].get("stopped_periods", 0.0)] for name in scenario.names], dtype=float).T
    result = score_states(scenario, planned, states, helds, elapsed, watchdog)
    network = network_report(reports, transport, mode, elapsed, scenario)
    network["stale_after"] = config.watchdog.stale_after
    return FleetRun(result, network, link_timelines(reports))


def inproc_programs(scenario: Scenario, setups: dict, config: NetworkConfig, mode: str, wait_s: float,
                    network: InProcNetwork, keys: dict | None = None) -> list[RobotProgram]:
    """Every robot program of ``scenario`` on the in-process ``network`` (fresh keys unless given)."""
    keys = keys or fleet_keys(scenario.names)
    limits = {r.name: (r.v_max, r.omega_max) for r in scenario.robots}
    programs = []
    for name, setup in setups.items():
        channel = robot_channel(name, setup.parents + setup.children, keys)
        programs.append(RobotProgram(setup, make_plant(setup, mode), network.endpoint(name), channel, limits, wait_s,
                                     LinkPlan(config.link, config.seed), config.watchdog))
    return programs


async def run_programs(programs: list[RobotProgram], mode: str, config: NetworkConfig, observer=None,
                       speed: float | None = None) -> list[RobotProgram]:
    """Run programs on this event loop until all end; the first failure cancels the rest.
    ``observer`` and ``speed``: see ``run_fleet``."""
    if speed:
        pace = paced_clock(speed)
        for program in programs:
            program.pace = pace
    tasks = [asyncio.ensure_future(run_program(p, mode, config)) for p in programs]
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


async def _inproc(scenario: Scenario, setups: dict, config: NetworkConfig, mode: str, wait_s: float, observer=None,
                  speed: float | None = None) -> list[RobotProgram]:
    return await run_programs(inproc_programs(scenario, setups, config, mode, wait_s, InProcNetwork()), mode, config,
                              observer, speed)


async def _observe(observer, programs) -> None:
    """Hand the programs to ``observer`` every ``observer.period_s`` until cancelled."""
    while True:
        observer(programs)
        await asyncio.sleep(observer.period_s)


def network_report(reports: list[dict], transport: str, mode: str, elapsed: float, scenario: Scenario) -> dict:
    """Per link (parent → child): states sent, received, lost (by the link model or on the
    way), frames rejected (and all frames sent and accepted), one-way latency and the age of
    the parent's state used at each control instant; per robot its watchdog events and
    control-loop period."""
    links = {}
    by_name = {r["name"]: r for r in reports}
    for sender in reports:
        name = sender["name"]
        for child in sender["children"]:
            receiver = by_name[child]
            sent, dropped = sender["states_sent"].get(child, 0), sender["lost"].get(child, 0)
            received, rejected = receiver["states_received"].get(name, 0), receiver["rejected"].get(name, 0)
            links[f"{name}->{child}"] = {
                "sent": sent, "received": received, "lost": dropped + max(sent - received, 0),
                "lost_by_model": dropped, "rejected": rejected, "frames_sent": sender["sent"].get(child, 0),
                "frames_received": receiver["received"].get(name, 0),
                "latency_s": quantiles(receiver["latency"].get(name, [])),
                "age_s": quantiles(receiver["ages"].get(name, []))}
    instants = len(range(0, scenario.n_steps + 1, scenario.hold_every))
    loop = max((r["loop_s"] for r in reports), default=0.0)   # the slowest robot's control loop
    return {"transport": transport, "mode": mode, "control_period": scenario.held_period,
            "elapsed_s": elapsed, "control_steps": instants, "loop_s": loop,
            "control_steps_per_s": instants / loop if loop > 0 else None, "links": links,
            "robots": {r["name"]: {"parents": r["parents"], "children": r["children"], "loop_s": r["loop_s"],
                                   "watchdog": r["events"], "period_s": r["period"]} for r in reports}}
