"""The link model in the centralized sampled-data simulator (spec fleet.md §3–6): a scenario
with a [network] link model (delay, jitter, loss, seed, watchdog) simulated centrally equals
the lockstep fleet of it — in process and over TCP — on every metric; the links change the
run, a seed reproduces it, and scenarios differing in their links simulate as one batch."""
import dataclasses
import json

import numpy as np
import pytest

from nonholo.cli import main
from nonholo.fleet.bench import star_text
from nonholo.errors import NonholoInputError
from nonholo.fleet.config import load_fleet, with_overrides
from nonholo.fleet.launch import run_fleet
from nonholo.sim.files import parse_scenario
from nonholo.sim.links import LinkModel, LinkSettings
from nonholo.sim.watchdog import WatchdogConfig
from nonholo.sim.simulator import simulate
from test_fleet_lockstep import assert_same_result
from test_fleet_tcp import CASES, OVERRIDES

LINKS = "[network]\nseed = 11\ndelay = 0.02\njitter = 0.03\nloss = 0.15\nstale_after = 0.06\n"
PER_LINK = {"chain-7": ("f2", "f3"), "tree-ll": ("R2", "F"), "formation-change": ("leader", "follower")}


def linked_file(tmp_path, case, network=LINKS):
    text = CASES[case]() + network
    if case in PER_LINK:   # and one link of its own: more delay, more loss
        parent, child = PER_LINK[case]
        text += f'[[network.links]]\nparent = "{parent}"\nchild = "{child}"\ndelay = 0.05\nloss = 0.3\n'
    path = tmp_path / f"{case}.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("case", CASES)
def test_centralized_run_with_links_equals_the_lockstep_fleet_in_process(case, tmp_path):
    scenario, config = load_fleet(linked_file(tmp_path, case), OVERRIDES)
    assert scenario.network is not None and scenario.network == config.link_settings
    central = simulate(scenario)
    run = run_fleet(scenario, "inproc", config=config)
    assert_same_result(central, run.result)
    for field in ("x", "y", "theta", "v", "omega"):
        assert np.allclose(central.trajectory(field), run.result.trajectory(field), rtol=1e-9, atol=1e-12), field
    assert central.to_dict()["simulation"]["link_model"]["seed"] == 11
    if case != "single-leader":   # the links did act: states were lost, and followers stopped at the start
        assert sum(link["lost_by_model"] for link in run.network["links"].values()) > 0
        assert any(r["watchdog"] for r in run.network["robots"].values())


@pytest.mark.parametrize("case", CASES)
def test_centralized_run_with_links_equals_the_lockstep_fleet_over_tcp(case, tmp_path):
    path = linked_file(tmp_path, case)
    scenario, config = load_fleet(path, OVERRIDES)
    run = run_fleet(scenario, "tcp", config=config, source=path, overrides=OVERRIDES, wait_s=15.0)
    assert_same_result(simulate(scenario), run.result)


class Summary:
    def __init__(self, summary: dict):
        self.summary = summary

    def to_dict(self) -> dict:
        return self.summary


@pytest.mark.parametrize("case", ["tree-ll", "formation-change"])
def test_nonholo_run_equals_nonholo_fleet_lockstep(case, tmp_path, capsys):
    path = linked_file(tmp_path, case, LINKS + "[simulation]\nduration = 2.0\ndt = 0.01\ncontrol_period = 0.02\n")
    assert main(["fleet", str(path), "--transport", "inproc", "--json"]) == 0
    fleet = json.loads(capsys.readouterr().out)
    assert main(["run", str(path), "--json"]) == 0
    central = json.loads(capsys.readouterr().out)
    assert central["simulation"]["link_model"] == fleet["simulation"]["link_model"]
    # settling per change of targets, also from `run --json` (it records a run with changes)
    settling = [robot["formation"]["settling"] for robot in central["robots"].values() if "formation" in robot]
    assert settling == [[]] * len(settling) if case == "tree-ll" else any(settling)
    assert_same_result(Summary(central), Summary(fleet))
    assert main(["run", str(path)]) == 0
    assert "link model (seed 11)" in capsys.readouterr().out


def test_a_link_model_needs_sampled_data_control(tmp_path, capsys):
    path = tmp_path / "continuous.toml"
    path.write_text(CASES["formation-change"]() + LINKS)   # no control_period: continuous-time laws
    assert main(["run", str(path), "--json"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "needs sampled-data control" in err and "control_period" in err
    assert str(path) in err   # the file is named, as the reader's errors name it
    scenario, _ = load_fleet(path)
    with pytest.raises(NonholoInputError, match="sampled-data"):
        simulate(dataclasses.replace(scenario, control_period=None))


def sampled_pair(**links):
    scenario = with_overrides(parse_scenario(CASES["formation-change"]()), **OVERRIDES)
    return dataclasses.replace(scenario, network=LinkSettings(**links) if links else None)


def test_links_change_the_run_and_a_seed_reproduces_it():
    plain = simulate(sampled_pair())
    delayed = simulate(sampled_pair(default=LinkModel(delay=0.04)))
    lossy = [simulate(sampled_pair(seed=seed, default=LinkModel(loss=0.3))) for seed in (5, 5, 6)]
    x = lambda result: result.trajectory("x")[1]   # noqa: E731  the follower
    assert np.abs(x(delayed) - x(plain)).max() > 1e-3
    assert np.array_equal(x(lossy[0]), x(lossy[1]))
    assert not np.array_equal(x(lossy[0]), x(lossy[2])) and not np.array_equal(x(lossy[0]), x(plain))
    ideal = simulate(sampled_pair(seed=3, default=LinkModel()))
    assert np.array_equal(x(ideal), x(plain))   # ideal links: the plain sampled-data run


def test_scenarios_differing_in_their_links_simulate_as_one_batch():
    # Sub-steps fixed: a batch shares one plan (planned alone, each member would plan its own).
    members = [dataclasses.replace(s, substeps=20) for s in
               [sampled_pair(seed=seed, default=LinkModel(delay=delay, jitter=0.02, loss=0.2))
                for seed, delay in ((1, 0.0), (2, 0.02), (2, 0.06))] + [sampled_pair()]]
    batch = simulate(members)
    for b, member in enumerate(members):
        alone = simulate(member)
        for field in ("x", "y", "v", "omega"):
            assert np.array_equal(batch.trajectory(field, member=b), alone.trajectory(field)), (b, field)


def test_a_network_table_without_delay_or_loss_keeps_its_seed_and_watchdog(tmp_path):
    """Ideal links simulate as none, but the table's seed and watchdog stay the scenario's
    (a Monte-Carlo over network.delay draws with them)."""
    from nonholo.sim.files import load_scenario

    path = tmp_path / "ideal.toml"
    path.write_text(star_text(1).replace("duration = 2.0", "duration = 1.0\ndt = 0.01\ncontrol_period = 0.02")
                    + "[network]\nseed = 7\nstale_after = 0.25\n")
    network = load_scenario(path).network
    assert network.ideal and network.seed == 7 and network.watchdog.stale_after == 0.25
    path.write_text(path.read_text().split("[network]")[0])
    assert load_scenario(path).network is None


CIRCLE_PAIR = """name = "circle-pair"
[simulation]
duration = 6.0
dt = 0.01
control_period = 0.05
substeps = 1
[reference]
kind = "circle"
radius = 4.0
period = 25.132741228718345
[[robots]]
name = "leader"
controller = "dynamic-feedback"
start = [4.0, 0.0, 1.5707963267948966]
[[robots]]
name = "f"
formation = "separation-bearing"
leader = "leader"
l = 1.5
phi = 2.5
d = 0.4
gains = { k1 = 2.0, k2 = 2.0 }
start = [5.0, -1.5, 1.8]
"""


def test_prediction_advances_a_delayed_parent_along_its_arc():
    """spec fleet.md §3: with ``predict`` a follower uses its parent's message advanced along
    the exact arc of the parent's command over the message's age. A leader that starts on its
    circle holds the circle's (v_d, ω_d), so its message advanced over any delay is where it
    is: the predicting follower over a delayed link runs as over an ideal one; without
    prediction it lags."""
    scenario = parse_scenario(CIRCLE_PAIR)
    ideal = simulate(scenario)
    leader_v = ideal.trajectory("v")[0]
    assert np.ptp(leader_v[1:]) < 1e-12   # the leader's command is constant (its message's arc is exact)
    delayed = dict(seed=1, default=LinkModel(delay=0.15), watchdog=WatchdogConfig(stale_after=1.0))
    lagging = simulate(dataclasses.replace(scenario, network=LinkSettings(**delayed)))
    predicting = simulate(dataclasses.replace(scenario, network=LinkSettings(**delayed, predict=True)))
    follower = lambda result, f: result.trajectory(f)[1]   # noqa: E731
    late = slice(int(0.2 / 0.01), None)   # from the first message's arrival (and the watchdog's resume)
    for field in ("x", "y", "theta"):
        assert np.abs(follower(lagging, field) - follower(ideal, field))[late].max() > 1e-2, field
    final = lambda result: {k: result.to_dict()["robots"]["f"]["formation"][k]["final"]   # noqa: E731
                            for k in ("l_error", "phi_error")}
    # the predicting follower starts three instants late, then converges as over an ideal link
    # (measured: l error 8.7e-6 m against 7.7e-6 m at 6 s; lagging: 0.12 m)
    for key, value in final(predicting).items():
        assert final(ideal)[key] < value < 1.5 * final(ideal)[key], key
        assert final(lagging)[key] > 500 * final(ideal)[key], key
    # a message of age 0 (an ideal link beside delayed ones) is used as sent, predicting or not
    from nonholo.sim.linkstep import parent_pose

    inbox = np.zeros((5, 2, 1, 1))
    inbox[:, 0, 0, 0] = (1.25, -0.5, 0.3, 0.9, -0.7)
    assert parent_pose(inbox, 0, 0, 0, 0.0, 1.0) == parent_pose(inbox, 0, 0, 0, 0.0, 0.0) == (1.25, -0.5, 0.3)


@pytest.mark.parametrize("case", ["tree-ll", "chain-7"])
def test_centralized_prediction_equals_the_lockstep_fleet(case, tmp_path):
    scenario, config = load_fleet(linked_file(tmp_path, case, LINKS + "predict = true\n"), OVERRIDES)
    assert scenario.network.predict and config.predict
    central = simulate(scenario)
    # the file's [network] config, or (API) none: the scenario's own link model, prediction included
    fleet = run_fleet(scenario, "inproc", config=config if case == "chain-7" else None)
    assert fleet.result.to_dict()["simulation"]["link_model"]["predict"]
    assert_same_result(central, fleet.result)
    plain = simulate(dataclasses.replace(scenario, network=dataclasses.replace(scenario.network, predict=False)))
    assert not np.array_equal(plain.trajectory("x"), central.trajectory("x"))


def test_an_age_of_exactly_stale_after_is_not_stale():
    """An age of three control periods, 3 × 0.05 = 0.15000000000000002 s in floats, does not
    exceed stale_after = 0.15 s (spec fleet.md §5: the follower stops when the age *exceeds*
    it): a follower whose link delays by exactly stale_after follows."""
    from nonholo.sim.watchdog import watchdog_update

    assert 3 * 0.05 > 0.15
    assert watchdog_update(False, 0, 0.0, 0.0, 3 * 0.05, True, 1.0, 2.0, 0.15, 3, 2.0, 8.0, 0.05)[2:4] == (1.0, 2.0)
    assert watchdog_update(False, 0, 1.0, 2.0, 0.1500001, True, 1.0, 2.0, 0.15, 3, 2.0, 8.0, 0.05)[0]   # beyond: stale
    scenario = parse_scenario(CIRCLE_PAIR)
    at_limit = simulate(dataclasses.replace(scenario, network=LinkSettings(
        seed=1, default=LinkModel(delay=0.15), watchdog=WatchdogConfig(stale_after=0.15))))
    beyond = simulate(dataclasses.replace(scenario, network=LinkSettings(
        seed=1, default=LinkModel(delay=0.2), watchdog=WatchdogConfig(stale_after=0.15))))
    assert np.abs(at_limit.trajectory("v")[1]).max() > 0.5
    assert np.abs(beyond.trajectory("v")[1]).max() == 0.0
    # the result says so: stopped at t = 0 (no message yet); at the limit it resumes at the
    # third fresh message (t = 0.15, 0.2, 0.25: stopping at 0 … 0.2, five instants)
    events = lambda result: result.to_dict()["robots"]["f"]["events"]   # noqa: E731
    assert (events(at_limit)["watchdog_stops"], events(at_limit)["watchdog_stopped_s"]) == (1, pytest.approx(0.25))
    # stopped all the run: its 6 s (the instant at its end holds nothing: it is not counted)
    assert scenario.duration == 6.0
    assert (events(beyond)["watchdog_stops"], events(beyond)["watchdog_stopped_s"]) == (1, pytest.approx(6.0))
    assert "watchdog_stops" not in simulate(scenario).to_dict()["robots"]["f"]["events"]   # no link model


@pytest.mark.parametrize("duration", [6.03, 0.05])
def test_the_stopped_time_counts_a_last_period_cut_short_only_as_far_as_the_run_goes(duration):
    """A follower stopped all the run (its parent's states arrive too late) is stopped for the
    run's duration: the last control period (0.03 of 0.05 s) counts 0.03 s, the instant at the
    end of the run (t = 0.05 in a one-period run) nothing; the lockstep fleet counts alike."""
    scenario = parse_scenario(CIRCLE_PAIR.replace("duration = 6.0", f"duration = {duration}"))
    scenario = dataclasses.replace(scenario, network=LinkSettings(
        seed=1, default=LinkModel(delay=0.2), watchdog=WatchdogConfig(stale_after=0.15)))
    central = simulate(scenario).to_dict()["robots"]["f"]["events"]
    assert (central["watchdog_stops"], central["watchdog_stopped_s"]) == (1, pytest.approx(duration, abs=1e-12))
    fleet = run_fleet(scenario, "inproc").result.to_dict()["robots"]["f"]["events"]   # its [network] links
    assert fleet["watchdog_stopped_s"] == pytest.approx(duration, abs=1e-12)


@pytest.mark.parametrize("field", ["decel_v", "decel_omega", "stale_after"])
def test_a_watchdog_that_could_never_stop_is_refused(field, tmp_path, capsys):
    path = tmp_path / "zero.toml"
    path.write_text(CIRCLE_PAIR + f"[network]\ndelay = 0.05\n{field} = 0.0\n")
    assert main(["run", str(path), "--json"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"nonholo run: {path}: network.{field}: must be positive"
