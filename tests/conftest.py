import contextlib
import math
import os
import shutil
import sys
import tempfile
from html.parser import HTMLParser
from pathlib import Path

import pytest

SPEC = Path(__file__).resolve().parents[1].parent / "shared" / "spec"

# The suite runs in two pytest-xdist workers, a test file each at a time (pyproject's addopts;
# ``-n 0`` runs it in one process). Most of it is numba compiling a kernel per law, one core's
# work each. The files below run robots on the wall clock (fleets of processes, paced runs,
# live servers, timed links) or a browser: their tests run *alone on the machine*. Each test
# holds a lock between the workers around its setup, call and teardown, shared for other tests
# and exclusive for these, and an exclusive request goes first (``MachineLock``). Beside the
# other worker's compiling, such tests once failed in 3 of 10 runs (a restarted robot came up
# after its followers' run had ended; a paced run's snapshots fell 0.127 s apart; a live page
# showed 6 of 8 robots by its deadline), even with the files kept in one worker.
ON_THE_CLOCK = frozenset({"test_fleet_faults.py", "test_fleet_telemetry.py", "test_fleet_launcher.py",
                          "test_view_processes.py", "test_view_browser.py", "test_view_server.py",
                          "test_view_foxglove.py", "test_comm_transports.py", "test_comm_hub_attacks.py"})
LOCK_DIR = "nonholo_machine_lock"   # the workers' input: the folder of the lock's two files


class MachineLock:
    """A readers-writer lock between the processes of one test run, on two files (``flock``):
    a test holds ``tests`` shared, or exclusive when it must run alone; ``gate`` makes an
    exclusive request wait for the tests running now, not for the ones that would start
    after them (a worker takes ``gate`` before ``tests``; the exclusive holder keeps it)."""

    def __init__(self, folder: Path):
        self.gate = open(folder / "gate", "a+b")
        self.tests = open(folder / "tests", "a+b")

    @contextlib.contextmanager
    def hold(self, alone: bool):
        import fcntl   # POSIX: elsewhere the suite runs in one process (pytest_configure)

        fcntl.flock(self.gate, fcntl.LOCK_EX)
        try:
            fcntl.flock(self.tests, fcntl.LOCK_EX if alone else fcntl.LOCK_SH)
        except BaseException:   # (interrupted while waiting: the gate is not kept)
            fcntl.flock(self.gate, fcntl.LOCK_UN)
            raise
        if not alone:
            fcntl.flock(self.gate, fcntl.LOCK_UN)
        try:
            yield
        finally:
            fcntl.flock(self.tests, fcntl.LOCK_UN)
            if alone:
                fcntl.flock(self.gate, fcntl.LOCK_UN)

    def close(self):
        self.gate.close()
        self.tests.close()


_LOCK = pytest.StashKey[MachineLock]()   # a worker's lock
_FOLDER = pytest.StashKey[Path]()        # the controller's folder of the lock's files


def pytest_configure(config):
    config.addinivalue_line("markers", "on_the_clock: runs robots on the wall clock or a browser; "
                                       "runs alone on the machine when the suite runs in workers")
    worker = getattr(config, "workerinput", None)
    if worker is not None and worker.get(LOCK_DIR):
        lock = config.stash[_LOCK] = MachineLock(Path(worker[LOCK_DIR]))
        # a child a test forks (multiprocessing) shares the lock's open files: closed there,
        # so that a child outliving a crashed worker cannot keep the lock held
        os.register_at_fork(after_in_child=lock.close)
    elif worker is None and getattr(config.option, "numprocesses", None) and sys.platform != "win32":
        config.stash[_FOLDER] = Path(tempfile.mkdtemp(prefix="nonholo-tests-"))   # (no flock there)


def pytest_unconfigure(config):
    lock = config.stash.get(_LOCK, None)
    if lock is not None:
        lock.close()
    folder = config.stash.get(_FOLDER, None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node):
    """xdist, in the controller: every worker gets the lock's folder."""
    folder = node.config.stash.get(_FOLDER, None)
    if folder is not None:
        node.workerinput[LOCK_DIR] = str(folder)


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.name in ON_THE_CLOCK:
            item.add_marker(pytest.mark.on_the_clock)
    # they come last (the workers take files in this order: --no-loadscope-reorder): by then
    # the other files have compiled most kernels they use, in both workers at once, and the
    # workers hand over to them once, not at every such file
    items.sort(key=lambda item: item.path.name in ON_THE_CLOCK)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item, nextitem):
    lock = item.config.stash.get(_LOCK, None)
    if lock is None:
        return (yield)
    with lock.hold(alone=item.get_closest_marker("on_the_clock") is not None):
        return (yield)


@pytest.fixture(scope="session")
def spec_dir():
    if not SPEC.is_dir():
        pytest.skip("../shared/spec not present")
    return SPEC


def pose_from_errors(ref_row, e1, e2, e3):
    """The robot pose whose tracking errors against ``ref_row`` are (e1, e2, e3)."""
    theta = ref_row[7] - e3
    c, s = math.cos(theta), math.sin(theta)
    return ref_row[1] - (c * e1 - s * e2), ref_row[2] - (s * e1 + c * e2), theta


class ReportPage(HTMLParser):
    """What the report tests look at in an HTML page: images, outward links, section ids,
    the number of tables and the text."""

    def __init__(self, html: str):
        super().__init__()
        self.images, self.links, self.sections, self.tables, self.text = [], [], [], 0, []
        self.feed(html)
        self.close()

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img":
            self.images.append(attrs["src"])
        elif tag == "a" and not attrs["href"].startswith("#"):
            self.links.append(attrs["href"])
        elif tag == "section":
            self.sections.append(attrs["id"])
        elif tag == "table":
            self.tables += 1

    def handle_data(self, data):
        self.text.append(data)
