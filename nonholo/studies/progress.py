"""Feedback on long work: a progress bar on a terminal, one-line progress logs otherwise.

``Progress(label, total, mode)`` counts steps of a long job. Modes:

* ``"bar"``: a tqdm bar on stderr, redrawn every second while a step runs (so the
  elapsed time moves even during a long step) and naming the step and, while numba
  compiles, the function being compiled;
* ``"log"``: for logs, CI and ``nohup`` (stderr not a terminal): a line when the job
  starts, a line for a finished step when ``LOG_EVERY_S`` seconds have passed since the last
  line (and for the last step), ``study leader: 3/9 steps, 12.1 s (done: solver steps T2)``,
  and every ``heartbeat`` seconds while a step runs, ``study leader: 3/9 steps, 42.0 s (running: simulate T3;
  compiling integrate)``;
* ``"off"``: nothing.

``mode_for(enabled)`` picks "bar" or "log" from whether stderr is a terminal.
Times are wall-clock seconds since the ``Progress`` was created.
"""
from __future__ import annotations

import sys
import threading
import time

HEARTBEAT_S = 20.0  # log mode: a line at least this often while a step runs
LOG_EVERY_S = 2.0  # log mode: a finished step is logged if this long has passed since the last line
MODES = ("bar", "log", "off")
LINE_WIDTH = 100  # log lines are cut to this many columns (UTF-8 bytes, as the study summaries)


def mode_for(enabled: bool, stream=None) -> str:
    """ "bar" on a terminal, "log" elsewhere, "off" if not ``enabled``."""
    if not enabled:
        return "off"
    stream = stream or sys.stderr
    return "bar" if getattr(stream, "isatty", lambda: False)() else "log"


def _describe(function) -> str:
    """A compiled function's name, with the control law it was built for if it is a closure
    over one (the simulator's kernels are: "integrate for kanayama_law")."""
    name = getattr(function, "__name__", "compiled code")
    for cell in getattr(function, "__closure__", None) or ():
        try:
            inner = cell.cell_contents
        except ValueError:  # an empty cell
            continue
        inner_name = getattr(getattr(inner, "py_func", inner), "__name__", "")
        if inner_name.endswith("_law"):
            return f"{name} for {inner_name}"
    return name


class _Compiling:
    """What numba is compiling right now (its ``numba:compile`` event fires on cache misses
    only), shared by every Progress of the process."""

    def __init__(self):
        self.names: list[str] = []
        self.count = 0
        self.users = 0
        self.lock = threading.Lock()
        self.listener = None

    def attach(self):
        with self.lock:
            self.users += 1
            if self.listener is not None:
                return
            try:
                from numba.core import event
            except ImportError:  # pragma: no cover - numba is a dependency
                return
            owner = self

            class Listener(event.Listener):
                def on_start(self, ev):
                    dispatcher = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
                    owner.names.append(_describe(getattr(dispatcher, "py_func", None)))
                    owner.count += 1

                def on_end(self, ev):
                    if owner.names:
                        owner.names.pop()

            self.listener = Listener()
            event.register("numba:compile", self.listener)

    def detach(self):
        with self.lock:
            self.users -= 1
            if self.users or self.listener is None:
                return
            from numba.core import event

            event.unregister("numba:compile", self.listener)
            self.listener = None

    def now(self) -> str | None:
        names = self.names
        return names[0] if names else None


COMPILING = _Compiling()


class Progress:
    """Counts the steps of a long job and tells the person waiting (see the module docstring).

    >>> with Progress("demo", 2, "off") as progress:
    ...     progress.start("first")
    ...     progress.done()
    >>> progress.count
    1
    """

    def __init__(self, label: str, total: int, mode: str = "log", unit: str = "steps", stream=None,
                 heartbeat: float = HEARTBEAT_S):
        if mode not in MODES:
            raise ValueError(f"unknown progress mode {mode!r} (valid: {', '.join(MODES)})")
        self.label, self.total, self.mode, self.unit = label, total, mode, unit
        self.stream = stream or sys.stderr
        self.heartbeat = heartbeat
        self.count = 0
        self.step: str | None = None
        self.started = time.perf_counter()
        self._bar = None
        self._stop = threading.Event()
        self._thread = None
        self._last_line = self.started

    # -- context
    def __enter__(self) -> "Progress":
        if self.mode == "off":
            return self
        COMPILING.attach()
        if self.mode == "bar":
            from tqdm import tqdm

            self._bar = tqdm(total=self.total, desc=self.label, unit=self.unit.rstrip("s") or "step",
                             file=self.stream, leave=False, dynamic_ncols=True,
                             bar_format="{desc}: {n}/{total} {bar} {elapsed}{postfix}")
        elif self.mode == "log":
            print(f"{self.label}: started, {self.total} {self.unit}", file=self.stream, flush=True)
        self._thread = threading.Thread(target=self._tick, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self.mode == "off" or self._thread is None:
            return
        self._stop.set()
        self._thread.join()
        self._thread = None
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        COMPILING.detach()

    # -- steps
    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.started

    def start(self, step: str) -> None:
        """A step begins (named in the bar and in heartbeat lines)."""
        self.step = step
        if self._bar is not None:
            self._bar.set_postfix_str(self._postfix(), refresh=True)

    def done(self, step: str | None = None) -> None:
        """The current step (or ``step``) is finished."""
        finished = step or self.step
        self.count += 1
        self.step = None
        if self._bar is not None:
            self._bar.set_postfix_str(self._postfix(), refresh=False)
            self._bar.update(1)
        elif self.mode == "log" and (self.count == self.total
                                     or time.perf_counter() - self._last_line >= LOG_EVERY_S):
            self._line(f"done: {finished}" if finished else None)

    # -- output
    def _postfix(self) -> str:
        parts = [self.step] if self.step else []
        compiling = COMPILING.now()
        if compiling:
            parts.append(f"compiling {compiling}")
        return "; ".join(parts)

    def _line(self, note: str | None) -> None:
        self._last_line = time.perf_counter()
        text = f"{self.label}: {self.count}/{self.total} {self.unit}, {self.elapsed:.1f} s"
        if note:
            while len(f"{text} ({note})".encode()) > LINE_WIDTH and len(note) > 1:
                note = note[:-2] + "…"
            text += f" ({note})"
        print(text, file=self.stream, flush=True)

    def _tick(self) -> None:
        while not self._stop.wait(1.0):
            if self._bar is not None:
                self._bar.set_postfix_str(self._postfix(), refresh=True)
            elif self.step is not None and time.perf_counter() - self._last_line >= self.heartbeat:
                compiling = COMPILING.now()
                self._line(f"running: {self.step}" + (f"; compiling {compiling}" if compiling else ""))
