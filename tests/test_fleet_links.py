"""The link model (spec fleet.md §3–4) as a pure draw, a lockstep fleet honouring it (the
same usable-message sequence over TCP as in process), and hostile frames (wrong key,
replayed) rejected and counted without any effect on the motion."""
import asyncio
import dataclasses

import numpy as np
import pytest

from nonholo.comm.envelope import Sealer
from nonholo.comm.transports.inproc import InProcNetwork
from nonholo.fleet.config import NetworkConfig, load_fleet, with_overrides
from nonholo.fleet.keys import fleet_keys
from nonholo.fleet.launch import inproc_programs, run_fleet, run_programs
from nonholo.sim.links import LOST, LinkModel, link_draws, link_schedule, newest_usable, usable_instants
from nonholo.fleet.setup import robot_setups
from nonholo.sim.watchdog import WatchdogConfig, WatchdogState, watchdog_step
from test_fleet_tcp import OVERRIDES, example_text


def test_draws_are_seeded_per_link_and_prefix_stable():
    model = LinkModel(delay=0.01, jitter=0.03, loss=0.2)
    d1, l1 = link_draws(model, 7, "leader", "f1", 50)
    d2, l2 = link_draws(model, 7, "leader", "f1", 200)
    assert np.array_equal(d1, d2[:50]) and np.array_equal(l1, l2[:50])
    d3, _ = link_draws(model, 7, "f1", "f2", 50)
    d4, _ = link_draws(model, 8, "leader", "f1", 50)
    assert not np.array_equal(d1, d3) and not np.array_equal(d1, d4)
    assert (d2 >= 0.01).all() and (d2 <= 0.04).all() and 0.1 < l2.mean() < 0.3


def test_usable_instants_delay_loss_and_order():
    assert list(usable_instants(LinkModel(delay=0.04), 0, "a", "b", 5, 0.02)) == [2, 3, 4, 5, 6]
    assert list(usable_instants(LinkModel(delay=0.03), 0, "a", "b", 3, 0.02)) == [2, 3, 4]
    model = LinkModel(delay=0.0, jitter=0.2, loss=0.3)
    usable = usable_instants(model, 3, "a", "b", 400, 0.02)
    kept = usable[usable != LOST]
    assert (np.diff(kept) >= 0).all()                      # no reordering unless asked
    assert (kept >= np.flatnonzero(usable != LOST)).all()  # never usable before it is sent
    schedule = link_schedule(model, 3, "a", "b", 400, 0.02)
    assert (np.diff(schedule) >= 0).all()
    assert set(schedule[schedule >= 0]) <= set(np.flatnonzero(usable != LOST))
    assert list(newest_usable(np.array([0, LOST, 3, 3]), 5)) == [0, 0, 0, 3, 3]


def test_watchdog_stops_within_deceleration_and_resumes():
    config = WatchdogConfig(stale_after=0.1, resume_after=3, decel_v=1.0, decel_omega=2.0)
    state = WatchdogState()
    state, v, w, event = watchdog_step(config, state, 0.0, True, 0.5, 1.0, 0.1)
    assert (v, w, event) == (0.5, 1.0, None)
    outputs = []
    for _ in range(8):
        state, v, w, event = watchdog_step(config, state, 0.5, False, 0.5, 1.0, 0.1)
        outputs.append((v, w, event))
    assert outputs[0][2] == "stop" and outputs[0][:2] == pytest.approx((0.4, 0.8))
    assert outputs[-1][:2] == (0.0, 0.0)
    for i in range(3):
        state, v, w, event = watchdog_step(config, state, 0.0, True, 0.5, 1.0, 0.1)
    assert event == "resume" and (v, w) == (0.5, 1.0)


def chain(tmp_path, network):
    path = tmp_path / "chain.toml"
    path.write_text(example_text("formation-chain", ("start_relative = [-4.0, 0.0, 0.0]\n", ""),
                                 ("[formation]", network + "\n[formation]")))
    scenario, config = load_fleet(path)
    return path, with_overrides(scenario, **OVERRIDES), config


def test_lockstep_honours_the_link_model_alike_in_process_and_over_tcp(tmp_path):
    from nonholo.fleet.bench import chain_text

    path = tmp_path / "chain.toml"
    path.write_text(chain_text(3) + "[network]\nseed = 11\ndelay = 0.02\njitter = 0.05\nloss = 0.1\n"
                    "stale_after = 0.1\n[[network.links]]\nparent = \"f2\"\nchild = \"f3\"\nloss = 0.5\n")
    scenario, config = load_fleet(path)
    scenario = with_overrides(scenario, **OVERRIDES)
    inproc = run_fleet(scenario, "inproc", config=config)
    tcp = run_fleet(scenario, "tcp", config=config, source=path, overrides=OVERRIDES)
    a, b = inproc.to_dict()["network"], tcp.to_dict()["network"]
    for field in ("x", "y", "theta", "v", "omega"):
        assert np.array_equal(inproc.result.trajectory(field), tcp.result.trajectory(field)), field
    instants = a["control_steps"]
    for name, link in a["links"].items():
        parent, child = name.split("->")
        usable = usable_instants(config.link(parent, child), 11, parent, child, instants, 0.02)
        assert link["lost_by_model"] == (usable == LOST).sum() > 0
        # A follower cancels once it has used its last scheduled state: states after that
        # (never usable to it) may or may not go out, depending on timing.
        assert link["sent"] + link["lost_by_model"] <= instants
        assert link["received"] == link["sent"] and link["rejected"] == 0
        for key in ("age_s", "rejected"):
            assert b["links"][name][key] == link[key]
        # Over TCP the cancel reaches the sender a moment later or sooner than in process: the
        # model's draws are the same, the count stops where the sender stopped.
        over_tcp = b["links"][name]
        assert 0 < over_tcp["lost_by_model"] <= (usable == LOST).sum()
        assert over_tcp["lost_by_model"] == (usable[:over_tcp["sent"] + over_tcp["lost_by_model"]] == LOST).sum()
        ages = (np.arange(instants) - link_schedule(config.link(parent, child), 11, parent, child, instants, 0.02))
        assert link["age_s"]["max"] == pytest.approx(ages[ages <= np.arange(instants)].max() * 0.02)
    events = [e["event"] for e in a["robots"]["f3"]["watchdog"]]
    assert events[:2] == ["stop", "resume"]        # no state usable at t = 0: stopped, then follows


def test_forged_and_replayed_frames_are_rejected_without_effect(tmp_path):
    _, scenario, _ = chain(tmp_path, "")
    scenario = dataclasses.replace(scenario, robots=scenario.robots[:3])
    config = NetworkConfig(transport="inproc")
    setups = robot_setups(scenario)

    def run(attack):
        network = InProcNetwork()
        keys = fleet_keys(scenario.names)
        programs = inproc_programs(scenario, setups, config, "lockstep", 10.0, network, keys)
        if attack:
            deliver, captured = network.deliver, []
            forger = Sealer(b"a key the fleet does not have!!!", key_id=1, sender_id=1)

            def hostile(sender, frame, to):
                deliver(sender, frame, to)
                if sender == "leader" and to == "f1":
                    captured.append(frame)
                    deliver("leader", captured[len(captured) // 2], "f1")                # replay
                    deliver("leader", forger.seal(b"(inform :sender (agent-identifier :name leader))"), "f1")
            network.deliver = hostile
        asyncio.run(run_programs(programs, "lockstep", config))
        return {p.setup.name: p for p in programs}

    clean, attacked = run(False), run(True)
    for name in clean:
        assert np.array_equal(clean[name].states, attacked[name].states)
    rejected = attacked["f1"].tally.rejected["leader"]
    assert rejected == 2 * attacked["leader"].tally.sent["f1"]
    assert attacked["f1"].channel.rejected["ReplayedMessage"] > 0
    assert attacked["f1"].channel.rejected["ForgedMessage"] > 0


def test_a_state_sealed_for_a_sibling_is_rejected_without_effect():
    """The leader's frames to f1, delivered to f2 too (before f2's own): sealed by the leader
    and fresh, but addressed to f1; f2 rejects every one and runs as without them."""
    from nonholo.fleet.bench import star_text
    from nonholo.sim.files import parse_scenario

    scenario = parse_scenario(star_text(2).replace("duration = 2.0", "duration = 1.0\ncontrol_period = 0.02"))
    config = NetworkConfig(transport="inproc")
    setups = robot_setups(scenario)

    def run(attack):
        network = InProcNetwork()
        programs = inproc_programs(scenario, setups, config, "lockstep", 10.0, network, fleet_keys(scenario.names))
        if attack:
            deliver = network.deliver

            def hostile(sender, frame, to):
                if sender == "leader" and to == "f1":
                    deliver("leader", frame, "f2")          # misaddressed: a copy to the sibling first
                deliver(sender, frame, to)
            network.deliver = hostile
        asyncio.run(run_programs(programs, "lockstep", config))
        return {p.setup.name: p for p in programs}

    clean, attacked = run(False), run(True)
    for name in clean:
        assert np.array_equal(clean[name].states, attacked[name].states), name
    assert attacked["f2"].tally.rejected["leader"] == attacked["leader"].tally.sent["f1"] > 0
    assert attacked["f1"].tally.rejected["leader"] == 0


def test_link_health_figure_and_network_table(tmp_path):
    from nonholo.fleet.report import format_network, plot_link_health

    path = tmp_path / "two.toml"
    path.write_text(example_text("formation-circle-switch", ("at = 100.0", "at = 0.5"))
                    + "[network]\nseed = 1\ndelay = 0.02\nloss = 0.2\n")
    scenario, config = load_fleet(path)
    run = run_fleet(with_overrides(scenario, **{**OVERRIDES, "duration": 1.0}), "inproc", config=config)
    text = format_network(run.network)
    assert "leader->follower" in text and max(len(line) for line in text.splitlines()) <= 100
    plot_link_health(run.timelines, run.network, tmp_path / "network.png")
    assert (tmp_path / "network.png").stat().st_size > 10_000


def test_realtime_applies_the_link_delay_and_loss(tmp_path):
    path = tmp_path / "two.toml"
    path.write_text(example_text("formation-circle-switch", ("at = 100.0", "at = 0.5"))
                    + "[network]\nseed = 2\ndelay = 0.03\njitter = 0.01\nloss = 0.2\n")
    scenario, config = load_fleet(path)
    run = run_fleet(with_overrides(scenario, **{**OVERRIDES, "duration": 1.0}), "inproc", "realtime", config=config)
    link = run.network["links"]["leader->follower"]
    assert link["lost_by_model"] > 0 and link["received"] > 0
    assert 0.03 <= link["latency_s"]["p50"] and link["latency_s"]["max"] < 0.2
    assert link["age_s"]["max"] < 0.2
