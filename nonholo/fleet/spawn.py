"""Start one ``nonholo robot`` process per robot on this machine and gather their traces.

The launcher makes a private directory (mode 0700) with a fresh key file (mode 0600, or
uses the scenario's), binds a listening TCP socket on 127.0.0.1 with an OS-chosen port for
each robot that has followers and hands it to that robot's process (so every process
starts at once and no port can be taken in between), then waits for every process with a
bounded wait. Whatever happens — a robot failing, a time-out, Ctrl-C (or SIGTERM, SIGHUP
turned into an interrupt by the command line) — every process group is terminated (SIGTERM,
then SIGKILL after a grace period) and reaped before it returns, with those signals held
meanwhile so that the cleanup runs to its end. On Linux a robot process also gets SIGTERM
when the launcher dies without cleaning up (SIGKILL): ``PR_SET_PDEATHSIG``.
"""
from __future__ import annotations

import contextlib
import ctypes
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
PR_SET_PDEATHSIG = 1      # linux/prctl.h
HELD_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


class LaunchError(SimulationError):
    """A robot process failed or did not finish in time."""


@dataclass
class Robots:
    """Running robot processes by name, their commands, the listening sockets the launcher
    keeps (so that a restarted robot takes over its port) and the work directory."""

    workdir: Path
    processes: dict = field(default_factory=dict)   # name -> Popen
    commands: dict = field(default_factory=dict)    # name -> (argv, inherited fds)
    listeners: dict = field(default_factory=dict)   # name -> listening socket
    endpoints: dict = field(default_factory=dict)   # name -> Zenoh endpoint it listens on
    stopped: bool = False                           # stop_all has run (it runs once)

    def start(self, name: str) -> subprocess.Popen:
        command, fds = self.commands[name]
        with open(self.workdir / f"{name}.err", "ab") as errors:
            process = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=errors,
                                       pass_fds=fds, start_new_session=True, preexec_fn=die_with_parent())
        self.processes[name] = process
        return process

    def wait(self, run_s: float, allowed: frozenset = frozenset()) -> dict:
        """Wait (at most ``run_s``) until every process has ended; LaunchError at the first
        failure of a robot not in ``allowed``; the exit codes by name."""
        deadline = time.monotonic() + run_s
        while True:
            codes = {name: p.poll() for name, p in self.processes.items()}
            failed = [name for name, code in codes.items() if code not in (None, 0) and name not in allowed]
            if failed:
                raise LaunchError(f"robot {failed[0]} failed (exit {codes[failed[0]]}): "
                                  f"{self.error_line(failed[0])}")
            if all(code is not None for code in codes.values()):
                return codes
            if time.monotonic() > deadline:
                late = [name for name, code in codes.items() if code is None]
                raise LaunchError(f"robot {late[0]} did not finish within {run_s:g} s")
            time.sleep(POLL_S)

    def stop_all(self) -> None:
        """Terminate every process group still running, then kill and reap (bounded), and
        close the listening sockets; Ctrl-C, SIGTERM and SIGHUP wait until it is done."""
        with signals_held():
            self._stop_all()

    def discard(self) -> None:
        """``stop_all``, then remove the work directory (its keys and traces)."""
        with signals_held():
            self._stop_all()
            shutil.rmtree(self.workdir, ignore_errors=True)

    def _stop_all(self) -> None:
        if self.stopped:
            return
        self.stopped = True
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
        for listener in self.listeners.values():
            listener.close()

    def error_line(self, name: str) -> str:
        try:
            lines = (self.workdir / f"{name}.err").read_text(errors="replace").strip().splitlines()
        except OSError:
            lines = []
        return lines[-1][:200] if lines else "no message"


@contextlib.contextmanager
def signals_held():
    """Within: Ctrl-C, SIGTERM and SIGHUP are held by the OS and delivered on the way out
    (where the platform can hold signals)."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, HELD_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def die_with_parent():
    """A ``preexec_fn`` that has the child get SIGTERM when the process that started it dies
    (Linux ``prctl(PR_SET_PDEATHSIG)``; the death of the starting thread counts, so start
    robots from the main thread), or None where there is no such call."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    parent = os.getpid()

    def preexec() -> None:
        prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
        if os.getppid() != parent:   # the parent died before the call
            os.kill(os.getpid(), signal.SIGTERM)
    return preexec


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


def free_port() -> int:
    """A port the OS says is free now (for Zenoh endpoints, which bind by themselves: another
    program could take it before the robot binds it; TCP robots inherit bound sockets)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def start_robot_processes(source: Path, scenario, keys: Path | None, overrides: dict, wait_s: float,
                          extra: dict | None = None, transport: str = "tcp", failover: tuple = ()) -> Robots:
    """Start every robot of ``scenario`` (read from ``source`` with ``overrides``) as its own
    process, writing ``NAME.npz`` traces to a new work directory; ``extra`` {name: [options]}.
    The caller must ``stop_all()`` (in a ``finally``) and remove the work directory."""
    robots = Robots(Path(tempfile.mkdtemp(prefix="nonholo-fleet-")))
    try:
        if keys is None:
            keys = robots.workdir / "fleet.keys"
            write_fleet_key_file(keys, scenario.names)
        children = {r.name: [] for r in scenario.robots}
        for robot in scenario.robots:
            for parent in robot.parents:
                children[parent].append(robot.name)
        for name in failover[1:2]:    # the successor may gain followers
            children[name] = children[name] or ["(successor)"]
        for name, kids in children.items():
            if kids and transport == "zenoh":
                robots.endpoints[name] = f"tcp/127.0.0.1:{free_port()}"
            elif kids:
                listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
                listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                listener.bind(("127.0.0.1", 0))
                listener.listen(64)
                robots.listeners[name] = listener
        ports = {name: s.getsockname()[1] for name, s in robots.listeners.items()}
        for robot in scenario.robots:
            name = robot.name
            if transport == "zenoh":
                options = ["--transport", "zenoh"] + [f"--connect={p}={robots.endpoints[p]}" for p in robot.parents]
            else:
                linked = robot.parents if not failover else [n for n in ports if n != name]
                options = [f"--connect={p}=127.0.0.1:{ports[p]}" for p in linked]
            fds = ()
            if name in robots.endpoints:
                options += ["--listen", robots.endpoints[name]]
            if name in robots.listeners:
                options += ["--listen-fd", str(robots.listeners[name].fileno())]
                fds = (robots.listeners[name].fileno(),)
            options += (extra or {}).get(name, [])
            robots.commands[name] = (robot_command(source, name, keys, robots.workdir / f"{name}.npz", overrides,
                                                   wait_s, options), fds)
            robots.start(name)
    except BaseException:
        robots.discard()
        raise
    return robots
