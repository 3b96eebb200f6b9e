"""Leader–follower formations (spec follower-posture.md §1–4; thesis §2.5, 4.11, 5.5), in
the words of the thesis, over the one model of a fleet (``nonholo.sim.scenario``): a
formation is a ``Scenario`` whose graph has followers, a leader is a root ``Robot``.

>>> from nonholo import controller, references
>>> from nonholo.formation import Formation, Leader, separation_bearing, simulate_formation
>>> import math
>>> leader = Leader("leader", controller("dynamic-feedback", kp=1.0, kd=0.7),
...                 start=(0.0, 0.0, math.atan2(0.25, 0.5)))
>>> follower = separation_bearing("f1", "leader", l=2.0, phi=math.pi / 3,
...                               start=(-4.0, 0.0, 0.0), start_frame="leader")
>>> result = simulate_formation(Formation([leader, follower], references.eight(), duration=10.0))
>>> print(f"{result.follower_metrics('f1')['l_error']['final']:.1e} m")
4.5e-05 m
"""
from __future__ import annotations

import math

from nonholo.errors import FormationError
from nonholo.models.formation_geometry import castor_point, place_follower
from nonholo.models.formation_geometry import separation_bearing as link_state
from nonholo.sim.result import SimulationResult as FormationResult
from nonholo.sim.scenario import (FORMATION_LAWS, SEPARATION_BEARING, SEPARATION_SEPARATION, Change, Follower, Robot,
                                  Scenario, separation_bearing, separation_separation, topological_order)
from nonholo.sim.simulator import simulate as simulate_formation


def Formation(robots, reference=None, **options) -> Scenario:  # noqa: N802 (the thesis's name for a scenario)
    """A scenario of ``robots`` (roots and followers), in the argument order of the thesis's
    formations: ``Formation(robots, reference, duration=…, dt=0.01, …)``."""
    options.setdefault("name", "formation")
    return Scenario(reference, robots, **options)


def Leader(name, controller, start=(0.0, 0.0, 0.0), goal=None, v_max=math.inf, omega_max=math.inf) -> Robot:  # noqa: N802
    """A root robot: tracks the reference or, with ``goal``, stabilises to it."""
    return Robot(name, controller, start, v_max, omega_max, goal)


__all__ = [
    "FORMATION_LAWS", "SEPARATION_BEARING", "SEPARATION_SEPARATION", "Change", "Follower", "Formation",
    "FormationError", "FormationResult", "Leader", "castor_point", "link_state", "place_follower",
    "separation_bearing", "separation_separation", "simulate_formation", "topological_order",
]
