"""The lock that lets the suite run in two workers (tests/conftest.py, ``MachineLock``): a test
on the wall clock runs alone; it waits for the tests running now, not for those that start
after it asked; other tests run side by side."""
import sys
import threading
import time

import pytest

from tests.conftest import MachineLock

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="flock is POSIX")


def held(path) -> bool:
    """Whether another open file holds ``path``'s lock (probed without waiting)."""
    import fcntl

    with open(path, "a+b") as probe:
        try:
            fcntl.flock(probe, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        fcntl.flock(probe, fcntl.LOCK_UN)
        return False


def until(condition, seconds=10.0):
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.005)


def started(folder, alone, log, name, inside=False):
    """A ``Holder`` started (and, if ``inside``, once it holds the lock)."""
    holder = Holder(folder, alone, log, name)
    holder.start()
    assert not inside or holder.inside.wait(10)
    return holder


class Holder(threading.Thread):
    """A worker's test: holds its own ``MachineLock`` (its own open files) until released."""

    def __init__(self, folder, alone, log, name):
        super().__init__(daemon=True)
        self.lock, self.alone, self.log, self.label = MachineLock(folder), alone, log, name
        self.inside, self.release = threading.Event(), threading.Event()

    def run(self):
        with self.lock.hold(alone=self.alone):
            self.log.append(f"{self.label} in")
            self.inside.set()
            self.release.wait(10)
            self.log.append(f"{self.label} out")
        self.lock.close()


def test_tests_off_the_clock_run_side_by_side(tmp_path):
    log = []
    first, second = started(tmp_path, False, log, "a"), started(tmp_path, False, log, "b")
    assert first.inside.wait(10) and second.inside.wait(10)   # both inside at once
    first.release.set()
    second.release.set()
    first.join(10)
    second.join(10)
    assert sorted(log) == ["a in", "a out", "b in", "b out"]


def test_a_test_on_the_clock_waits_for_the_running_test_then_runs_alone_and_goes_first(tmp_path):
    log = []
    running = started(tmp_path, False, log, "running", inside=True)
    clock = started(tmp_path, True, log, "clock")
    until(lambda: held(tmp_path / "gate"))            # it asked: holds the gate, waits for the tests
    later = started(tmp_path, False, log, "later")
    time.sleep(0.2)
    assert log == ["running in"]                      # neither the clock test nor the later one
    running.release.set()
    assert clock.inside.wait(10)
    time.sleep(0.2)
    assert log == ["running in", "running out", "clock in"]   # alone: the later test still waits
    clock.release.set()
    assert later.inside.wait(10)
    later.release.set()
    for thread in (running, clock, later):
        thread.join(10)
    assert log == ["running in", "running out", "clock in", "clock out", "later in", "later out"]
    assert not held(tmp_path / "gate") and not held(tmp_path / "tests")


def test_two_tests_on_the_clock_run_one_after_the_other(tmp_path):
    log = []
    first = started(tmp_path, True, log, "first", inside=True)
    second = started(tmp_path, True, log, "second")
    time.sleep(0.2)
    assert log == ["first in"]
    first.release.set()
    assert second.inside.wait(10)
    second.release.set()
    first.join(10)
    second.join(10)
    assert log == ["first in", "first out", "second in", "second out"]


def test_a_failing_test_releases_the_lock(tmp_path):
    lock = MachineLock(tmp_path)
    with pytest.raises(RuntimeError):
        with lock.hold(alone=True):
            raise RuntimeError("the test failed")
    lock.close()
    assert not held(tmp_path / "gate") and not held(tmp_path / "tests")
