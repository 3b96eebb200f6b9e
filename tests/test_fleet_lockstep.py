"""A lockstep fleet run (every robot its own program, in-process transport) equals the
centralized sampled-data run (spec fleet.md §6) on every metric."""
import dataclasses
import math

import pytest

from nonholo import examples
from nonholo.fleet.launch import run_fleet
from nonholo.sim.files import load_scenario
from nonholo.sim.simulator import planned_groups, simulate

RELATIVE = 1e-9
FLOOR = 1e-12   # metrics at the rounding floor (an error of 1e-16 against 0) compare absolutely
# The time of an extremum flips between near-ties (a chain in formation keeps its distances
# constant to 1e-15): extremum values are compared, their times are not.
TIES = True


def leaves(value, path=""):
    if isinstance(value, dict):
        for key, item in value.items():
            yield from leaves(item, f"{path}.{key}")
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from leaves(item, f"{path}[{i}]")
    else:
        yield path, value


def assert_same_result(central, fleet):
    # (what a run cost is not compared: its time, and its RK4 steps — the centralized run
    # counts the windows it ran again while planning, the robots run the plan it ended with)
    expected, actual = dict(leaves(central.to_dict())), dict(leaves(fleet.to_dict()))
    assert expected.keys() <= actual.keys()
    for key, want in expected.items():
        if "elapsed" in key or key.endswith("rk4_steps") or (TIES and (key.endswith("_time") or "_pair" in key or "nearest" in key)):
            continue
        got = actual[key]
        if isinstance(want, float) and isinstance(got, float):
            assert math.isclose(want, got, rel_tol=RELATIVE, abs_tol=FLOOR), (key, want, got)
        else:
            assert want == got, (key, want, got)


def sampled(name, duration=2.0, **changes):
    scenario = load_scenario(examples.resolve(name))
    return dataclasses.replace(scenario, duration=duration, dt=0.01, control_period=0.02, steps=None, **changes)


def chain_in_formation():
    scenario = load_scenario(examples.resolve("formation-chain"))
    robots = (scenario.robots[0],) + tuple(dataclasses.replace(r, start=None) for r in scenario.robots[1:])
    return sampled("formation-chain", robots=robots)


def circle_switch():
    scenario = load_scenario(examples.resolve("formation-circle-switch"))
    leader, follower = scenario.robots
    change = dataclasses.replace(follower.changes[0], at=1.0)
    return sampled("formation-circle-switch", robots=(leader, dataclasses.replace(follower, changes=(change,))))


def single_leader():
    scenario = load_scenario(examples.resolve("formation-circle-switch"))
    return sampled("formation-circle-switch", robots=scenario.robots[:1])


@pytest.mark.parametrize("make", [single_leader, chain_in_formation, lambda: sampled("formation-eight-triangle"),
                                  circle_switch], ids=["single-leader", "chain-7", "tree-ll", "formation-change"])
def test_lockstep_equals_centralized_sampled_data(make):
    scenario = make()
    central = simulate(scenario)
    run = run_fleet(scenario, transport="inproc", mode="lockstep")
    assert_same_result(central, run.result)
    # the robots integrate the plan the centralized run ended with: as many RK4 steps, or
    # fewer where it ran windows again while planning
    assert 0 < run.result.rk4_steps <= central.rk4_steps
    if make is single_leader:   # (a tracking leader under sampled data: no planning)
        assert run.result.rk4_steps == central.rk4_steps == scenario.n_steps
    summary = run.to_dict()
    assert summary["network"]["mode"] == "lockstep"
    for link in summary["network"]["links"].values():
        assert link["rejected"] == 0 and link["lost"] == 0 and link["sent"] == link["received"]


def test_planning_returns_the_plan_it_ran():
    """The bundled chain's violent start-up re-plans its sub-steps up to the last iteration:
    the plan returned must be the one integrated (it was updated after the last run once,
    and a fleet of it ended in a KeyError)."""
    for planned in planned_groups(sampled("formation-chain")):
        assert planned.plan.max() > 100   # the start-up needs hundreds of sub-steps
        assert planned.rows.shape[0] == planned.targets.shape[0] == planned.plan.size + 1


def test_fleet_cli_json(tmp_path, capsys):
    import json

    from nonholo.cli import main

    path = tmp_path / "one.toml"
    path.write_text('name = "one"\n[simulation]\nduration = 1.0\ndt = 0.01\ncontrol_period = 0.02\n'
                    '[reference]\nkind = "circle"\n[[robots]]\nname = "leader"\ncontroller = "dynamic-feedback"\n'
                    'gains = { kp = 1.0, kd = 0.7, xi0 = 0.5 }\n')
    assert main(["fleet", str(path), "--transport", "inproc", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["network"]["transport"] == "inproc" and "leader" in summary["robots"]
    path.write_text(path.read_text().replace("control_period = 0.02\n", ""))
    capsys.readouterr()
    assert main(["fleet", str(path), "--json"]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "--control-period S" in err and str(path) in err


def test_zenoh_without_its_module_is_one_line_before_any_robot_starts(monkeypatch, capsys):
    import importlib.util

    from nonholo.cli import main

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *args: None if name == "zenoh" else real(name, *args))
    assert main(["fleet", "formation-chain", "--control-period", "0.02", "--transport", "zenoh", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err == "nonholo fleet: the zenoh transport needs the Python module 'zenoh': " \
                  "python3 -m pip install 'nonholo[zenoh]'\n"
