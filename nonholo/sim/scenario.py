"""Scenario objects: what to simulate, as plain immutable data."""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field

from nonholo.control.registry import ControllerConfig, controller
from nonholo.errors import NonholoInputError
from nonholo.references.base import Reference

METHODS = ("rk4", "solve_ivp")
MAX_STEPS = 1e8


def _is_real(value) -> bool:
    """A finite real number (numpy scalars included, booleans not)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)


def _is_count(value) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool) and value >= 1


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
        if not isinstance(self.controller, ControllerConfig):
            raise NonholoInputError(f"robot {self.name!r}: controller must come from nonholo.controller(...), "
                                    f"got {self.controller!r}")
        try:
            start = tuple(self.start)
        except TypeError:
            start = ()
        if len(start) != 3 or not all(_is_real(s) for s in start):
            raise NonholoInputError(f"robot {self.name!r}: start must be three finite numbers [x, y, theta], "
                                    f"got {self.start!r}")
        object.__setattr__(self, "start", tuple(float(s) for s in start))
        for limit in ("v_max", "omega_max"):
            value = getattr(self, limit)
            if not (isinstance(value, numbers.Real) and not isinstance(value, bool) and value > 0):
                raise NonholoInputError(f"robot {self.name!r}: {limit} must be a number > 0, got {value!r}")
            object.__setattr__(self, limit, float(value))


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
        if not isinstance(self.reference, Reference):
            raise NonholoInputError(f"reference must be a nonholo reference, got {self.reference!r}")
        try:
            object.__setattr__(self, "robots", tuple(self.robots))
        except TypeError:
            raise NonholoInputError(f"robots must be a list of Robot, got {self.robots!r}") from None
        if not self.robots:
            raise NonholoInputError("a scenario needs at least one robot")
        if not all(isinstance(r, Robot) for r in self.robots):
            raise NonholoInputError("robots must be nonholo.Robot objects")
        names = [r.name for r in self.robots]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise NonholoInputError(f"robot names must be unique, repeated: {', '.join(duplicates)}")
        duration = self.duration if self.duration is not None else self.reference.default_duration
        if duration is None:
            raise NonholoInputError(f"a duration is needed: the {self.reference.kind} reference has no natural one")
        if not (_is_real(duration) and duration > 0):
            raise NonholoInputError(f"duration must be a positive number of seconds, got {duration!r}")
        object.__setattr__(self, "duration", float(duration))
        if self.steps is not None:
            if not _is_count(self.steps):
                raise NonholoInputError(f"steps must be a positive integer, got {self.steps!r}")
            object.__setattr__(self, "steps", int(self.steps))
            dt_of_steps = self.duration / self.steps
            # A scenario built with steps carries the derived dt (dataclasses.replace passes both).
            if self.dt is not None and not math.isclose(self.dt, dt_of_steps, rel_tol=1e-12):
                raise NonholoInputError("give dt or steps, not both")
            object.__setattr__(self, "dt", dt_of_steps)
        dt = 0.01 if self.dt is None else self.dt
        if not (_is_real(dt) and dt > 0):
            raise NonholoInputError(f"dt must be a positive number of seconds, got {dt!r}")
        if dt > self.duration:
            raise NonholoInputError(f"dt = {dt:g} s is longer than the duration {self.duration:g} s")
        object.__setattr__(self, "dt", float(dt))
        if self.substeps is not None:
            if not _is_count(self.substeps):
                raise NonholoInputError(f"substeps must be a positive integer, got {self.substeps!r}")
            object.__setattr__(self, "substeps", int(self.substeps))
        if self.method not in METHODS:
            raise NonholoInputError(f"unknown method {self.method!r} (valid: {', '.join(METHODS)})")
        if self.duration / self.dt > MAX_STEPS:
            raise NonholoInputError(
                f"dt = {self.dt:g} s gives {self.duration / self.dt:.3g} steps over {self.duration:g} s (at most "
                f"{MAX_STEPS:g}): use a larger dt")
        if self.control_period is not None:
            if not (_is_real(self.control_period) and 0 < self.control_period <= self.duration):
                raise NonholoInputError(
                    f"control_period must be a positive number of seconds up to the duration, got {self.control_period!r}")
            ratio = self.control_period / self.dt
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
