"""Leader–follower formations (spec follower-posture.md §1–4; thesis §2.5, 4.11, 5.5).

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
from nonholo.formation.geometry import castor_point, place_follower, separation_bearing as link_state
from nonholo.formation.model import (FORMATION_LAWS, SEPARATION_BEARING, SEPARATION_SEPARATION, Change, Follower,
                                     Formation, FormationError, Leader, separation_bearing, separation_separation,
                                     topological_order)
from nonholo.formation.result import FormationResult
from nonholo.formation.simulator import simulate_formation

__all__ = [
    "FORMATION_LAWS", "SEPARATION_BEARING", "SEPARATION_SEPARATION", "Change", "Follower", "Formation",
    "FormationError", "FormationResult", "Leader", "castor_point", "link_state", "place_follower",
    "separation_bearing", "separation_separation", "simulate_formation", "topological_order",
]
