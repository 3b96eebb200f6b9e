"""The Dask path gives the local path's --json (apart from ``timing``): a LocalCluster of two
worker processes bound to 127.0.0.1, dashboard off, closed (and its processes reaped) after."""
import json
import os
import time

import pytest

from nonholo.cli import main
from nonholo.studies import distributed

distributed_module = pytest.importorskip("distributed")
psutil = pytest.importorskip("psutil")

LINE = """name = "line-dfl"
[simulation]
duration = 20.0
dt = 0.01
[reference]
kind = "line"
[[robots]]
name = "leader"
controller = "dynamic-feedback"
gains = { kp = 1.0, kd = 0.7, xi0 = 0.5 }
[[robots]]
name = "kanayama"
controller = "kanayama"
"""


@pytest.fixture(scope="module")
def scheduler():
    cluster = distributed_module.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                              dashboard_address=None)
    with distributed_module.Client(cluster) as client:
        pids = list(client.run(os.getpid).values())
    try:
        yield cluster.scheduler_address
    finally:
        cluster.close()
        deadline = time.monotonic() + 10
        while any(psutil.pid_exists(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(psutil.pid_exists(p) for p in pids), "worker processes left running"


def cli_json(capsys, *argv):
    assert main(list(argv)) == 0
    out = json.loads(capsys.readouterr().out)
    out.pop("timing")
    return out


def test_chunks_are_worth_sending():
    bounds = distributed.chunk_bounds(10_000, 2000.0)   # 2000 robot-steps per sample
    assert bounds[0] == (0, bounds[0][1]) and bounds[-1][1] == 10_000
    sizes = [b - a for a, b in bounds]
    assert min(sizes) * 2000.0 / distributed.NOMINAL_ROBOT_STEPS_PER_S >= distributed.MIN_CHUNK_SECONDS
    assert max(sizes) - min(sizes) <= 1


def test_montecarlo_sweep_and_tune_match_the_local_path(tmp_path, capsys, scheduler, monkeypatch):
    monkeypatch.setattr(distributed, "CHUNK_SECONDS", 0.002)      # several chunks even for this short study
    monkeypatch.setattr(distributed, "MIN_CHUNK_SECONDS", 0.002)
    path = str(tmp_path / "line.toml")
    (tmp_path / "line.toml").write_text(LINE)
    runs = {
        "montecarlo": ["montecarlo", path, "--samples", "300", "--vary", "leader.start.x=normal(0, 0.5)", "--vary",
                       "kanayama.gains.kx=uniform(1, 20)", "--seed", "5", "--json", "--quiet"],
        "sweep": ["sweep", path, "--robot", "kanayama", "--gain", "kx=1:20:25", "--json", "--quiet"],
        "tune": ["tune", path, "--gains", "kp,kd", "--bounds", "kp=0.5:3", "--bounds", "kd=0.5:3", "--maxiter", "3",
                 "--popsize", "5", "--objective", "ise", "--json", "--quiet"],
    }
    for name, argv in runs.items():
        local = cli_json(capsys, *argv)
        remote = cli_json(capsys, *argv, "--dask", scheduler)
        assert local == remote, name
    assert len(distributed.chunk_bounds(300, 2000.0)) > 3


def test_bad_addresses_are_input_errors(capsys, tmp_path):
    (tmp_path / "line.toml").write_text(LINE)
    assert main(["montecarlo", str(tmp_path / "line.toml"), "--samples", "2", "--vary",
                 "leader.start.x=normal(0, 1)", "--dask", "not an address"]) == 2
    assert "--dask" in capsys.readouterr().err
