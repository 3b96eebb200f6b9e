"""The simulator refuses, before allocating, runs that would not fit, and keeps formation
safety figures as running minima (no per-sample table of pairs)."""
import math
import tracemalloc

import pytest

import nonholo as nh
from nonholo.cli import main

BASE = """
[simulation]
{simulation}
[reference]
kind = "line"
[[robots]]
name = "leader"
controller = "kanayama"
"""


@pytest.mark.parametrize("simulation, words", [
    ("duration = 10\nsubsteps = 1000000000", "GiB"),
    ("duration = 9.9e7\ndt = 1", "GiB"),
])
def test_oversized_runs_are_refused_up_front(tmp_path, capsys, simulation, words):
    path = tmp_path / "big.toml"
    path.write_text(BASE.format(simulation=simulation))
    assert main(["run", str(path), "--json"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err and "Traceback" not in err


def test_many_followers_keep_memory_linear():
    """300 followers in a column behind one leader, statistics only: memory stays small (it
    grew with the square of the follower count when pairwise distances were kept per sample)."""
    leader = nh.Robot("leader", nh.controller("dynamic-feedback"), start=(0.0, 0.0, math.pi / 2))  # on the line
    robots = [leader] + [nh.separation_bearing(f"f{i}", "leader", 2.0 + 0.5 * i, math.pi) for i in range(1, 301)]
    scenario = nh.Scenario(nh.references.line(), robots, duration=2.0, dt=0.05)
    nh.simulate(nh.Scenario(nh.references.line(), robots[:3], duration=0.1, dt=0.05), record=False)  # compile
    tracemalloc.start()
    result = nh.simulate(scenario, record=False)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 30e6
    safety = result.follower_metrics("f150")["safety"]
    assert safety["min_distance"] == pytest.approx(0.5, abs=1e-6)   # in formation from the start, 0.5 m apart
    assert result.follower_metrics("f300")["l_error"]["max"] < 1e-9
