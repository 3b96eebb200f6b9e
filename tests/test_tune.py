"""Gain tuning: the closed-form case (dynamic feedback on a straight line, ∫|e|² dt =
|ė(0)|²/(2 kp kd)), objectives parsed safely, robust tuning over starts, the CLI."""
import dataclasses
import json
import re

import numpy as np
import pytest

from nonholo.cli import main
from nonholo.errors import NonholoInputError
from nonholo.studies.tune import Objective, evaluate_chunk, run_tune

# Start on the line (e(0) = 0) heading along x while the line heads along y at 1 m/s, with
# ξ(0) = 0.5: ė(0) = (0, 1) − 0.5 (1, 0), |ė(0)|² = 1.25; the error dynamics are linear.
LINE = """name = "line-dfl"
[simulation]
duration = 40.0
dt = 0.01
[reference]
kind = "line"
[[robots]]
name = "leader"
controller = "dynamic-feedback"
gains = { kp = 1.0, kd = 0.7, xi0 = 0.5 }
"""
E_DOT_0 = 1.25


def ise(kp, kd):
    return E_DOT_0 / (2 * kp * kd)


def test_objective_matches_the_closed_form():
    points = np.array([[0.5, 0.5], [1.0, 0.7], [3.0, 2.0], [2.0, 4.0]])
    values = evaluate_chunk({"text": LINE, "source": "line", "steps": None, "robot": "leader",
                             "fields": [("leader", "gains.kp"), ("leader", "gains.kd")], "values": points,
                             "objective": "ise"})
    np.testing.assert_allclose(values, [ise(kp, kd) for kp, kd in points], rtol=2e-3)


def test_finds_the_known_optimum():
    result = run_tune(LINE, ["kp", "kd"], ["kp=0.5:4", "kd=0.5:4"], "ise", seed=2, maxiter=15, popsize=8,
                      progress=False)
    assert result.gains["kp"] == pytest.approx(4.0, rel=0.01) and result.gains["kd"] == pytest.approx(4.0, rel=0.01)
    assert result.objective == pytest.approx(ise(4.0, 4.0), rel=0.01)
    assert result.baseline == {"kp": 1.0, "kd": 0.7}              # Table 5.1
    assert result.baseline_objective == pytest.approx(ise(1.0, 0.7), rel=2e-3)
    assert result.history == sorted(result.history, reverse=True)  # the best never gets worse
    assert result.evaluations >= 16
    # ∫|e|² falls as kp, kd grow: the optimum is on the upper bounds, and the result says so
    warning = result.bound_warning()
    assert re.search(r"kp = 3\.9\d* is at its upper bound \(0\.5:4\); kd = 3\.9\d* is at its upper bound", warning)
    assert dataclasses.replace(result, gains={"kp": 2.0, "kd": 0.51}).bound_warning() == (
        "warning: kd = 0.51 is at its lower bound (0.5:4): the optimum may lie beyond it; widen --bounds that way")
    assert dataclasses.replace(result, gains={"kp": 2.0, "kd": 2.0}).bound_warning() is None


def test_objectives_are_parsed_never_evaluated():
    assert Objective.parse("2*rms+max").describe() == "2*rms + max"
    for bad in ("rms*2", "__import__('os')", "rms + -1*effort", "speed"):
        with pytest.raises(NonholoInputError):
            Objective.parse(bad)


def test_robust_over_starts_and_cli(tmp_path, capsys):
    path = tmp_path / "line.toml"
    path.write_text(LINE)
    code = main(["tune", str(path), "--gains", "kp,kd", "--bounds", "kp=0.5:2", "--bounds", "kd=0.5:2",
                 "--objective", "rms + 0.001*effort", "--start", "leader.start.x=normal(0, 0.5)", "--start-samples",
                 "4", "--maxiter", "3", "--popsize", "4", "--steps", "1000", "--json", "--quiet", "--out",
                 str(tmp_path / "out")])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["starts"] == 4 and set(out["optimum"]["gains"]) == {"kp", "kd"}
    assert out["optimum"]["objective"] <= out["baseline"]["objective"] * 1.5
    assert (tmp_path / "out" / "convergence.png").stat().st_size > 0
    assert main(["tune", str(path), "--gains", "kp,zz"]) == 2
    assert "zz" in capsys.readouterr().err
    assert main(["tune", str(path), "--gains", "kp", "--bounds", "kp=3:1"]) == 2


def test_bounds_outside_a_gain_s_rules_are_one_line_exit_2(tmp_path, capsys):
    path = tmp_path / "line.toml"
    path.write_text(LINE)
    assert main(["tune", str(path), "--gains", "kp", "--bounds", "kp=-1:1", "--steps", "100", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("nonholo tune: --bounds kp=-1:1: gain 'kp1' of dynamic-feedback must be > 0, got -1")
    assert len(err.splitlines()) == 1


def test_the_table_shows_every_tuned_gain_whole(tmp_path, capsys):
    from nonholo.cli.tune import describe

    path = tmp_path / "line.toml"
    path.write_text(LINE.replace("dynamic-feedback", "kanayama").replace("{ kp = 1.0, kd = 0.7, xi0 = 0.5 }",
                                                                         "{ kx = 10.0, ky = 0.0064, ktheta = 0.16 }"))
    result = run_tune(path.read_text(), ["kx", "ky", "ktheta"], steps=200, maxiter=1, popsize=2, progress=False)
    text = describe(result)
    for name, value in {**result.gains, **result.baseline}.items():
        assert f"{name} = {value:.4g}" in text
    assert max(map(len, text.splitlines())) <= 100
    result.gains = {f"a_long_gain_name_{i}": 1.0 + i for i in range(4)}   # too long for a column: own lines
    text = describe(result)
    assert "optimum gains: a_long_gain_name_0 = 1" in text and max(map(len, text.splitlines())) <= 100
