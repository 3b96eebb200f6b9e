"""nonholo: collaborative nonholonomic robots.

>>> import nonholo as nh
>>> scenario = nh.Scenario(nh.references.eight(), [nh.Robot("leader", nh.controller("dynamic-feedback"))])
>>> result = nh.simulate(scenario)
>>> print(f"{result.metrics.error_mean[0]:.5f} m")
0.00194 m
"""
__version__ = "0.1.0"

from nonholo import numba_cache  # noqa: E402  (first: before any module compiles)

numba_cache.install()

from nonholo import references  # noqa: E402
from nonholo.control.registry import CONTROLLERS, controller  # noqa: E402
from nonholo.errors import (ExpressionError, FormationError, InfeasibleReferenceError,  # noqa: E402
                            NonholoInputError, ScenarioError, SimulationError)
from nonholo.sim.files import load_scenario, parse_scenario  # noqa: E402
from nonholo.sim.result import SimulationResult  # noqa: E402
from nonholo.sim.scenario import Change, Follower, Robot, Scenario, separation_bearing, separation_separation  # noqa: E402
from nonholo.sim.simulator import simulate  # noqa: E402

__all__ = [
    "CONTROLLERS", "Change", "ExpressionError", "Follower", "FormationError", "InfeasibleReferenceError",
    "NonholoInputError", "Robot", "Scenario", "ScenarioError", "SimulationError", "SimulationResult", "controller",
    "load_scenario", "parse_scenario", "references", "separation_bearing", "separation_separation", "simulate",
]
