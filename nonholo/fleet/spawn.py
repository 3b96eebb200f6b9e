"""Start one ``nonholo robot`` process per robot on this machine and gather their traces.

The launcher makes a private directory (mode 0700) with a fresh key file (mode 0600, or
uses the scenario's), binds a listening TCP socket on 127.0.0.1 with an OS-chosen port for
each robot that has followers and hands it to that robot's process (so every process
starts at once and no port can be taken in between), then waits for every process with a
bounded wait. Whatever happens — a robot failing, a time-out, Ctrl-C — every process group
is terminated (SIGTERM, then SIGKILL after a grace period) and reaped before it returns.
"""
from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from nonholo.errors import SimulationError
from nonholo.fleet.keys import write_fleet_key_file

TERMINATE_GRACE_S = 1.0
POLL_S = 0.02


class LaunchError(SimulationError):
    """A robot process failed or did not finish in time."""


@dataclass
class Robots:
    """Running robot processes by name, and where their outputs go."""

    workdir: Path
    processes: dict = field(default_factory=dict)   # name -> Popen

    def stop_all(self) -> None:
        """Terminate every process group still running, then kill and reap (bounded)."""
        for process in self.processes.values():
            if process.poll() is None:
                _signal_group(process, signal.SIGTERM)
        deadline = time.monotonic() + TERMINATE_GRACE_S
        for process in self.processes.values():
            try:
                process.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass
        for process in self.processes.values():
            _signal_group(process, signal.SIGKILL)   # the whole group, stray children too
            process.wait()

    def error_line(self, name: str) -> str:
        try:
            lines = (self.workdir / f"{name}.err").read_text(errors="replace").strip().splitlines()
        except OSError:
            lines = []
        return lines[-1][:200] if lines else "no message"


def _signal_group(process: subprocess.Popen, sig: int) -> None:
    try:
        os.killpg(process.pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def robot_command(source: Path, name: str, keys: Path, trace: Path, overrides: dict, wait_s: float,
                  extra: list[str]) -> list[str]:
    command = [sys.executable, "-m", "nonholo", "robot", str(source), "--name", name, "--keys", str(keys),
               "--trace", str(trace), "--wait", repr(wait_s)]
    for option, value in overrides.items():
        if value is not None:
            command += [f"--{option.replace('_', '-')}", repr(float(value))]
    return command + extra


def run_robot_processes(source: Path, scenario, keys: Path | None, overrides: dict, wait_s: float,
                        run_s: float, extra: dict | None = None, on_started=None) -> tuple[Path, Robots]:
    """Run every robot of ``scenario`` (read from ``source`` with ``overrides``) as its own
    process; return the work directory holding ``NAME.npz`` traces (the caller removes it).
    ``run_s`` bounds the whole run after start-up; ``on_started(robots)`` runs once all started
    (fault tests use it); ``extra`` {name: [options]}."""
    workdir = Path(tempfile.mkdtemp(prefix="nonholo-fleet-"))
    robots = Robots(workdir)
    sockets = []
    try:
        if keys is None:
            keys = workdir / "fleet.keys"
            write_fleet_key_file(keys, scenario.names)
        children = {r.name: [] for r in scenario.robots}
        for robot in scenario.robots:
            for parent in robot.parents:
                children[parent].append(robot.name)
        listeners = {}
        for name, kids in children.items():
            if kids:
                listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
                listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                listener.bind(("127.0.0.1", 0))
                listener.listen(64)
                sockets.append(listener)
                listeners[name] = listener
        ports = {name: s.getsockname()[1] for name, s in listeners.items()}
        for robot in scenario.robots:
            name = robot.name
            options = [f"--connect={p}=127.0.0.1:{ports[p]}" for p in robot.parents]
            fds = ()
            if name in listeners:
                options += ["--listen-fd", str(listeners[name].fileno())]
                fds = (listeners[name].fileno(),)
            options += (extra or {}).get(name, [])
            command = robot_command(source, name, keys, workdir / f"{name}.npz", overrides, wait_s, options)
            with open(workdir / f"{name}.err", "wb") as errors:
                robots.processes[name] = subprocess.Popen(command, stdin=subprocess.DEVNULL,
                                                          stdout=subprocess.DEVNULL, stderr=errors,
                                                          pass_fds=fds, start_new_session=True)
        for listener in sockets:
            listener.close()
        sockets.clear()
        if on_started is not None:
            on_started(robots)
        deadline = time.monotonic() + run_s
        while True:
            codes = {name: p.poll() for name, p in robots.processes.items()}
            failed = [name for name, code in codes.items() if code not in (None, 0)]
            if failed:
                raise LaunchError(f"robot {failed[0]} failed (exit {codes[failed[0]]}): "
                                  f"{robots.error_line(failed[0])}")
            if all(code == 0 for code in codes.values()):
                return workdir, robots
            if time.monotonic() > deadline:
                late = [name for name, code in codes.items() if code is None]
                raise LaunchError(f"robot {late[0]} did not finish within {run_s:g} s")
            time.sleep(POLL_S)
    except BaseException:
        shutil.rmtree(workdir, ignore_errors=True)
        raise
    finally:
        for listener in sockets:
            listener.close()
        robots.stop_all()
