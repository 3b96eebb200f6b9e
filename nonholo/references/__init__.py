"""Reference trajectories and their flatness feedforward (spec leader.md §2).

>>> from nonholo import references
>>> ref = references.eight()                    # thesis Test 1
>>> ref.table([0.0])[0, 7:]                     # theta_d, v_d, omega_d at t = 0
array([0.46364761, 0.55901699, 0.        ])
"""
from nonholo.references.base import BACKWARD, DIRECTIONS, FORWARD, Reference
from nonholo.references.expression import ExpressionReference
from nonholo.references.feedforward import REF_COLUMNS, feedforward
from nonholo.references.thesis import THESIS_TESTS, circle, eight, line, sinusoid
from nonholo.references.waypoints import WaypointReference

expression = ExpressionReference.from_strings
waypoints = WaypointReference

KINDS = (*THESIS_TESTS, "expression", "waypoints")

__all__ = [
    "BACKWARD", "DIRECTIONS", "FORWARD", "KINDS", "REF_COLUMNS", "THESIS_TESTS", "ExpressionReference", "Reference",
    "WaypointReference", "circle", "eight", "expression", "feedforward", "line", "sinusoid", "waypoints",
]
