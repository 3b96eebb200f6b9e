"""Work in forked processes (``nonholo.studies.forking``): the report's figures, the same
files as drawn at once; a call's value or its exception; failures as one line; nothing left
running."""
from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from nonholo.studies.forking import Drawing, ForkedCall, draw_now, forking

needs_fork = pytest.mark.skipif(not forking(), reason="figures are drawn in forked processes on Linux only")


def _plot(values, path):
    from nonholo.studies.plots import plt, save_figure

    fig, ax = plt.subplots(figsize=(3, 2))
    ax.plot(values, label=f"{len(values)} values")
    ax.legend()
    save_figure(fig, path)


def _write_pid(path):
    Path(path).write_text(str(os.getpid()))


def _append_pid_slowly(path):
    time.sleep(0.05)
    with open(path, "a") as handle:
        handle.write(f"{os.getpid()}\n")


def _fail(path):
    raise ValueError(f"no data for\n{Path(path).name}")


def _vanish(path):
    os._exit(3)


def _sleep(path):
    time.sleep(60)


def _reaped(prefix="nonholo-figures"):
    """No such child of this process is left (``active_children`` also reaps)."""
    return [p for p in multiprocessing.active_children() if p.name.startswith(prefix)] == []


@needs_fork
def test_figures_drawn_in_children_are_the_files_drawn_at_once(tmp_path):
    here, there = tmp_path / "here", tmp_path / "there"
    here.mkdir()
    there.mkdir()
    data = [list(range(n)) for n in (3, 50, 7, 400, 12)]
    for i, values in enumerate(data):
        draw_now(_plot, values, here / f"f{i}.png")
    with Drawing(2) as drawing:
        for i, values in enumerate(data):
            drawing(_plot, values, there / f"f{i}.png")
        drawing(_write_pid, there / "pid-a")
        drawing(_write_pid, there / "pid-b")
        assert drawing.pending() == 7
        drawing.start("section")
        result = drawing.finish()
    assert result["section"]["figures"] == 7 and result["section"]["seconds"] > 0
    assert drawing.pending() == 0
    for i in range(len(data)):
        assert (there / f"f{i}.png").read_bytes() == (here / f"f{i}.png").read_bytes()
    pids = {int((there / name).read_text()) for name in ("pid-a", "pid-b")}
    assert os.getpid() not in pids
    assert _reaped()


@needs_fork
def test_sections_share_the_processes_and_each_is_timed(tmp_path):
    with Drawing(2) as drawing:
        for section in ("a", "b", "c"):
            for i in range(3):
                drawing(_append_pid_slowly, tmp_path / f"{section}{i}")
            drawing.start(section)
            assert len(drawing.running) <= 2
        result = drawing.finish()
    assert sorted(result) == ["a", "b", "c"]
    assert all(entry["figures"] == entry["drawn"] == 3 and entry["seconds"] >= 0.05 for entry in result.values())
    # every figure drawn, each once (a section's children share its counter, not another's)
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"{s}{i}" for s in "abc" for i in range(3)]
    assert all(len(p.read_text().split()) == 1 for p in tmp_path.iterdir())
    assert _reaped()


def test_without_processes_figures_are_drawn_at_once_in_order(tmp_path):
    order = []
    drawing = Drawing(0)
    for name in ("one", "two", "three"):
        drawing(order.append, name)
    assert order == []
    drawing.start("section")
    assert order == ["one", "two", "three"]
    assert drawing.finish()["section"]["figures"] == 3


@needs_fork
def test_a_failing_figure_is_one_line_naming_it_and_no_child_is_left(tmp_path):
    drawing = Drawing(2)
    for i in range(4):
        drawing(_sleep if i == 3 else _write_pid, tmp_path / f"x{i}")
    drawing(_fail, tmp_path / "bad.png")
    drawing.start("section")
    with pytest.raises(RuntimeError) as caught:
        drawing.finish()
    message = str(caught.value)
    assert message == "figure _fail failed: no data for bad.png"
    assert _reaped()


@needs_fork
def test_a_child_that_vanishes_is_reported_with_its_exit_code(tmp_path):
    drawing = Drawing(1)
    drawing(_vanish, tmp_path / "gone.png")
    drawing.start("section")
    with pytest.raises(RuntimeError, match=r"figures of section: the drawing process ended without a word "
                                           r"\(exit code 3\)"):
        drawing.finish()
    assert _reaped()


@needs_fork
def test_close_stops_drawing_at_once(tmp_path):
    drawing = Drawing(2)
    drawing(_sleep, tmp_path / "a")
    drawing(_sleep, tmp_path / "b")
    drawing.start("section")
    assert len(drawing.running) == 2
    started = time.perf_counter()
    drawing.close()
    assert time.perf_counter() - started < 10
    assert drawing.running == [] and _reaped()


def test_a_bad_process_count_is_refused():
    from nonholo.errors import NonholoInputError
    from nonholo.studies import StudyOptions

    with pytest.raises(ValueError, match="processes must be a whole number"):
        Drawing(-1)
    with pytest.raises(NonholoInputError, match="processes must be a whole number from 0 to 16"):
        StudyOptions(Path("x"), processes=17)
    run = subprocess.run([sys.executable, "-m", "nonholo", "study", "--processes", "two", "--out", "x"],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert "--processes: expected a whole number from 0 to 16, got 'two'" in run.stderr
    assert "Traceback" not in run.stderr


@needs_fork
def test_the_report_waits_for_its_figures_and_keeps_sections_that_draw_themselves(tmp_path):
    from nonholo.studies import StudyOptions
    from nonholo.studies.report import ReportWriter

    class Drawn:
        name, title, elapsed_s, spec_file = "drawn", "Drawn", 0.5, "leader.md"

        def write_data(self, folder):
            return []

        def html_section(self, folder, draw=draw_now):
            for i in range(3):
                draw(_plot, [1, 2, i], folder / f"p{i}.png")
            return "<p>three figures</p>"

    class Itself(Drawn):   # a study written before ``draw``: it draws its figure itself
        name, title = "itself", "Itself"

        def html_section(self, folder):
            _plot([4, 5], folder / "own.png")
            return "<p>its own figure</p>"

    options = StudyOptions(tmp_path, progress=False, processes=2)
    with ReportWriter(tmp_path, options) as writer:
        writer.add(Drawn())
        writer.add(Itself())
        page = writer.finish().read_text(encoding="utf-8")
    assert all((tmp_path / "drawn" / f"p{i}.png").stat().st_size > 1000 for i in range(3))
    assert (tmp_path / "itself" / "own.png").stat().st_size > 1000
    assert "(wall time), its 3 figures" in page and "(wall time).</p><p>its own figure" in page
    assert _reaped()


class Unpicklable(Exception):
    def __init__(self, message, handle):
        super().__init__(message)
        self.handle = handle

    def __reduce__(self):
        raise TypeError("cannot pickle a handle")


@needs_fork
def test_a_forked_call_returns_its_value_from_another_process():
    parent = os.getpid()
    with ForkedCall(lambda: {"pid": os.getpid(), "values": list(range(5))}) as call:
        value = call.result()
        assert call.result() is value   # asked again: the same value, no second run
    assert value["values"] == [0, 1, 2, 3, 4] and value["pid"] != parent
    assert call.process is None and _reaped("nonholo-call")


@needs_fork
def test_a_forked_call_raises_the_child_s_exception_in_the_parent():
    from nonholo.errors import NonholoInputError

    def bad_input():
        raise NonholoInputError("scenario.toml: [reference] kind: expected one of line, circle")

    call = ForkedCall(bad_input)
    for _ in range(2):   # at every call
        with pytest.raises(NonholoInputError, match=r"^scenario.toml: \[reference\] kind: expected"):
            call.result()

    def unpicklable():
        raise Unpicklable("a socket\nbroke", object())

    with pytest.raises(RuntimeError, match=r"^test_a_forked_call_raises.*unpicklable failed: a socket broke$"):
        ForkedCall(unpicklable).result()
    with pytest.raises(RuntimeError, match=r"its process ended without a word \(exit code 5\)"):
        ForkedCall(lambda: os._exit(5)).result()
    assert _reaped("nonholo-call")


@needs_fork
def test_a_forked_call_closed_unanswered_is_stopped():
    call = ForkedCall(lambda: time.sleep(60))
    started = time.perf_counter()
    call.close()
    assert time.perf_counter() - started < 10 and _reaped("nonholo-call")


def test_without_processes_a_call_runs_here_when_asked():
    ran = []
    call = ForkedCall(lambda: ran.append(os.getpid()) or "value", processes=0)
    assert ran == [] and call.process is None
    assert call.result() == "value" and call.result() == "value"
    assert ran == [os.getpid()]


def _delayed_draw_calls(original):
    def delayed(calls, *rest):   # a child scheduled late, as on a loaded machine
        time.sleep(0.4 if Path(calls[0][1][0]).name.startswith("A") else 0.0)
        original(calls, *rest)
    return delayed


def _slow_append(path):
    time.sleep(1.0)
    _append_pid_slowly(path)


@needs_fork
def test_a_section_s_children_share_its_counter_whatever_their_timing(tmp_path, monkeypatch):
    import nonholo.studies.forking as forking

    monkeypatch.setattr(forking, "_draw_calls", _delayed_draw_calls(forking._draw_calls))
    with Drawing(2) as drawing:
        drawing(_slow_append, tmp_path / "P0")
        drawing.start("P")                      # one process busy for a second
        drawing(_append_pid_slowly, tmp_path / "A0")
        drawing(_append_pid_slowly, tmp_path / "A1")
        drawing.start("A")                      # waits for two free processes, then forks both
        drawing(_append_pid_slowly, tmp_path / "B0")
        drawing(_append_pid_slowly, tmp_path / "B1")
        drawing.start("B")
        result = drawing.finish()
    assert all(entry["drawn"] == entry["figures"] for entry in result.values())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["A0", "A1", "B0", "B1", "P0"]
    assert all(len(p.read_text().split()) == 1 for p in tmp_path.iterdir())   # each drawn once
    assert _reaped()


@needs_fork
def test_input_errors_from_a_forked_call_keep_their_type_and_fields():
    import functools

    from nonholo.errors import FormationError, InputFileError, ScenarioError

    def raise_(exc):
        raise exc

    for exc in (ScenarioError("a.toml", "robots[0].gains.kp", "expected a number > 0, got -1"),
                FormationError("f1", "leaders", "unknown robot 'ghost'"),
                InputFileError("b.toml", "not valid TOML (line 3)")):
        with pytest.raises(type(exc)) as caught:
            ForkedCall(functools.partial(raise_, exc)).result()
        assert str(caught.value) == str(exc) and caught.value.__dict__ == exc.__dict__


def _children_of_command(marker: str) -> list[int]:
    """Processes whose command line holds ``marker`` (a forked child keeps its parent's)."""
    found = []
    for pid in os.listdir("/proc"):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as handle:
                if marker.encode() in handle.read():
                    found.append(int(pid))
        except (OSError, ValueError):
            pass
    return found


def _wait_gone(marker: str, seconds: float = 5.0) -> list[int]:
    deadline = time.monotonic() + seconds
    while _children_of_command(marker) and time.monotonic() < deadline:
        time.sleep(0.1)
    return _children_of_command(marker)


@needs_fork
@pytest.mark.parametrize("signum, code", [(15, 143), (1, 129), (9, -9)])
def test_no_helper_outlives_a_stopped_study(tmp_path, signum, code):
    out = tmp_path / f"report-{signum}"
    command = [sys.executable, "-m", "nonholo", "study", "--quick", "--quiet", "--out", str(out)]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120   # stopped once helpers run (compiling ahead, the leader's sweeps)
        while len(_children_of_command(str(out))) < 2 and time.monotonic() < deadline and process.poll() is None:
            time.sleep(0.05)
        assert len(_children_of_command(str(out))) >= 2, "no helper process was seen"
        os.kill(process.pid, signum)
        _, err = process.communicate(timeout=60)
        assert process.returncode == code
        assert "Traceback" not in err
        assert _wait_gone(str(out)) == []
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        for pid in _children_of_command(str(out)):
            os.kill(pid, 9)


def test_a_tabulated_study_written_before_draw_still_draws_its_figures(tmp_path):
    from nonholo.studies.framework import TabulatedStudyResult
    from nonholo.studies.report import section_html

    class Older(TabulatedStudyResult):
        name, title, elapsed_s, runs, findings, quick = "older", "Older", 0.1, {}, [], False

        def tables(self):
            return []

        def setup_text(self):
            return "set-up"

        def write_figures(self, folder):   # no ``draw``: it draws at once, as before
            _plot([1, 3, 2], folder / "older.png")
            return [("older.png", "its figure")]

    drawing = Drawing(2)
    html = section_html(Older(), tmp_path, drawing)
    assert (tmp_path / "older.png").stat().st_size > 1000 and "its figure" in html
    assert drawing.pending() == 0


@needs_fork
def test_sections_of_the_same_name_keep_their_own_counts(tmp_path):
    with Drawing(3) as drawing:
        drawing(_append_pid_slowly, tmp_path / "a")
        drawing(_append_pid_slowly, tmp_path / "b")
        drawing.start("leader")
        drawing(_append_pid_slowly, tmp_path / "c")
        drawing.start("leader")
        result = drawing.finish()
    assert {name: (e["figures"], e["drawn"]) for name, e in result.items()} == {"leader": (2, 2),
                                                                                 "leader (2)": (1, 1)}
    assert all(len(p.read_text().split()) == 1 for p in tmp_path.iterdir())


@needs_fork
def test_figures_started_from_another_thread_outlive_that_thread(tmp_path):
    import threading

    drawing = Drawing(2)
    drawing(_append_pid_slowly, tmp_path / "a")
    drawing(_slow_append, tmp_path / "b")   # still drawing when the thread that forked it has ended
    thread = threading.Thread(target=drawing.start, args=("section",))
    thread.start()
    thread.join()
    assert drawing.finish()["section"]["drawn"] == 2
    assert _reaped()


def _in_a_daemon(queue):
    queue.put((forking(), ForkedCall(lambda: os.getpid()).result() == os.getpid()))


@needs_fork
def test_a_daemonic_worker_computes_here_instead_of_forking():
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    worker = context.Process(target=_in_a_daemon, args=(queue,), daemon=True)
    worker.start()
    try:
        assert queue.get(timeout=30) == (False, True)
    finally:
        worker.join(30)


# ------------------------------------------------------------------ compiling ahead

def _study(name, order, tmp_path, warm_up=None, wait=False):
    from nonholo.studies.base import Study, StudyResult

    class Done(StudyResult):
        title, elapsed_s = name, 0.0
        text = html_section = write_data = to_dict = lambda self, *args, **kwargs: None

    def run(options):
        if wait:   # the child runs the later warm-ups meanwhile, in order: wait for the last one
            deadline = time.monotonic() + 60
            while len(_read(tmp_path / "fourth").split()) < 3 and time.monotonic() < deadline:
                time.sleep(0.01)
        result = Done()
        result.name = name
        return result

    return Study(name=name, title=name, summary=name, run=run, order=order, warm_up=warm_up)


def _read(path) -> str:
    try:
        return path.read_text()
    except FileNotFoundError:
        return ""


def _warm_up_writing(path, fail=False):
    def warm_up(options):
        path.write_text(f"{os.getpid()} {os.nice(0)} {options.quick}")
        if fail:
            raise RuntimeError("a warm-up that fails")
    return warm_up


@needs_fork
@pytest.mark.parametrize("processes", [0, 2])
def test_later_studies_warm_up_in_a_lower_priority_child_while_the_first_runs(tmp_path, monkeypatch, processes):
    from nonholo.studies import report
    from nonholo.studies.base import StudyOptions

    studies = [_study("first", 1, tmp_path, _warm_up_writing(tmp_path / "never"), wait=processes > 0),  # no need
               _study("second", 2, tmp_path, warm_up=_warm_up_writing(tmp_path / "second", fail=True)),
               _study("third", 3, tmp_path),
               _study("fourth", 4, tmp_path, warm_up=_warm_up_writing(tmp_path / "fourth"))]
    monkeypatch.setattr(report, "chosen_studies", lambda names: studies)
    options = StudyOptions(tmp_path / "out", quick=True, progress=False, processes=processes)
    names = [result.name for result in report.each_result(None, options)]
    assert names == ["first", "second", "third", "fourth"]
    assert not (tmp_path / "never").exists() and _reaped("nonholo-compile-ahead")
    if processes == 0:   # nothing beside the studies: no warm-up at all
        assert not (tmp_path / "second").exists() and not (tmp_path / "fourth").exists()
        return
    for name in ("second", "fourth"):   # the failing one did not stop the next
        pid, nice, quick = (tmp_path / name).read_text().split()
        assert int(pid) != os.getpid() and quick == "True"
        assert int(nice) == min(19, os.nice(0) + report.AHEAD_NICE)


WARMED = """
import gc, sys
import numba
from nonholo.studies.base import StudyOptions
from nonholo.studies.{module} import STUDY

def overloads():
    return sum(len(d.overloads) for d in gc.get_objects() if isinstance(d, numba.core.registry.CPUDispatcher))

options = StudyOptions(sys.argv[1], quick=True, progress=False)
STUDY.warm_up(options)
warmed = overloads()
STUDY.run(options)
print(warmed, overloads())
"""


@pytest.mark.parametrize("module", ["formation", "posture"])
def test_a_study_s_warm_up_compiles_every_kernel_its_run_uses(tmp_path, module):
    # in a fresh process: its run adds no compiled function to those of its warm-up (each
    # one loaded from the disk cache, or compiled, by the warm-up)
    done = subprocess.run([sys.executable, "-c", WARMED.format(module=module), str(tmp_path)], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    warmed, after = map(int, done.stdout.split()[-2:])
    assert warmed > 0 and after == warmed
