"""The ``nonholo`` command line.

Each sub-command lives in its own module of this package and exposes
``register(subparsers)``; modules are discovered here so that adding a command never
edits this file. Exit codes: 0 success, 1 run-time failure, 2 bad input.

``main`` is also the last resort for what a command does not handle itself: a
``NonholoInputError`` is one line and exit 2, a ``SimulationError`` one line and exit 1,
Ctrl-C exit 130 (a command that starts processes also ends on SIGTERM or SIGHUP as on
Ctrl-C, with one line and exit 143 or 129: ``signals_interrupt``), and a reader that closes the pipe (``nonholo run … | head -2``) ends the
command quietly with exit 141, as a Unix tool killed by SIGPIPE does (the recipe of the
Python documentation, "Note on SIGPIPE": the rest of the output goes to the null device).
"""
from __future__ import annotations

import argparse
import atexit
import contextlib
import gc
import importlib
import os
import pkgutil
import re
import signal
import sys
import textwrap

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE


TERMINATING = ("SIGTERM", "SIGHUP")


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised in the main thread as Ctrl-C's KeyboardInterrupt is, so that
    every cleanup Ctrl-C runs (``finally`` blocks, reaping child processes) runs for it too."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextlib.contextmanager
def signals_interrupt():
    """Within: SIGTERM and SIGHUP (where the platform has them) raise ``Terminated`` in the
    main thread; once one has, the next ones are ignored so that the cleanup is not cut
    short. The previous handlers are restored on the way out."""
    signums = [getattr(signal, name) for name in TERMINATING if hasattr(signal, name)]
    previous = {signum: signal.getsignal(signum) for signum in signums}

    def interrupt(signum, frame):
        for other in signums:
            signal.signal(other, signal.SIG_IGN)
        raise Terminated(signum)

    for signum in signums:
        signal.signal(signum, interrupt)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


# Run as the ``nonholo`` program, the garbage collector looks at young objects every 2,000
# allocations instead of 700: importing numba, scipy and matplotlib, numba's compiler and
# matplotlib's figures make many short-lived containers, and with the default settings the
# collector's passes took about a tenth of a warm ``nonholo study``. (10,000 was no faster
# and let a first run's peak memory grow by 70 MB: numba's compiler leaves large cycles.)
# ``main`` sets it only when it parses the process's own arguments, not when called from Python.
PROGRAM_GC_THRESHOLD = (2_000, 10, 10)
# And at its exit, once the exit handlers registered during the command have run, everything
# still alive is frozen out of the collections that Python's shutdown runs (``gc.freeze``):
# they would traverse every object of sympy, numba, scipy and matplotlib to free memory that
# the operating system takes back at once anyway (0.4–0.5 s after a study). Objects are still
# freed by their reference counts; objects in reference cycles are left to the operating
# system, their finalizers not run (nonholo closes its files, sockets and processes itself).


# Run as the ``nonholo`` program, fresh memory is made cheaper to get (``tune_memory``):
# * glibc's malloc serves arrays of up to 32 MiB (its largest setting) from its heap and keeps
#   up to 256 MiB of freed memory there for the next ones, instead of mapping fresh pages for
#   every large array and returning them at every free. A recorded Test 1 run allocates ~9 MB
#   of tables and records; with glibc's adaptive thresholds they were faulted in page by page
#   at every run (2,245 page faults, 3.3 ms of a 7.7 ms run).
# * numpy does not advise the kernel to back arrays of 4 MB and more with transparent huge
#   pages where the kernel then compacts memory at the first touch (THP ``defrag`` set to
#   ``madvise``, ``defer+madvise`` or ``always``; ``madvise`` is the usual default): on this
#   kind of virtual machine the gain sweeps' reference tables (30–50 MB each) were written
#   at 140–200 ns a row instead of 23, 0.8 s of the leader study.
# Set only for the program (as ``PROGRAM_GC_THRESHOLD``); from Python, the environment
# variables MALLOC_MMAP_THRESHOLD_=33554432 MALLOC_TRIM_THRESHOLD_=268435456
# NUMPY_MADVISE_HUGEPAGE=0 do the same (docs/performance.md).
PROGRAM_MMAP_BYTES = 32 * 2**20
PROGRAM_TRIM_BYTES = 256 * 2**20
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3   # glibc's mallopt parameters (malloc.h)
_THP_DEFRAG = "/sys/kernel/mm/transparent_hugepage/defrag"


def tune_memory() -> dict[str, bool]:
    """Set this process's malloc thresholds (``PROGRAM_MMAP_BYTES``, ``PROGRAM_TRIM_BYTES``)
    where the C library is glibc, and turn numpy's huge-page advice off where the kernel
    would compact memory for it (see above); which of the two took."""
    import ctypes

    taken = {"malloc": False, "hugepages_off": False}
    try:
        mallopt = ctypes.CDLL(None).mallopt   # glibc's (musl's ignores these; none on macOS, Windows)
        mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
        taken["malloc"] = bool(mallopt(_M_MMAP_THRESHOLD, PROGRAM_MMAP_BYTES)) & \
            bool(mallopt(_M_TRIM_THRESHOLD, PROGRAM_TRIM_BYTES))
    except (OSError, AttributeError, TypeError):
        pass
    try:
        with open(_THP_DEFRAG) as handle:
            defrag = handle.read()
    except OSError:   # no transparent huge pages (not Linux)
        return taken
    if any(f"[{mode}]" in defrag for mode in ("madvise", "defer+madvise", "always")):
        try:
            from numpy._core.multiarray import _set_madvise_hugepage as switch   # numpy 2
        except ImportError:
            try:
                from numpy.core.multiarray import _set_madvise_hugepage as switch   # numpy 1.26
            except ImportError:
                return taken
        switch(False)
        taken["hugepages_off"] = True
    return taken


def processes_count(text: str) -> int:
    """``--processes N``: a whole number from 0 to ``MAX_PROCESSES`` (an argparse type)."""
    from nonholo.studies.forking import MAX_PROCESSES

    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= MAX_PROCESSES:
        raise argparse.ArgumentTypeError(f"expected a whole number from 0 to {MAX_PROCESSES}, got {text!r}")
    return value


@contextlib.contextmanager
def collector_for_long_work():
    """Leave what is alive now (the imported modules, numba's and matplotlib's own objects)
    out of every garbage collection until the block ends (``gc.freeze``): a long command's
    collections then look at its own objects only."""
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="nonholo",
        description="Collaborative nonholonomic robots: simulate, analyse and network "
        "unicycle leader-follower formations.",
    )
    from nonholo import __version__

    parser.add_argument("--version", action="version", version=f"nonholo {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module_info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if module_info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{module_info.name}")
        register = getattr(module, "register", None)
        if register is not None:
            register(subparsers)
    return parser


_QUANTITY = re.compile(r"(\d) (?=(?:s|m|m/s|rad|rad/s|steps?|robots?|time\(s\)|evaluations|generations|starts|"
                       r"samples|points|inputs)\b)")


def wrap(line: str, width: int = 100) -> str:
    """``line`` wrapped to ``width`` columns (continuation lines indented), never between a
    number and its unit."""
    if len(line) <= width:
        return line
    kept = _QUANTITY.sub("\\1\u00a0", line)   # a no-break space: textwrap does not break there
    return textwrap.fill(kept, width, subsequent_indent="    ", break_on_hyphens=False).replace("\u00a0", " ")


def announce_compiling(prog: str) -> None:
    """On a terminal, say once when numba starts compiling (its ``numba:compile`` event fires
    on cache misses only: the first run after an install or an update), so that a first run
    is not a silent pause of seconds."""
    if not sys.stderr.isatty():
        return
    from numba.core import event

    class FirstCompile(event.Listener):
        said = False

        def on_start(self, ev):
            if not self.said:
                self.said = True
                from tqdm import tqdm   # (written above an open progress bar, not through it)

                tqdm.write(f"{prog}: compiling for this machine (cached for the next runs) …", file=sys.stderr)

        def on_end(self, ev):
            pass

    event.register("numba:compile", FirstCompile())


def main(argv: list[str] | None = None) -> int:
    from nonholo.errors import NonholoInputError, SimulationError

    prog = "nonholo"
    if argv is None:   # the program itself (see PROGRAM_GC_THRESHOLD, tune_memory)
        gc.set_threshold(*PROGRAM_GC_THRESHOLD)
        atexit.register(gc.freeze)   # runs after the exit handlers registered later (by the command)
        tune_memory()
    try:
        try:
            parser = build_parser()
            args = parser.parse_args(argv)
            if getattr(args, "handler", None) is None:
                parser.print_help()
                return EXIT_BAD_INPUT
            prog = f"nonholo {args.command}"
            if argv is None and args.command != "study":   # (the study's progress names what compiles)
                announce_compiling(prog)
            return int(args.handler(args) or EXIT_OK)
        finally:
            sys.stdout.flush()  # a closed pipe shows here, not at exit (also after --help's SystemExit)
    except BrokenPipeError:
        _discard_stdout()
        return EXIT_BROKEN_PIPE
    except Terminated as exc:
        print(f"{prog}: ended by {signal.Signals(exc.signum).name}; every process it started was stopped",
              file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except NonholoInputError as exc:
        _error_line(prog, exc)
        return EXIT_BAD_INPUT
    except SimulationError as exc:
        _error_line(prog, exc)
        return EXIT_FAILURE


def _error_line(prog: str, exc: Exception) -> None:
    message = " ".join(str(exc).split())  # one line, whatever the message holds
    print(f"{prog}: error: {message}", file=sys.stderr)


def _discard_stdout() -> None:
    """Point standard output at the null device, so that flushing what is left at exit
    raises no second BrokenPipeError."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (AttributeError, OSError, ValueError):  # no file descriptor (a captured or replaced stream)
        pass


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
