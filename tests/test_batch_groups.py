"""How a batch's copies are grouped for the kernel (``nonholo.sim.simulator._groups``): checked
against the rule written out plainly, one copy at a time, and against runs alone."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from nonholo import examples, references
from nonholo.control.registry import controller
from nonholo.sim import simulator as sm
from nonholo.sim.files import load_scenario
from nonholo.sim.scenario import Robot, Scenario


def test_first_seen_numbers_values_in_order_of_first_appearance():
    first, at = sm.first_seen(np.array([5, 3, 5, 7, 3, 3]))
    assert first.tolist() == [0, 1, 3]
    assert at.tolist() == [0, 1, 0, 2, 1, 1]
    first, at = sm.first_seen(np.array([], dtype=np.int64))
    assert first.size == 0 and at.size == 0
    rng = np.random.default_rng(0)   # small sets are numbered in Python, larger ones with numpy
    for size in (1, sm.SMALL_SET - 1, sm.SMALL_SET, 500):
        values = rng.integers(0, max(2, size // 4), size) * 7919
        first, at = sm.first_seen(values)
        plain = list(dict.fromkeys(values.tolist()))
        assert values[first].tolist() == plain
        assert first.tolist() == [values.tolist().index(v) for v in plain]
        assert at.tolist() == [plain.index(v) for v in values.tolist()]


def plain_groups(scenarios, v_peak, omega_peak):
    """The grouping rule one copy at a time: (member, component) walked member by member,
    component by component; copies of one group share root laws, structure and the prior
    plan of their own rates; groups in the order of their first copies."""
    first = scenarios[0]
    groups: dict[tuple, list] = {}
    for member, scenario in enumerate(scenarios):
        for component in first.components():
            robots = [scenario.robots[i] for i in component]
            local = {robot.name: j for j, robot in enumerate(robots)}
            laws = tuple(dict.fromkeys((r.controller.law, r.controller.controller.gain_tuple)
                                       for r in robots if isinstance(r, Robot)))
            rate = sm._prior_rate(robots, v_peak, omega_peak, {})
            key = (laws, tuple(sm._structure(r, local) for r in robots), sm.prior_parts(first, rate))
            groups.setdefault(key, []).append((member, tuple(component)))
    return list(groups.values())


def mixed_scenario(seed: int) -> Scenario:
    """Lone tracking roots under two laws, a few sharing a configuration object and some
    with gains of their own (some stiff enough for a plan of their own), posture roots, and
    a formation (a leader and two followers)."""
    rng = np.random.default_rng(seed)
    shared = controller("dynamic-feedback")
    stiff = controller("dynamic-feedback", kd=40.0)
    other = controller("kanayama")
    polar = controller("polar")
    chain = load_scenario(examples.path("formation-eight-triangle"))
    robots = list(chain.robots)
    for i in range(40):
        pick = rng.integers(5)
        config = (shared, stiff, other, controller("dynamic-feedback", kp=float(rng.uniform(1, 3))), polar)[pick]
        goal = tuple(rng.normal(size=3)) if config is polar else None
        robots.insert(int(rng.integers(len(robots) + 1)), Robot(f"r{i}", config, tuple(rng.normal(scale=0.3, size=3)),
                                                               goal=goal))
    return Scenario(references.eight(), robots, dt=0.05, duration=2.0)


@pytest.mark.parametrize("seed", [0, 1])
def test_groups_follow_the_plain_rule(seed):
    base = mixed_scenario(seed)
    rng = np.random.default_rng(seed + 10)
    # members that differ in gains, so that a position's copies split over groups
    members = [base] + [dataclasses.replace(base, robots=tuple(
        dataclasses.replace(r, controller=controller("dynamic-feedback", kd=float(rng.choice([0.7, 40.0]))))
        if isinstance(r, Robot) and r.controller.name == "dynamic-feedback" and rng.random() < 0.5 else r
        for r in base.robots)) for _ in range(3)]
    v_peak, omega_peak = sm._reference_survey(base)
    groups = sm._groups(members, v_peak, omega_peak, 0.5)
    expected = plain_groups(members, v_peak, omega_peak)
    assert [group.copies for group in groups] == expected
    assert len(expected) >= 6   # (the case is not trivial: laws, structures and plans differ)
    for group in groups:
        assert group.index.shape == (len(group.members), len(group.robots))
        for b, (member, indices) in enumerate(group.copies):   # each copy's starts, limits and gains
            for j, i in enumerate(indices):
                robot = members[member].robots[i]
                assert tuple(group.state[:3, j, b]) == members[member].initial_poses()[i]
                assert (group.limits[0, j, b], group.limits[1, j, b]) == (robot.v_max, robot.omega_max)
                if isinstance(robot, Robot):
                    gains = robot.controller.gain_vector()
                    start = 3 if robot.posture else 0
                    assert group.fields[start:start + len(gains), j, b].tolist() == list(gains)


def test_a_batch_of_lone_roots_is_one_group_in_scenario_order():
    shared = controller("dynamic-feedback")
    robots = [Robot(f"r{i}", shared, (0.1 * i, 0.0, 0.0)) for i in range(50)]
    scenario = Scenario(references.eight(), robots, dt=0.05, duration=1.0)
    (group,) = sm._groups([scenario], *sm._reference_survey(scenario), 0.5)
    assert group.members.tolist() == [0] * 50 and group.index[:, 0].tolist() == list(range(50))
    record = np.arange(10 * 3 * 50.0).reshape(10, 3, 1, 50)   # (copies of one robot: the member's robots in order)
    view = sm._in_run_layout(group, record, 10, 50, 1)
    assert np.shares_memory(view, record) and view.shape == (10, 3, 50, 1)
    merged = np.full_like(view, np.nan)
    sm._merge_record(merged, record, sm._places(group.index, group.members))
    np.testing.assert_array_equal(view, merged)
    assert group.state[0, 0].tolist() == [0.1 * i for i in range(50)]


def test_members_equal_their_runs_alone():
    """Lone roots of two configurations (two plans, so two groups) over three members that
    give each robot another configuration and start: each robot's statistics equal its run
    alone."""
    slow, stiff = controller("dynamic-feedback"), controller("dynamic-feedback", kd=40.0)
    members = [Scenario(references.eight(), [Robot(f"r{i}", (slow, stiff)[(i + m) % 2], (0.2 * i, -0.1 * m, 0.1 * i))
                                             for i in range(6)], dt=0.05, duration=2.0) for m in range(3)]
    together = sm.simulate(members, record=False)
    for member, scenario in enumerate(members):
        for i, robot in enumerate(scenario.robots):
            alone = sm.simulate(Scenario(references.eight(), [robot], dt=0.05, duration=2.0), record=False)
            np.testing.assert_array_equal(together.stats[:, i, member], alone.stats[:, 0, 0])


def test_a_formation_of_two_root_laws_with_different_gain_counts():
    """An l–l follower of a dynamic-feedback root (five gains) and a Kanayama root (three):
    each root position has its own gain table (one table across positions could not hold
    rows of both lengths, and the set-up failed)."""
    from nonholo.sim.scenario import separation_separation

    roots = [Robot("a", controller("dynamic-feedback", kp=2.0), (0.0, 0.0, 0.0)),
             Robot("b", controller("kanayama", kx=3.0), (0.0, 3.0, 0.0))]
    follower = separation_separation("f", ("a", "b"), (2.0, 2.0), k1=1.5, k2=0.8, start=(-2.0, 1.5, 0.0))
    scenario = Scenario(references.eight(), [*roots, follower], dt=0.01, duration=4.0)
    (group,) = sm._groups([scenario], *sm._reference_survey(scenario), 0.5)
    assert [law for law, _ in group.laws] == [r.controller.law for r in roots]
    for j, robot in enumerate(roots):
        gains = robot.controller.gain_vector()
        assert group.fields[:len(gains), j, 0].tolist() == list(gains)
        assert not group.fields[len(gains):, j, 0].any()
    assert group.fields[[sm.kn.K1, sm.kn.K2], 2, 0].tolist() == [1.5, 0.8]


def _layouts():
    """(index (copies, robots of the graph), members (copies,)) of groups as ``_groups`` makes
    them: lone robots of one member side by side, one robot of many members, graphs of two
    robots across members, and copies scattered over robots and members."""
    return {
        "lone robots of one member": (np.arange(2, 6)[:, None], np.full(4, 1)),
        "one robot of every member": (np.full((5, 1), 3), np.arange(5)),
        "graphs across members": (np.tile([4, 1], (3, 1)), np.array([0, 2, 4])),
        "scattered": (np.array([[0], [6], [2], [5]]), np.array([3, 0, 4, 0])),
    }


@pytest.mark.parametrize("layout", list(_layouts()))
def test_a_group_s_record_lands_where_its_index_says(layout):
    # block copies where the copies lie side by side, element by element elsewhere: the same
    # record as numpy's element-by-element assignment, link rows of a graph without them zero
    index, members = _layouts()[layout]
    rng = np.random.default_rng(1)
    g_record = rng.normal(size=(10, 6, index.shape[1], index.shape[0]))
    expected = np.full((15, 6, 7, 5), np.nan)
    expected[:10, :, index, members[:, None]] = np.moveaxis(g_record, 2, 3)
    expected[10:, :, index, members[:, None]] = 0.0
    merged = np.full_like(expected, np.nan)
    sm._merge_record(merged, g_record, sm._places(index, members))
    np.testing.assert_array_equal(merged, expected)
    assert np.isnan(merged).sum() == merged.size - 15 * 6 * index.size   # (nothing else written)


@pytest.mark.parametrize("case", ["whole members", "lone robots", "robots reversed", "part of the robots"])
def test_a_group_s_record_is_the_run_s_without_a_copy_only_where_its_memory_is_in_the_run_s_order(case):
    # (robots of the graph, copies) read as (robots, members): the same memory in the same
    # order for whole members and for a scenario's lone robots, not otherwise
    index, members = {
        "whole members": (np.tile(np.arange(3), (4, 1)), np.arange(4)),
        "lone robots": (np.arange(12)[:, None], np.zeros(12, dtype=np.int64)),
        "robots reversed": (np.arange(12)[::-1, None], np.zeros(12, dtype=np.int64)),
        "part of the robots": (np.arange(6)[:, None], np.zeros(6, dtype=np.int64)),
    }[case]
    n_robots, n_members = (3, 4) if case == "whole members" else (12, 1)
    group = type("G", (), {"index": index, "members": members})()
    record = np.random.default_rng(2).normal(size=(10, 3, index.shape[1], index.shape[0]))
    view = sm._in_run_layout(group, record, 10, n_robots, n_members)
    if case in ("robots reversed", "part of the robots"):
        assert view is None
        return
    merged = np.full((10, 3, n_robots, n_members), np.nan)
    sm._merge_record(merged, record, sm._places(index, members))
    assert np.shares_memory(view, record)
    np.testing.assert_array_equal(view, merged)
