"""``nonholo bench``: interleaved rounds, spreads and the step profile (structure, not speed)."""
import subprocess
import sys

import numpy as np
import pytest

from nonholo.cli import bench as bench_cli
from nonholo.sim import benchmark


def test_interleaved_alternates_subjects_and_skips_slow_baselines():
    calls = []
    times = benchmark.interleaved({"a": lambda: calls.append("a"), "b": lambda: calls.append("b")}, 4, {"b": 2})
    # one untimed warm-up each, then a b a a b a a (b in rounds 0 and 2 only)
    assert calls == ["a", "b", "a", "b", "a", "a", "b", "a"]
    assert len(times["a"]) == 4 and len(times["b"]) == 2
    assert all(t >= 0.0 for t in times["a"] + times["b"])


def test_step_profile_parts_add_up_to_the_step():
    profile = benchmark.step_profile(robots=16, duration=0.2, rounds=1)
    parts = profile["batch_ns_per_robot_step"]
    assert set(parts) == {key for key, _ in benchmark.PROFILE_PARTS}
    named = ("law", "plant_rk4", "sample", "setup", "rest")
    assert sum(parts[k] for k in named) == pytest.approx(parts["step"], rel=1e-12)
    assert parts["law"] > 0.0 and parts["step"] > 0.0 and np.isfinite(list(parts.values())).all()
    single = profile["single_ms"]
    assert single["reference_table"] > 0.0
    assert single["reference_table"] + single["recording"] + single["rest"] == pytest.approx(single["whole"])
    assert profile["steps"] == 20 and profile["robots"] == 16


@pytest.mark.parametrize("bad", ["0", "-3", "x"])
def test_bench_rounds_must_be_positive(bad):
    run = subprocess.run([sys.executable, "-m", "nonholo", "bench", "--rounds", bad], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == 2
    assert "positive whole number" in run.stderr and "Traceback" not in run.stderr


def test_bench_help_names_the_profile():
    run = subprocess.run([sys.executable, "-m", "nonholo", "bench", "--help"], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == 0 and "--profile" in run.stdout
    assert all(len(label) <= 46 for _, label, _, _ in bench_cli.TARGETS)


def test_profile_parts_at_or_below_zero_read_as_about_zero():
    # (a part that is a difference of medians can fall below zero within the noise)
    for ns in (-0.3, 0.0):
        line = bench_cli.part_line("the rest", ns, 8.9)
        assert line.endswith("~0 ns per robot-step") and "-0" not in line and "%" not in line
    line = bench_cli.part_line("law", 4.4, 8.8)
    assert "4.4 ns per robot-step" in line and line.endswith("50 %") and len(line) <= 100
