"""The plant behind a robot program: read its pose, command v and ω.

A real robot's driver takes the simulated unicycle's place by implementing ``Plant``:
``pose()`` returns the latest (x, y, θ) estimate in metres and radians (odometry, motion
capture) and ``command(v, ω)`` sends a saturated command that the drive holds until the
next one. A simulated plant also has ``advance(k)``, with which a lockstep run moves it
over output step k on logical time; a real plant moves by itself.
"""
from __future__ import annotations

import time
from typing import Callable, Protocol

import numpy as np

from nonholo.fleet.step import plant_steps
from nonholo.models.unicycle import unicycle_arc


class Plant(Protocol):
    def pose(self) -> tuple[float, float, float]:
        """The robot's axle pose (x, y, θ) now."""

    def command(self, v: float, omega: float) -> None:
        """Hold linear speed ``v`` (m/s) and turn rate ``omega`` (rad/s) until the next command."""


class SimulatedUnicycle:
    """The kinematic unicycle integrated as the centralized simulator integrates it: over
    output step k, ``plan[k]`` RK4 sub-steps of dt/plan[k] under the held command."""

    def __init__(self, pose, dt: float, plan: np.ndarray, contract: bool) -> None:
        self._pose = np.array(pose[:3], dtype=float)
        self.dt, self.plan = dt, plan
        self.v = self.omega = 0.0
        self._hold, _ = plant_steps(contract)

    def pose(self) -> tuple[float, float, float]:
        return float(self._pose[0]), float(self._pose[1]), float(self._pose[2])

    def command(self, v: float, omega: float) -> None:
        self.v, self.omega = float(v), float(omega)

    def advance(self, k: int) -> None:
        self._hold(self._pose, self.v, self.omega, self.dt, int(self.plan[k]))


class WallClockUnicycle:
    """The simulated unicycle on the wall clock (realtime runs): it moves by itself, as a
    real robot does, along the exact arc of the command it holds; ``pose()`` is its pose now."""

    def __init__(self, pose, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._pose = tuple(float(p) for p in pose[:3])
        self._since = clock()
        self.v = self.omega = 0.0

    def _catch_up(self) -> None:
        now = self._clock()
        self._pose = unicycle_arc(*self._pose, self.v, self.omega, now - self._since)
        self._since = now

    def pose(self) -> tuple[float, float, float]:
        self._catch_up()
        return self._pose

    def command(self, v: float, omega: float) -> None:
        self._catch_up()
        self.v, self.omega = float(v), float(omega)
