"""Monte-Carlo: safe distribution parsing, seeded reproducibility, failures counted (not
aborting), worst samples re-runnable, streaming to disk, the CLI's contract."""
import json
import math

import numpy as np
import pytest

import nonholo as nh
from nonholo.fleet.bench import star_text
from nonholo.cli import main
from nonholo.errors import NonholoInputError
from nonholo.studies.montecarlo import Distribution, Variation, patched_toml, run_montecarlo, toml_text, wilson

LINE = """name = "line-dfl"
[simulation]
duration = 20.0
dt = 0.02
[reference]
kind = "line"
[[robots]]
name = "leader"
controller = "dynamic-feedback"
gains = { kp = 1.0, kd = 0.7 }
[[robots]]
name = "other"
controller = "kanayama"
"""

FORMATION = """name = "pair"
[simulation]
duration = 10.0
dt = 0.02
[reference]
kind = "circle"
[[robots]]
name = "leader"
controller = "dynamic-feedback"
start = [0, 0, "pi/2"]
[[robots]]
name = "f1"
formation = "separation-bearing"
leader = "leader"
l = 2.0
phi = "pi/3"
d = 0.5
start_relative = [-1.5, -1, 0]
"""

# Dynamic feedback at h·λ = 2.5 (just inside RK4's linear limit) grows without bound from a
# start off the reference: state overflow after a few hundred seconds.
UNSTABLE = """name = "unstable"
[simulation]
duration = 1000.0
dt = 0.5
substeps = 1
[reference]
kind = "eight"
[[robots]]
name = "r"
controller = "dynamic-feedback"
gains = { kp = 20.0, kd = 5.0, xi_min = 1e-9 }
"""


def without_timing(result):
    out = result.to_dict()
    out.pop("timing")
    return out


def test_distributions_are_parsed_never_evaluated():
    assert Distribution.parse(" normal( 1 , 0.5 ) ") == Distribution("normal", 1.0, 0.5)
    assert Distribution.parse("uniform(-1e-1, 2.)") == Distribution("uniform", -0.1, 2.0)
    for bad in ("__import__('os')(0, 1)", "normal(0)", "normal(0, -1)", "uniform(2, 1)", "gamma(1, 2)",
                "normal(0, 1) + 1", "normal(inf, 1)"):
        with pytest.raises(NonholoInputError):
            Distribution.parse(bad)


def test_fields_are_checked_against_the_scenario():
    scenario = nh.parse_scenario(FORMATION)
    assert Variation.parse("f1.phi=normal(1, 0.1)", scenario).path == "phi"
    assert Variation.parse("leader.gains.kp=uniform(1, 2)", scenario).field == "leader.gains.kp"
    with pytest.raises(NonholoInputError, match="f1.gains.kp"):
        Variation.parse("f1.gains.kp=uniform(1, 2)", scenario)
    with pytest.raises(NonholoInputError, match="no robot"):
        Variation.parse("ghost.start.x=normal(0, 1)", scenario)


def test_seeded_reproducible_and_only_the_varied_formation_simulated():
    vary = ["leader.start.x=normal(0, 0.5)", "leader.gains.kd=uniform(0.5, 1.5)"]
    a = run_montecarlo(LINE, vary, 40, seed=3, progress=False)
    b = run_montecarlo(LINE, vary, 40, seed=3, progress=False)
    c = run_montecarlo(LINE, vary, 40, seed=4, progress=False)
    assert json.dumps(without_timing(a)) == json.dumps(without_timing(b))
    assert without_timing(a)["metrics"] != without_timing(c)["metrics"]
    out = a.to_dict()
    assert out["simulated_robots"] == ["leader"]
    rms = out["metrics"]["leader.error_rms"]
    assert rms["n"] == 40 and rms["mean_ci95"][0] <= rms["mean"] <= rms["mean_ci95"][1]
    assert rms["quantiles"]["q05"] <= rms["quantiles"]["q50"] <= rms["quantiles"]["q95"]
    # each sample is the scenario with the drawn numbers, simulated alone
    i = 7
    alone = nh.simulate(nh.parse_scenario(LINE.replace("start", "start")), record=False)
    x, kd = a.values[i]
    robot = nh.Robot("leader", nh.controller("dynamic-feedback", kp=1.0, kd=kd), (x, 0.0, 0.0))
    single = nh.simulate(nh.Scenario(alone.scenario.reference, [robot], duration=20.0, dt=0.02), record=False)
    assert a.column("leader.error_rms")[i] == pytest.approx(single.metrics.error_rms[0], rel=1e-12)


def test_divergence_is_a_counted_failure_not_an_abort():
    result = run_montecarlo(UNSTABLE, ["r.start.x=uniform(-0.001, 3)"], 12, seed=0, progress=False)
    failures = result.failure_summary()
    assert 0 < failures["diverged"]["count"] < 12
    low, high = failures["diverged"]["ci95"]
    assert low <= failures["diverged"]["probability"] <= high
    assert result.to_dict()["worst"][0]["failures"][0] == "diverged"
    json.dumps(result.to_dict(), allow_nan=False)
    with pytest.raises(nh.SimulationError):
        nh.simulate(nh.parse_scenario(UNSTABLE.replace("name = \"r\"", "name = \"r\"\nstart = [3, 0, 0]")))



def test_a_batch_that_diverges_names_its_members_and_report_marks_them():
    from nonholo.sim.simulator import diverged

    stable = nh.parse_scenario(UNSTABLE)
    members = [nh.parse_scenario(UNSTABLE.replace('name = "r"', f'name = "r"\nstart = [{x}, 0, 0]'))
               for x in (0.0, 3.0, 0.0, 3.0)]
    with pytest.raises(nh.SimulationError, match=r"'r' diverged in 2 member\(s\) of the batch \(the first: member 1;"):
        nh.simulate(members, record=False)
    result = nh.simulate(members, record=False, on_divergence="report")
    assert diverged(result.stats).any(axis=0).tolist() == [False, True, False, True]
    assert result.metrics.error_mean[0, 0] == pytest.approx(nh.simulate(stable, record=False).metrics.error_mean[0])


WEDGE = """
name = "wedge"
[simulation]
duration = 8.0
dt = 0.01
[reference]
kind = "circle"
[[robots]]
name = "leader"
controller = "dynamic-feedback"
gains = { kp = 1.0, kd = 0.7, xi0 = 0.5 }
start = [0.0, 0.0, 1.5707963267948966]
[[robots]]
name = "R2"
formation = "separation-bearing"
leader = "leader"
l = 3.605551275463989
phi = "atan2(-2*sqrt(3), 1)"
start_relative = [-1.0, -4.0, 0.0]
[[robots]]
name = "F"
formation = "separation-separation"
leaders = ["leader", "R2"]
l = [2.0, 2.0]
start_relative = [-3.0, -2.0, 0.0]
"""


def test_an_l_l_singularity_crossed_between_samples_is_a_singular_failure():
    # the spec's wedge passes through sin(γ1 − γ2) = 0 at t = 7.25 s between two samples, where
    # no guard acts (|sin| stays above sin_floor at every sample): counted as singular all the same
    result = run_montecarlo(WEDGE, ["F.gains.k1=uniform(0.99, 1.01)"], 3, seed=0, progress=False)
    assert result.failure_summary()["singular"]["count"] == 3
    scenario = nh.parse_scenario(WEDGE)
    safety = nh.simulate(scenario).follower_metrics("F")["safety"]
    assert safety["singular_samples"] == 0 and safety["sin_gamma_sign_changes"] >= 1


def test_collision_closer_than_two_d_and_worst_files_rerun(tmp_path):
    result = run_montecarlo(FORMATION, ["f1.l=uniform(0.6, 3.0)", "f1.start.y=normal(0, 0.3)"], 24, seed=1,
                            out=tmp_path, worst=2, worst_by="f1.error_max", progress=False)
    collisions = result.failure_summary()["collision"]["count"]
    assert 0 < collisions < 24   # some starts and targets come closer than 2d = 1 m
    assert (tmp_path / "histograms.png").stat().st_size > 0
    rows = (tmp_path / "samples.csv").read_text().splitlines()
    assert len(rows) == 25 and rows[0].startswith("sample,f1.l,f1.start.y,")
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["worst"][0]["file"] == "worst-1.toml"
    worst = summary["worst"][0]
    rerun = nh.simulate(nh.load_scenario(tmp_path / "worst-1.toml"), record=False)
    assert rerun.metrics.error_max[1] == pytest.approx(worst["f1.error_max"], rel=1e-6)
    assert rerun.scenario.robot("f1").targets[0] == worst["values"]["f1.l"]


def test_toml_writer_round_trips_the_bundled_examples():
    from nonholo import examples

    for name in examples.names():
        text = examples.path(name).read_text()
        scenario = nh.parse_scenario(text)
        again = nh.parse_scenario(toml_text(patched_toml(text, (), ())))
        assert again.robots == scenario.robots and again.duration == scenario.duration


def test_wilson_interval():
    low, high = wilson(5, 100)
    assert low < 0.05 < high and high - low < 0.1
    assert wilson(100, 100)[1] == 1.0 and math.isclose(wilson(0, 10)[0], 0.0)


def test_cli_json_and_exit_codes(tmp_path, capsys):
    path = tmp_path / "line.toml"
    path.write_text(LINE)
    code = main(["montecarlo", str(path), "--samples", "8", "--vary", "leader.start.y=normal(0, 1)", "--json",
                 "--quiet"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["samples"] == 8 and set(out["failures"]) >= {"diverged", "collision"}
    assert main(["montecarlo", str(path), "--samples", "8", "--vary", "leader.start.q=normal(0, 1)"]) == 2
    assert "leader.start.q" in capsys.readouterr().err
    assert main(["montecarlo", str(path), "--samples", "0", "--vary", "leader.start.x=normal(0, 1)"]) == 2
    assert main(["montecarlo", str(path), "--samples", "4", "--vary", "leader.start.x=normal(0, 1)", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert max(len(line) for line in text.splitlines()) <= 100
    np.testing.assert_equal(len(text.splitlines()) > 5, True)


def test_docstring_examples_of_the_study_modules():
    import doctest

    from nonholo.studies import distributed, montecarlo, tune

    for module in (montecarlo, tune, distributed):
        failures, attempted = doctest.testmod(module)
        assert failures == 0 and attempted > 0, module.__name__


# A leader on the circle and one follower (nonholo.fleet.bench.star_text), sampled at 50 Hz
# over a link with a delay.
NETWORKED = star_text(1).replace("duration = 2.0", "duration = 3.0\ndt = 0.01\ncontrol_period = 0.02") + \
    "[network]\nseed = 3\ndelay = 0.02\n"


def test_link_model_varied_moves_followers_only_and_worst_files_rerun(tmp_path):
    """--vary network.delay / network.loss: the leader's figures stay, the follower's change
    with the draws, a re-run gives the same numbers, and a worst sample re-runs to its own."""
    vary = ["network.delay=uniform(0, 0.2)", "network.loss=uniform(0, 0.5)"]
    result = run_montecarlo(NETWORKED, vary, 24, seed=5, out=tmp_path)
    again = run_montecarlo(NETWORKED, vary, 24, seed=5)
    assert np.array_equal(result.metrics, again.metrics)
    assert result.worst_by == "f1.error_max"
    assert np.ptp(result.column("leader.error_max")) == 0.0 and np.ptp(result.column("f1.error_max")) > 0.1
    # a delay beyond stale_after (0.1 s): every state is stale on arrival, the follower never moves
    stale = result.values[:, 0] > 0.1 + 0.02
    assert stale.any() and (result.column("f1.peak_v")[stale] == 0.0).all()
    assert (result.column("f1.peak_v")[result.values[:, 0] < 0.05] > 0.0).all()
    worst = json.loads((tmp_path / "summary.json").read_text())["worst"][0]
    rerun = nh.simulate(nh.load_scenario(tmp_path / worst["file"]), record=False)
    assert rerun.scenario.network.default.delay == worst["values"]["network.delay"]
    assert rerun.metrics.error_max[1] == pytest.approx(worst["f1.error_max"], rel=1e-12)


def test_link_model_variation_needs_sampled_data_and_its_range():
    continuous = NETWORKED.replace("control_period = 0.02\n", "").replace("delay = 0.02\n", "")
    with pytest.raises(NonholoInputError, match="network.delay: the link model needs sampled-data control"):
        run_montecarlo(continuous, ["network.delay=uniform(0, 0.1)"], 4)
    with pytest.raises(NonholoInputError, match="network.loss: .* draws fall outside"):
        run_montecarlo(NETWORKED, ["network.loss=normal(0.1, 0.5)"], 50)
    with pytest.raises(NonholoInputError, match="'bandwidth' is not a number of the link model"):
        run_montecarlo(NETWORKED, ["network.bandwidth=uniform(0, 1)"], 4)


def test_a_draw_outside_a_gain_s_rules_is_one_line_naming_the_option_and_sample():
    with pytest.raises(NonholoInputError, match=r"^--vary leader\.gains\.kp: sample \d+ draws -[\d.]+: gain 'kp1' "
                                                r"of dynamic-feedback must be > 0"):
        run_montecarlo(LINE, ["leader.gains.kp=normal(1, 5)"], 20, progress=False)
