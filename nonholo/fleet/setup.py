"""What one robot of a fleet needs to know from its scenario: its law and gains, its
parents and children, its start, and the time tables of a sampled-data run (spec
fleet.md §1–2) — taken from the simulator's own packing (``planned_groups``), so a robot
program and the centralized simulator read the same numbers."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nonholo.errors import NonholoInputError
from nonholo.sim import kernel as kn
from nonholo.sim.scenario import Robot, Scenario
from nonholo.sim.simulator import planned_groups
from nonholo.sim.targets import TABLE_COLUMNS

ROOT, BEARING, PAIR = "root", "separation-bearing", "separation-separation"


@dataclass(frozen=True, eq=False)
class RobotSetup:
    """One robot's program data. ``kind``: ``ROOT``, ``BEARING`` or ``PAIR``; ``contract``:
    its group's compile flavour (see ``nonholo.fleet.step``); ``start`` (x, y, θ, ξ);
    ``branch`` an l–φ bearing's initial 2π branch; ``fields`` a root's law fields (goal
    first for a posture law) or a follower's (k1, k2, d, …); ``plan`` RK4 sub-steps per output
    step; ``rows`` (N+1, 10) the reference and ``targets`` (N+1, 6) this follower's targets
    (``nonholo.sim.targets.TABLE_COLUMNS``, offsets included) at the output instants."""

    name: str
    index: int
    kind: str
    parents: tuple[str, ...]
    children: tuple[str, ...]
    contract: bool
    law: object
    gains: type | None
    fields: np.ndarray
    v_max: float
    omega_max: float
    start: np.ndarray
    branch: float
    plan: np.ndarray
    rows: np.ndarray
    targets: np.ndarray
    dt: float
    n_steps: int
    hold_every: int
    sin_floor: float

    @property
    def control_steps(self) -> range:
        """Output steps that are control instants t_k = k T (the last one included when
        the duration is a multiple of T, as in the kernel)."""
        return range(0, self.n_steps + 1, self.hold_every)


def robot_setups(scenario: Scenario, planned: list | None = None) -> dict[str, RobotSetup]:
    """Every robot's setup, by name (sampled-data scenarios only); ``planned``: the
    scenario's ``planned_groups`` if already computed."""
    if scenario.control_period is None:
        raise NonholoInputError("control_period: a fleet runs sampled-data control; set [simulation] "
                                "control_period (a multiple of dt, e.g. 0.02 for 50 Hz)")
    children: dict[str, list[str]] = {r.name: [] for r in scenario.robots}
    for robot in scenario.robots:
        for parent in robot.parents:
            children[parent].append(robot.name)
    index = {name: i for i, name in enumerate(scenario.names)}
    setups = {}
    for item in planned if planned is not None else planned_groups(scenario):
        group = item.group
        branches = group.initial_branches()
        for b, (_, indices) in enumerate(group.copies):
            for j, i in enumerate(indices):
                robot = scenario.robots[i]
                kind = int(group.kinds[j])
                if isinstance(robot, Robot):
                    law, gains = group.laws[kind - kn.ROOT_A]
                    targets = np.zeros((item.rows.shape[0], len(TABLE_COLUMNS)))
                else:
                    law, gains = None, None
                    targets = item.targets[:, :, j].copy()
                    targets[:, [0, 4]] = targets[:, [0, 4]] + group.offsets[0, j, b]   # (and the values just after)
                    targets[:, [1, 5]] = targets[:, [1, 5]] + group.offsets[1, j, b]
                setups[robot.name] = RobotSetup(
                    name=robot.name, index=index[robot.name],
                    kind=ROOT if isinstance(robot, Robot) else robot.law, parents=tuple(robot.parents),
                    children=tuple(children[robot.name]), contract=not group.followers, law=law, gains=gains,
                    fields=group.fields[:, j, b].copy(), v_max=float(group.limits[0, j, b]),
                    omega_max=float(group.limits[1, j, b]), start=group.state[:, j, b].copy(),
                    branch=float(branches[j, b]), plan=item.plan, rows=item.rows, targets=targets, dt=scenario.dt,
                    n_steps=scenario.n_steps, hold_every=scenario.hold_every, sin_floor=scenario.sin_floor)
    return setups
