"""Work beside a study, in processes forked from it: the report's figures, and a study's
own independent part (the leader study's gain sweeps).

Matplotlib builds and renders a figure in Python, one core at a time (26 figures: most of a
warm ``nonholo study``), and numba compiles one function at a time (most of a first run);
neither vectorizes, and these machines have two cores. A child forked from the study's own
process sees the study's data as it is in memory: nothing is copied or pickled on the way in.

* **Figures.** A report section names its figures as calls, ``draw(plot_test, runs, title,
  path)``, and goes on writing its text: the page refers to a figure by its file name, never
  to what drawing it returned. ``Drawing`` draws a section's calls in up to ``processes``
  children, which take the calls one by one from a shared counter, while the parent runs the
  next study. ``finish`` waits for them, with progress, and raises one line naming the
  figure if any drawing failed. ``draw_now`` is the same interface drawing at once, in this
  process.
* **A call.** ``ForkedCall(function)`` runs ``function()`` in a child at once;
  ``result()`` waits for its return value (pickled back: keep it small) or raises the
  child's exception in the parent. ``nice`` lowers the child's priority: work that only
  speeds up later work (compiling ahead, ``studies.report.each_result``) then takes what the
  study's own processes leave of the cores.

Both fall back to this process (in order, at the same points) where ``fork`` is not the safe
default (anything but Linux) or with ``processes=0`` (``StudyOptions``' default: a library
caller, in a notebook with its own threads, opts in; ``nonholo study`` forks 2). ``close``
stops and reaps every child (an interrupted study leaves none behind); a child ends with
its parent, even a killed one, and leaves Ctrl-C to it. A child is forked only while no
progress line of the study is being drawn (its ticker thread stopped), so that no thread
of this process is writing to the terminal when it forks; tqdm's monitor thread may be
alive, and the children never use tqdm.

>>> calls = []
>>> draw_now(calls.append, "figure.png")
>>> calls
['figure.png']
>>> ForkedCall(lambda: 6 * 7, processes=0).result()
42
"""
from __future__ import annotations

import contextlib
import multiprocessing
import multiprocessing.connection
import os
import sys
import threading
import time
from collections.abc import Callable

#: child processes at once, by default: the machines this is made for have two cores
PROCESSES = 2
#: the most a caller may ask for (``StudyOptions``, ``--processes``)
MAX_PROCESSES = 16
#: how long ``finish`` and a section waiting for a free process block between looks (seconds)
POLL_S = 0.2


def draw_now(function: Callable, *args, **kwargs) -> None:
    """Draw a figure at once (``function(*args, **kwargs)``)."""
    function(*args, **kwargs)


def forking() -> bool:
    """True where work may go to forked children: Linux, and not inside a daemonic process
    (a multiprocessing or Dask worker, which may have no children)."""
    return (sys.platform.startswith("linux") and "fork" in multiprocessing.get_all_start_methods()
            and not multiprocessing.current_process().daemon)


def _from_main_thread() -> bool:
    """Whether a child forked now may be tied to its parent's life: Linux's parent-death signal
    follows the forking *thread*, which must then be the main one (it lives as long as the
    process)."""
    return threading.current_thread() is threading.main_thread()


def _call_name(function: Callable) -> str:
    function = getattr(function, "func", function)   # a functools.partial: its function's name
    return getattr(function, "__qualname__", None) or getattr(function, "__name__", None) or repr(function)


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _travelling(exc: BaseException, function: Callable) -> BaseException:
    """``exc`` itself if it pickles (the parent raises the same type), else a ``RuntimeError``
    of one line."""
    import pickle

    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:  # noqa: BLE001 (an exception that does not travel: its line does)
        return RuntimeError(f"{_call_name(function)} failed: {_one_line(exc)}")


_HELD = ("SIGTERM", "SIGHUP", "SIGINT")


@contextlib.contextmanager
def _signals_held():
    """Around a fork: the stopping signals wait (blocked), so that a child never runs its
    parent's handlers before its own are set (``_as_child`` unblocks them)."""
    import signal

    held = {getattr(signal, name) for name in _HELD}
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _as_child(tied: bool) -> None:
    """A helper's signals: SIGTERM and SIGHUP end it at once (``close`` terminates it), Ctrl-C
    is its parent's to handle (which then stops it), and, if ``tied`` (forked from the main
    thread), it ends when its parent does, even killed (Linux's parent-death signal). Forked
    with them held (``_signals_held``): they are let through once its handlers are set."""
    import os
    import signal

    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGHUP, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {getattr(signal, name) for name in _HELD})
    if not tied:
        return
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))   # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    parent = multiprocessing.parent_process()
    if parent is not None and os.getppid() != parent.pid:   # the parent died before that
        os._exit(1)


def _draw_calls(calls: list, counter, connection, tied: bool) -> None:
    """A child's work: take the next figure's call from the shared counter until none is
    left and report each one drawn, ``("drawn", index)``; a failure is one line to the
    parent and exit code 1."""
    import os

    _as_child(tied)
    try:
        while True:
            with counter.get_lock():
                index = counter.value
                counter.value += 1
            if index >= len(calls):
                break
            function, args, kwargs = calls[index]
            try:
                function(*args, **kwargs)
            except BaseException as exc:  # noqa: BLE001 (one line to the parent, whatever it was)
                connection.send(("error", f"figure {_call_name(function)} failed: {_one_line(exc)}"))
                connection.close()
                os._exit(1)
            connection.send(("drawn", index))
        connection.send(("done", time.perf_counter()))   # the clock is the system's: the parent reads it alike
    finally:
        connection.close()


def _fork_children(calls: list, processes: int, name: str) -> tuple[list, object]:
    """Up to ``processes`` children drawing ``calls``, taken from one new shared counter:
    their [process, connection] pairs and the counter (keep it until they are reaped: its
    shared memory, freed while they still count on it, could become another counter)."""
    context = multiprocessing.get_context("fork")
    counter = context.Value("l", 0)
    children, tied = [], _from_main_thread()
    try:
        for _ in range(min(processes, len(calls))):
            receiver, sender = context.Pipe(duplex=False)
            process = context.Process(target=_draw_calls, args=(calls, counter, sender, tied), daemon=True,
                                      name=name)
            try:
                with _signals_held():   # a signal held meanwhile is raised as the block ends: counted first
                    process.start()
                    children.append([process, receiver])
            finally:
                sender.close()
    except BaseException:   # an interrupt or a failed fork: none of the started ones is left running
        _reap(children)
        raise
    return children, counter


def _reap(children: list) -> None:
    """Stop (if still running) and reap every child of ``children``."""
    for process, _ in children:
        if process.is_alive():
            process.terminate()
    for process, connection in children:
        process.join()
        connection.close()


class Drawing:
    """Figures of report sections drawn in forked children (see the module docstring).

    Calling it queues a figure (the ``draw`` a section receives); ``start(section)`` starts
    drawing what was queued since the last start; ``finish()`` waits for every figure;
    ``close()`` (also at the end of a ``with`` block) stops whatever still runs.
    """

    def __init__(self, processes: int = PROCESSES):
        if not isinstance(processes, int) or processes < 0:
            raise ValueError(f"processes must be a whole number >= 0, not {processes!r}")
        self.processes = processes if forking() else 0
        self.queued: list = []
        self.running: list = []          # [process, connection, section]
        self.sections: dict = {}         # section -> {"figures", "drawn", "started", "seconds", "children"}
        self.failure: str | None = None

    # -- queue and start
    def __call__(self, function: Callable, *args, **kwargs) -> None:
        self.queued.append((function, args, kwargs))

    def start(self, section: str, progress=None) -> None:
        """Draw the figures queued since the last start as ``section``'s: in this process if
        there are no child processes (``progress`` sees each figure drawn), otherwise in up to
        ``processes`` children once as many are free (the parent waits for a free one)."""
        calls, self.queued = self.queued, []
        entry = {"figures": len(calls), "drawn": 0, "started": time.perf_counter(), "seconds": 0.0, "children": 0}
        if section in self.sections:   # the same name again (a library caller's): an entry of its own
            section = next(f"{section} ({n})" for n in range(2, len(self.sections) + 2)
                           if f"{section} ({n})" not in self.sections)
        self.sections[section] = entry
        if not calls:
            return
        if self.processes == 0:
            for function, args, kwargs in calls:
                function(*args, **kwargs)
                entry["drawn"] += 1
                if progress is not None:
                    progress.done(f"{section} figure {entry['drawn']}")
            entry["seconds"] = time.perf_counter() - entry["started"]
            return
        wanted = min(self.processes, len(calls))
        self._wait(until_free=self.processes - wanted + 1)   # as many free processes as the section takes
        self._raise_failure()
        entry["started"] = time.perf_counter()
        children, entry["counter"] = _fork_children(calls, wanted, f"nonholo-figures-{section}")
        entry["children"] = len(children)
        self.running += [[process, connection, section] for process, connection in children]

    # -- wait
    def finish(self, progress=None) -> dict:
        """Wait for every figure; ``progress`` (a ``Progress`` over ``pending()`` figures)
        sees each one drawn. Returns each section's figures, how many were drawn, and its
        drawing's wall time (from its start to its last child's end); raises
        ``RuntimeError`` with one line if a figure failed (every child reaped)."""
        self._wait(until_free=1, progress=progress)
        self._raise_failure()
        lost = {name: e["figures"] - e["drawn"] for name, e in self.sections.items() if e["drawn"] != e["figures"]}
        if lost:   # every child reported done: a figure neither drawn nor failed is a defect here
            name, count = next(iter(lost.items()))
            raise RuntimeError(f"figures of {name}: {count} of {self.sections[name]['figures']} were not drawn")
        return {name: {"figures": e["figures"], "drawn": e["drawn"], "seconds": e["seconds"]}
                for name, e in self.sections.items()}

    def pending(self) -> int:
        """Figures queued or started and not drawn yet."""
        return len(self.queued) + sum(e["figures"] - e["drawn"] for e in self.sections.values())

    def _wait(self, until_free: int, progress=None) -> None:
        """Read the children's reports until fewer than ``until_free`` run (a failure stops all)."""
        while self.running and len(self.running) >= until_free and not self.failure:
            ready = multiprocessing.connection.wait([r[1] for r in self.running], timeout=POLL_S)
            for child in [r for r in self.running if r[1] in ready]:
                self._read(child, progress)

    def _read(self, child: list, progress) -> None:
        process, connection, section = child
        entry = self.sections[section]
        try:
            kind, value = connection.recv()
        except (EOFError, OSError):
            kind, value = "gone", None
        if kind == "drawn":
            entry["drawn"] += 1
            if progress is not None:
                progress.done(f"{section} figure {value + 1}")
            return
        connection.close()
        process.join()
        self.running.remove(child)
        entry["children"] -= 1
        if entry["children"] == 0:
            entry.pop("counter", None)
        if kind == "done":
            entry["seconds"] = max(entry["seconds"], value - entry["started"])
        elif kind == "error":
            self.failure = value
        else:
            self.failure = (f"figures of {section}: the drawing process ended without a word "
                            f"(exit code {process.exitcode})")

    def _raise_failure(self) -> None:
        if self.failure:
            message = self.failure
            self.close()
            raise RuntimeError(message)

    # -- stop
    def close(self) -> None:
        """Stop and reap every child still drawing (nothing is left running)."""
        _reap([child[:2] for child in self.running])
        self.running = []

    def __enter__(self) -> "Drawing":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _call(function: Callable, connection, tied: bool, nice: int = 0) -> None:
    """A child's work for ``ForkedCall``: the return value, or the exception (itself if it
    pickles, else a ``RuntimeError`` of one line)."""
    _as_child(tied)
    try:
        if nice:
            with contextlib.suppress(OSError):   # (raising one's niceness needs no privilege)
                os.nice(nice)
        try:
            message = ("value", function())
        except BaseException as exc:  # noqa: BLE001 (handed to the parent, whatever it was)
            message = ("error", _travelling(exc, function))
        connection.send(message)
    finally:
        connection.close()


class ForkedCall:
    """``function()`` run in a forked child from now on; ``result()`` its return value (see
    the module docstring). With ``processes=0`` or without ``fork``, ``result()`` calls it
    here instead, when asked."""

    def __init__(self, function: Callable, processes: int = PROCESSES, name: str = "call", nice: int = 0):
        self.function, self.process, self.connection = function, None, None
        self._outcome: tuple | None = None   # ("value", v) or ("error", exception) once known
        if processes > 0 and forking():
            context = multiprocessing.get_context("fork")
            self.connection, sender = context.Pipe(duplex=False)
            self.process = context.Process(target=_call, args=(function, sender, _from_main_thread(), nice),
                                           daemon=True, name=f"nonholo-{name}")
            try:
                with _signals_held():
                    self.process.start()
            except BaseException:   # interrupted as the held signals came through: not left running
                self.close()
                raise
            finally:
                sender.close()

    def result(self):
        """The return value (waiting for the child); the child's exception is raised here,
        at every call."""
        if self._outcome is None:
            if self.process is None:
                try:
                    self._outcome = ("value", self.function())
                except Exception as exc:
                    self._outcome = ("error", exc)
            else:
                try:
                    self._outcome = self.connection.recv()
                except (EOFError, OSError):
                    self.process.join()
                    self._outcome = ("error", RuntimeError(f"{_call_name(self.function)}: its process ended "
                                                           f"without a word (exit code {self.process.exitcode})"))
                self.close()
        kind, value = self._outcome
        if kind == "error":
            raise value
        return value

    def close(self) -> None:
        """Reap the child (stopped first if it has not answered yet)."""
        if self.process is not None:
            if self.process.pid is not None:   # (a fork that failed started nothing)
                if self._outcome is None and self.process.is_alive():
                    self.process.terminate()
                self.process.join()
            self.connection.close()
            self.process = None

    def __enter__(self) -> "ForkedCall":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
