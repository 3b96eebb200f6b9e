"""Gain sweeps: grid parsing, trend classification, batch = direct simulations."""
import dataclasses

import numpy as np
import pytest

import nonholo as nh
from nonholo.studies.sweep import GainAxis, SweepSpec, classify_trend, run_sweep, run_sweeps


def short_scenario():
    robots = [nh.Robot("dfl", nh.controller("dynamic-feedback")), nh.Robot("kan", nh.controller("kanayama")),
              nh.Robot("lin", nh.controller("approximate-linearization")),
              nh.Robot("nl", nh.controller("nonlinear"))]
    return nh.Scenario(nh.references.eight(), robots, duration=30.0, steps=3000, name="short")


@pytest.mark.parametrize("values, word", [
    ([3, 2, 1], "decreases"), ([1, 2, 3], "increases"), ([1, 1, 1], "no effect"),
    ([1.0, 1.0000001, 1.0], "no effect"), ([3, 1, 2], "decreases, then increases"),
    ([1, 3, 2], "increases, then decreases"), ([1, 3, 2, 4], "oscillates"),
    ([3.0, 2.0, 2.001, 1.0], "decreases"),  # a wiggle below 1 % of the range is ignored
    ([3.0, 2.0, 2.1, 1.0], "oscillates")])
def test_classify_trend(values, word):
    assert classify_trend(values).word == word


def test_trend_agreement_with_claims():
    assert classify_trend([1, 3, 2, 4]).agrees_with("oscillates")
    assert classify_trend([1, 3, 2, 4]).agrees_with("increases, then oscillates")
    assert not classify_trend([4, 3, 2, 4, 1]).agrees_with("increases, then oscillates")
    assert classify_trend([3, 2, 1]).agrees_with("decreases")
    assert not classify_trend([3, 2, 1]).agrees_with("increases")


@pytest.mark.parametrize("text", ["zeta", "zeta=1:2", "zeta=a:2:3", "=1:2:3", "zeta=1:2:0", "zeta=1:inf:3"])
def test_bad_gain_specs(text):
    with pytest.raises(nh.NonholoInputError):
        GainAxis.parse(text)


def test_two_gain_sweep_equals_direct_simulations():
    scenario = short_scenario()
    axes = [GainAxis.parse("kx=1:9:3"), GainAxis.parse("ky=0.01:0.05:2")]
    sweep = run_sweep(scenario, axes, metric="rms")
    assert sweep.values.shape == (3, 2) and sweep.points == 6
    for i, kx in enumerate(axes[0].values):
        for j, ky in enumerate(axes[1].values):
            robot = nh.Robot("one", nh.controller("kanayama", kx=float(kx), ky=float(ky)))
            direct = nh.simulate(nh.Scenario(scenario.reference, [robot], duration=30.0, steps=3000),
                                 record=False).metrics
            assert sweep.values[i, j] == pytest.approx(float(direct.error_rms[0]), rel=1e-12)
    assert len(sweep.rows()) == 6 and sweep.header()[:2] == ["kx", "ky"]


def test_several_sweeps_in_one_batch_keep_their_own_results():
    scenario = short_scenario()
    together = run_sweeps(scenario, [SweepSpec((GainAxis.parse("zeta=0.2:0.8:3"),), "lin"),
                                     SweepSpec((GainAxis.parse("kp=0.5:2:3"),), "dfl")])
    alone = run_sweep(scenario, [GainAxis.parse("kp=0.5:2:3")], robot="dfl")
    np.testing.assert_allclose(together[1].values, alone.values, rtol=1e-12)
    assert together[0].controller == "approximate-linearization"


def test_robot_choice_and_bad_input():
    scenario = short_scenario()
    assert run_sweep(scenario, [GainAxis.parse("kd1=0.5:1:2")]).robot == "dfl"
    with pytest.raises(nh.NonholoInputError, match="--robot"):
        run_sweep(scenario, [GainAxis.parse("zeta=0.2:0.8:3")])
    with pytest.raises(nh.NonholoInputError, match="must be in"):
        run_sweep(scenario, [GainAxis.parse("zeta=0.5:1.5:3")], robot="lin")
    with pytest.raises(nh.NonholoInputError, match="metric"):
        run_sweep(scenario, [GainAxis.parse("kx=1:2:2")], metric="median")
    with pytest.raises(nh.NonholoInputError, match="no robot named"):
        run_sweep(scenario, [GainAxis.parse("kx=1:2:2")], robot="nobody")


def test_plots_and_files(tmp_path):
    scenario = short_scenario()
    line = run_sweep(scenario, [GainAxis.parse("kx=1:9:4")])
    heat = run_sweep(scenario, [GainAxis.parse("kx=1:9:3"), GainAxis.parse("ky=0.01:0.05:3")])
    for name, sweep in (("line", line), ("heat", heat)):
        sweep.plot(tmp_path / f"{name}.png")
        assert (tmp_path / f"{name}.png").read_bytes()[:4] == b"\x89PNG"
        sweep.write_csv(tmp_path / f"{name}.csv")
        assert len((tmp_path / f"{name}.csv").read_text().splitlines()) == sweep.points + 1
    assert "trend" in line.to_dict() and "trend" not in heat.to_dict()


def test_best_point_on_the_grid_edge_is_reported():
    import numpy as np

    from nonholo.studies.sweep import GainAxis, SweepResult

    def result(values, *axes):
        values = np.asarray(values, dtype=float)
        errors = {s: values for s in ("mean", "std", "rms", "max", "final")}
        return SweepResult("s", "r", "kanayama", axes, "mean", errors, 0.1)

    inside = result([3.0, 1.0, 2.0], GainAxis.linear("kx", 1, 3, 3))
    assert inside.best() == {"kx": 2.0} and inside.best_on_edge() == [] and inside.edge_warning() is None
    low = result([1.0, 2.0, 3.0], GainAxis.linear("kx", 1, 3, 3))
    assert low.best_on_edge() == ["kx"] and "kx = 1, the lowest value swept" in low.edge_warning()
    assert low.to_dict()["best"] == {"point": {"kx": 1.0}, "value": 1.0, "on_edge": ["kx"]}
    corner = result([[5.0, 4.0], [3.0, 9.0], [6.0, 7.0]], GainAxis.linear("a", 0, 2, 3), GainAxis.linear("b", 0, 1, 2))
    assert corner.best() == {"a": 1.0, "b": 0.0} and corner.best_on_edge() == ["b"]


def test_a_chunk_builds_only_its_own_robots_and_they_are_the_whole_grid_s():
    from nonholo import examples
    from nonholo.formation import Follower
    from nonholo.studies.sweep import sweep_robots

    scenario = nh.load_scenario(examples.path("test1-eight"))
    axes = [GainAxis.linear("kx", 1.0, 9.0, 7), GainAxis.linear("ky", 0.01, 0.03, 5)]
    base = next(r for r in scenario.robots if r.controller.name == "kanayama")
    whole = sweep_robots(base, axes, "0:")
    assert len(whole) == 35 and whole[12].name == "0:kanayama#12"
    for span in (slice(0, 35), slice(3, 17), slice(34, 35), slice(20, 20)):
        assert sweep_robots(base, axes, "0:", span) == whole[span]
    chain = nh.load_scenario(examples.path("formation-chain"))
    follower = next(r for r in chain.robots if isinstance(r, Follower))
    axes = [GainAxis.linear("k1", 0.5, 2.0, 6)]
    assert sweep_robots(follower, axes, span=slice(2, 5)) == sweep_robots(follower, axes)[2:5]


def test_a_follower_s_sweep_reports_the_output_its_parameters_drive():
    """An l–φ follower's separation error does not depend on its bearing's gain k2 (the
    outputs are decoupled): a k2 sweep reports the bearing's error, which falls as k2
    rises, equal to the follower's heading statistics run alone; a k1 sweep the separation's."""
    from nonholo import examples
    from nonholo.studies.sweep import run_sweep

    chain = nh.load_scenario(examples.path("formation-chain"))
    # fixed sub-steps: a batch's plan is its copies' (their fastest rates), a run alone its own
    chain = dataclasses.replace(chain, robots=chain.robots[:2], duration=5.0, substeps=8)
    bearing = run_sweep(chain, [GainAxis.linear("k2", 0.5, 2.0, 4)], robot="f1", progress=False)
    assert (bearing.output, bearing.unit) == ("phi", "rad") and bearing.to_dict()["output"] == "phi"
    assert bearing.trend().word == "decreases"
    f1 = chain.robots[1]
    alone = nh.simulate(dataclasses.replace(chain, robots=(chain.robots[0], dataclasses.replace(f1, k2=1.5))),
                        record=False).metrics
    assert bearing.values[2] == pytest.approx(alone.heading_mean[1], rel=1e-12)
    separation = run_sweep(chain, [GainAxis.linear("k1", 0.5, 2.0, 4)], robot="f1", progress=False)
    assert (separation.output, separation.unit) == ("l", "m") and separation.trend().word == "decreases"
    assert separation.values[0] == pytest.approx(
        nh.simulate(dataclasses.replace(chain, robots=(chain.robots[0], dataclasses.replace(f1, k1=0.5))),
                    record=False).metrics.error_mean[1], rel=1e-12)
