"""A lockstep fleet of one OS process per robot over authenticated TCP equals the
centralized sampled-data run (spec fleet.md §6), and bad network input is one line, exit 2."""

import pytest

from nonholo import examples
from nonholo.cli import main
from nonholo.fleet.config import load_fleet, with_overrides
from nonholo.fleet.launch import run_fleet
from nonholo.sim.simulator import simulate
from test_fleet_lockstep import assert_same_result

OVERRIDES = {"duration": 2.0, "dt": 0.01, "control_period": 0.02}


def example_text(name, *edits):
    text = examples.resolve(name).read_text()
    for old, new in edits:
        assert old in text
        text = text.replace(old, new)
    return text


SINGLE = ('name = "one"\n[simulation]\nduration = 1.0\n[reference]\nkind = "circle"\n[[robots]]\n'
          'name = "leader"\ncontroller = "dynamic-feedback"\ngains = { kp = 1.0, kd = 0.7, xi0 = 0.5 }\n')
CASES = {
    "single-leader": lambda: SINGLE,
    "chain-7": lambda: example_text("formation-chain", ("start_relative = [-4.0, 0.0, 0.0]\n", "")),
    "tree-ll": lambda: example_text("formation-eight-triangle"),
    "formation-change": lambda: example_text("formation-circle-switch", ("at = 100.0", "at = 1.0")),
}


@pytest.mark.parametrize("case", CASES)
def test_tcp_lockstep_equals_centralized_sampled_data(case, tmp_path):
    path = tmp_path / f"{case}.toml"
    path.write_text(CASES[case]())
    scenario, config = load_fleet(path)
    scenario = with_overrides(scenario, **OVERRIDES)
    run = run_fleet(scenario, transport="tcp", config=config, source=path, overrides=OVERRIDES, wait_s=15.0)
    assert_same_result(simulate(scenario), run.result)
    network = run.to_dict()["network"]
    assert network["transport"] == "tcp"
    for link in network["links"].values():
        assert link["rejected"] == 0 and link["lost"] == 0 and link["sent"] == link["received"] > 0
        assert link["age_s"]["max"] == 0.0


@pytest.mark.parametrize("table, field", [
    ('transport = "carrier-pigeon"', "network.transport"),
    ("delay = -1.0", "network.delay"),
    ("loss = 1.5", "network.loss"),
    ("colour = 3", "network.colour"),
    ("[[network.links]]\nparent = \"leader\"\nchild = \"nobody\"", "network.links[0]"),
    ("[network.addresses]\nghost = \"127.0.0.1:1\"", "network.addresses.ghost"),
])
def test_bad_network_table_is_one_line_exit_2(table, field, tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(SINGLE + "[network]\n" + table + "\n")
    assert main(["fleet", str(path), "--control-period", "0.02", "--json"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err and "Traceback" not in err


def test_zenoh_lockstep_equals_centralized_sampled_data(tmp_path):
    pytest.importorskip("zenoh")
    path = tmp_path / "tree.toml"
    path.write_text(CASES["tree-ll"]())
    scenario, config = load_fleet(path)
    overrides = {**OVERRIDES, "duration": 1.0}
    scenario = with_overrides(scenario, **overrides)
    run = run_fleet(scenario, transport="zenoh", config=config, source=path, overrides=overrides, wait_s=15.0)
    assert_same_result(simulate(scenario), run.result)
    assert run.network["transport"] == "zenoh"


def test_a_failing_robot_fails_the_run_and_every_process_is_reaped(tmp_path, monkeypatch):
    from nonholo.fleet import spawn
    from nonholo.fleet.bench import chain_text

    path = tmp_path / "chain.toml"
    path.write_text(chain_text(2))
    scenario, _ = load_fleet(path)
    started = []
    original = spawn.Robots.start

    def record(robots, name):
        started.append(original(robots, name))
        return started[-1]

    monkeypatch.setattr(spawn.Robots, "start", record)
    robots = spawn.start_robot_processes(path, scenario, None, OVERRIDES, 10.0,
                                         extra={"f2": ["--connect", "ghost=127.0.0.1:1"]})
    try:
        with pytest.raises(spawn.LaunchError, match="robot f2 failed"):
            robots.wait(30.0)
    finally:
        robots.discard()   # as run_fleet does: every process reaped, whatever happened
    assert len(started) == 3 and all(p.returncode is not None for p in started)
