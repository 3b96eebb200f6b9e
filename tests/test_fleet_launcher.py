"""The launcher's end (`nonholo fleet`): SIGTERM and SIGHUP end it as Ctrl-C does (every
robot process reaped, the private folder with its keys removed, one line, exit 128 + the
signal); when the launcher is killed outright its robots die with it (Linux); and
`nonholo bench-fleet` fails with one line."""
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import nonholo.cli
from nonholo.fleet.bench import star_text
from nonholo.fleet.config import load_fleet
from nonholo.fleet.launch import run_fleet

NAMES = ("leader", "f1")
# A leader on the circle and one follower (nonholo.fleet.bench.star_text), run long enough
# to be signalled mid-run.
SCENARIO = star_text(1).replace("duration = 2.0", "duration = 60.0\ndt = 0.02\ncontrol_period = 0.02")
START_S = 15.0     # bound on the robots' start (Pythons importing numba on a loaded machine)
END_S = 4.0        # bound on the launcher's end after the signal (grace 1 s, then SIGKILL)


@pytest.fixture(scope="module")
def scenario_file(tmp_path_factory):
    """The scenario, with what the robot processes run compiled first (numba caches it)."""
    folder = tmp_path_factory.mktemp("signals")
    short = folder / "short.toml"
    short.write_text(SCENARIO.replace("duration = 60.0", "duration = 0.2"))
    scenario, config = load_fleet(short)
    run_fleet(scenario, "inproc", "realtime", config=config)
    path = folder / "signals.toml"
    path.write_text(SCENARIO)
    return path


def robot_pids(folder: Path) -> list[int]:
    """Processes whose command line names ``folder`` (the robots: their keys and traces are there)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if str(folder).encode() in (entry / "cmdline").read_bytes():
                    pids.append(int(entry.name))
            except OSError:
                pass
    return pids


def alive(pid: int) -> bool:
    """Running (a zombie has ended)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def wait_until(condition, bound: float) -> bool:
    deadline = time.monotonic() + bound
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def start_launcher(path: Path, tmp: Path):
    """`nonholo fleet` in realtime with its temporary folder under ``tmp``; (process, folder,
    robot pids) once every robot runs."""
    env = dict(os.environ, TMPDIR=str(tmp))
    launcher = subprocess.Popen([sys.executable, "-m", "nonholo", "fleet", str(path), "--mode", "realtime"],
                                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)

    def running() -> bool:
        assert launcher.poll() is None, launcher.communicate()[1].decode(errors="replace")[-500:]
        folders = list(tmp.glob("nonholo-fleet-*"))
        errs = [folders[0] / f"{n}.err" for n in NAMES] if folders else []
        return bool(errs) and all(e.exists() and "running at" in e.read_text(errors="replace") for e in errs)
    return launcher, running


@pytest.fixture
def launched(scenario_file, tmp_path):
    """Start the launcher; afterwards kill whatever of it or its robots is left (by pid)."""
    started = []

    def launch():
        launcher, running = start_launcher(scenario_file, tmp_path)
        started.append((launcher, []))
        assert wait_until(running, START_S), "the robots did not start in time"
        folder = next(tmp_path.glob("nonholo-fleet-*"))
        pids = robot_pids(folder)
        started[-1][1].extend(pids)
        assert len(pids) == len(NAMES)
        return launcher, folder, pids
    yield launch
    for launcher, pids in started:
        if launcher.poll() is None:
            launcher.kill()
        launcher.communicate()
        for pid in pids:
            if alive(pid):
                os.kill(pid, signal.SIGKILL)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_sigterm_or_sighup_ends_the_launcher_as_ctrl_c_does(launched, signum):
    launcher, folder, pids = launched()
    launcher.send_signal(signum)
    _, err = launcher.communicate(timeout=END_S + 5.0)
    assert launcher.returncode == 128 + signum
    lines = err.decode(errors="replace").strip().splitlines()
    # what it started (a line for logs), then how it ended
    assert lines == [f"nonholo fleet: {len(NAMES)} robot programs (tcp, realtime), 60 s of robot time",
                     f"nonholo fleet: ended by {signal.Signals(signum).name}; every process it started was stopped"]
    assert wait_until(lambda: not any(alive(pid) for pid in pids), END_S)
    assert not folder.exists()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux only")
def test_robots_die_with_a_killed_launcher(launched):
    launcher, folder, pids = launched()
    launcher.kill()           # no cleanup at all: the robots get SIGTERM from the kernel
    launcher.wait(timeout=5.0)
    assert wait_until(lambda: not any(alive(pid) for pid in pids), END_S)
    shutil.rmtree(folder, ignore_errors=True)   # nobody was left to remove it


def test_bench_fleet_failure_is_one_line_exit_1(monkeypatch, capsys):
    from nonholo.fleet import bench

    def fail(*args, **kwargs):
        raise OSError(24, "Too many open files")
    monkeypatch.setattr(bench, "run_bench", fail)
    assert nonholo.cli.main(["bench-fleet", "--rates", "100", "--latency-only"]) == 1
    err = capsys.readouterr().err
    assert err == "nonholo bench-fleet: OSError: [Errno 24] Too many open files\n"


def test_bench_fleet_bad_rate_is_one_line_exit_2(capsys):
    assert nonholo.cli.main(["bench-fleet", "--rates", "0"]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_a_fleet_too_large_to_keep_is_refused_in_one_line_before_it_plans(tmp_path, capsys):
    """Two robots for 2e6 s at dt = 0.02 s: the states a fleet keeps would need ~38 GiB. As
    ``nonholo run`` does, the fleet refuses it in one line (exit 2), before planning (which
    would allocate a table of the whole horizon and die with a MemoryError traceback)."""
    from view_fleets import chain_toml

    path = tmp_path / "long.toml"
    path.write_text(chain_toml(2e6, followers=1))
    assert nonholo.cli.main(["fleet", str(path), "--transport", "inproc", "--quiet", "--json"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "would need" in err and "Traceback" not in err
