"""Helpers for tests that start `nonholo` commands as child processes: their output read line by
line with bounded waits, and every child (and the robot processes it started) reaped at the end."""
import os
import queue
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STOP_S = 15.0


class Lines:
    """The lines of a child's output stream, read on a thread into a bounded queue."""

    def __init__(self, stream) -> None:
        self.seen: list[str] = []
        self._queue: queue.Queue = queue.Queue(maxsize=10_000)
        threading.Thread(target=self._read, args=(stream,), daemon=True).start()

    def _read(self, stream) -> None:
        try:
            for line in stream:
                self._queue.put(line)
        except (ValueError, OSError):   # closed by the test at its end
            pass
        self._queue.put(None)

    def wait_for(self, pattern: str, seconds: float) -> re.Match:
        """The first line (from now on) matching ``pattern``; AssertionError after ``seconds``."""
        deadline = time.monotonic() + seconds
        while True:
            try:
                line = self._queue.get(timeout=max(0.01, deadline - time.monotonic()))
            except queue.Empty:
                line = ""
            if line is None or time.monotonic() > deadline:
                raise AssertionError(f"no line matching {pattern!r}; got: {''.join(self.seen[-5:])[:600]}")
            self.seen.append(line)
            match = re.search(pattern, line)
            if match:
                return match


@contextmanager
def running(arguments: list[str]):
    """``python -m nonholo ARGUMENTS`` as a child: yields (process, stdout Lines, stderr Lines).
    At the end it is interrupted (Ctrl-C: the launcher stops and reaps its robots), killed if
    it does not end in time, and reaped."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    process = subprocess.Popen([sys.executable, "-m", "nonholo", *arguments], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, env=env)
    try:
        yield process, Lines(process.stdout), Lines(process.stderr)
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
        try:
            process.wait(STOP_S)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(STOP_S)
        process.stdout.close()
        process.stderr.close()


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]
