"""Scenario objects: what to simulate, as plain immutable data."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from nonholo.control.registry import ControllerConfig, controller
from nonholo.errors import NonholoInputError
from nonholo.references.base import Reference

METHODS = ("rk4", "solve_ivp")


@dataclass(frozen=True)
class Robot:
    """A unicycle robot tracking the scenario's reference.

    ``start`` is (x, y, θ) in metres and radians; ``v_max``/``omega_max`` are actuator
    limits (saturation, counted in the results); infinite by default.
    """

    name: str
    controller: ControllerConfig = field(default_factory=lambda: controller("dynamic-feedback"))
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    v_max: float = math.inf
    omega_max: float = math.inf

    def __post_init__(self):
        start = tuple(float(s) for s in self.start)
        if len(start) != 3 or not all(math.isfinite(s) for s in start):
            raise NonholoInputError(f"robot {self.name!r}: start must be three finite numbers [x, y, theta]")
        object.__setattr__(self, "start", start)
        for limit in ("v_max", "omega_max"):
            if not getattr(self, limit) > 0:
                raise NonholoInputError(f"robot {self.name!r}: {limit} must be > 0, got {getattr(self, limit)!r}")


@dataclass(frozen=True)
class Scenario:
    """Robots tracking one reference over ``duration`` seconds.

    Output grid t_k = k·dt, k = 0…N, N = round(duration/dt) (or give ``steps`` = N and
    dt = duration/N). ``substeps``: RK4 sub-steps per output step (None = automatic from
    the law's stiffness, with a refined start for stiff laws). ``control_period``: if set,
    the law runs as sampled-data control with a zero-order hold at that period (a
    multiple of dt); otherwise it is evaluated at every RK4 stage (continuous-time law).
    ``method``: "rk4" (compiled, batch) or "solve_ivp" (scipy, tight tolerances, for
    cross-checks).
    """

    reference: Reference
    robots: tuple[Robot, ...]
    duration: float | None = None
    dt: float | None = None
    steps: int | None = None
    substeps: int | None = None
    control_period: float | None = None
    method: str = "rk4"
    name: str = "scenario"

    def __post_init__(self):
        object.__setattr__(self, "robots", tuple(self.robots))
        if not self.robots:
            raise NonholoInputError("a scenario needs at least one robot")
        names = [r.name for r in self.robots]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise NonholoInputError(f"robot names must be unique, repeated: {', '.join(duplicates)}")
        duration = self.duration if self.duration is not None else self.reference.default_duration
        if duration is None:
            raise NonholoInputError(f"a duration is needed: the {self.reference.kind} reference has no natural one")
        if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
            raise NonholoInputError(f"duration must be a positive number of seconds, got {duration!r}")
        object.__setattr__(self, "duration", float(duration))
        if self.steps is not None:
            if not (isinstance(self.steps, int) and self.steps >= 1):
                raise NonholoInputError(f"steps must be a positive integer, got {self.steps!r}")
            dt_of_steps = self.duration / self.steps
            # A scenario built with steps carries the derived dt (dataclasses.replace passes both).
            if self.dt is not None and not math.isclose(self.dt, dt_of_steps, rel_tol=1e-12):
                raise NonholoInputError("give dt or steps, not both")
            object.__setattr__(self, "dt", dt_of_steps)
        dt = 0.01 if self.dt is None else self.dt
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise NonholoInputError(f"dt must be a positive number of seconds, got {dt!r}")
        if dt > self.duration:
            raise NonholoInputError(f"dt = {dt:g} s is longer than the duration {self.duration:g} s")
        object.__setattr__(self, "dt", float(dt))
        if self.substeps is not None and not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise NonholoInputError(f"substeps must be a positive integer, got {self.substeps!r}")
        if self.method not in METHODS:
            raise NonholoInputError(f"unknown method {self.method!r} (valid: {', '.join(METHODS)})")
        if self.control_period is not None:
            ratio = self.control_period / self.dt if self.control_period > 0 else 0.0
            if not (self.control_period > 0 and abs(ratio - round(ratio)) < 1e-6 and round(ratio) >= 1):
                raise NonholoInputError(
                    f"control_period must be a positive multiple of dt = {self.dt:g} s, got {self.control_period!r}")
            if self.method != "rk4":
                raise NonholoInputError("sampled-data control (control_period) needs method = \"rk4\"")

    @property
    def n_steps(self) -> int:
        return max(1, round(self.duration / self.dt))

    @property
    def hold_every(self) -> int:
        """Output steps between control updates (0 = continuous-time law)."""
        return 0 if self.control_period is None else round(self.control_period / self.dt)
