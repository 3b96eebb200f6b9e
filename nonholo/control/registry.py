"""The tracking controllers by name, with their gains, defaults (thesis Table 5.1) and
admissible ranges. A ``TrackingController`` describes a family of laws; a
``ControllerConfig`` is one choice of law and gains, ready for the simulator."""
from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from nonholo.control.cascaded import cascaded_linear_law, cascaded_sine_law
from nonholo.control.feedback_linearization import dynamic_feedback_law, offset_point_law
from nonholo.control.kanayama import kanayama_law
from nonholo.control.linearization import approximate_linearization_law, nonlinear_law
from nonholo.errors import NonholoInputError


@dataclass(frozen=True)
class GainRule:
    """Admissible values of one gain, as a predicate and its wording."""

    holds: Callable[[float], bool]
    wording: str


POSITIVE = GainRule(lambda g: g > 0, "> 0")
NONZERO = GainRule(lambda g: g != 0, "!= 0")
UNIT_INTERVAL = GainRule(lambda g: 0 < g < 1, "in (0, 1)")
ABOVE_MINUS_ONE = GainRule(lambda g: g > -1, "> -1")


@dataclass(frozen=True)
class TrackingController:
    """A family of tracking laws (spec leader.md §3).

    ``gains``: the order of the gain vector the compiled law reads. ``aliases`` map a
    convenience gain to several canonical ones (``kp`` sets ``kp1`` and ``kp2``).
    ``initial_compensator``: the gain that gives ξ(0), if the law has a compensator.
    """

    name: str
    title: str
    source: str
    laws: Mapping[str, Callable]
    gains: tuple[str, ...]
    defaults: Mapping[str, float]
    rules: Mapping[str, GainRule]
    aliases: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    initial_compensator: str | None = None
    needs_moving_reference: bool = True
    stiffness: Callable[[Mapping[str, float], float, float], float] = lambda gains, v_d, omega_d: 0.0
    kind: str = "tracking"

    @property
    def xi_is_speed(self) -> bool:  # TEMP shim until the declaration API lands
        return self.initial_compensator == "xi0"

    @property
    def gain_tuple(self):
        return _gain_tuple(self.name, self.kind, self.gains)

    @property
    def variants(self) -> tuple[str, ...]:
        return tuple(self.laws)

    @property
    def accepted_gains(self) -> tuple[str, ...]:
        extra = (self.initial_compensator,) if self.initial_compensator else ()
        return (*self.gains, *self.aliases, *extra)

    def configure(self, gains: Mapping[str, float] | None = None, variant: str | None = None) -> "ControllerConfig":
        """Validate user gains (defaults fill the rest) and pick a variant."""
        gains = dict(gains or {})
        variant = variant or self.variants[0]
        if variant not in self.laws:
            raise NonholoInputError(f"unknown variant {variant!r} of {self.name} (valid: {', '.join(self.variants)})")
        resolved = dict(self.defaults)
        for name, value in gains.items():
            if name not in self.accepted_gains:
                raise NonholoInputError(
                    f"unknown gain {name!r} for {self.name} (gains: {', '.join(self.accepted_gains)})")
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
                raise NonholoInputError(f"gain {name!r} of {self.name} must be a finite number, got {value!r}")
        for alias, targets in self.aliases.items():
            if alias in gains:
                clash = [t for t in targets if t in gains]
                if clash:
                    raise NonholoInputError(f"gain {alias!r} of {self.name} conflicts with {', '.join(clash)}: give one or the other")
                resolved.update({t: float(gains[alias]) for t in targets})
        resolved.update({k: float(v) for k, v in gains.items() if k not in self.aliases})
        for name, rule in self.rules.items():
            if not rule.holds(resolved[name]):
                raise NonholoInputError(f"gain {name!r} of {self.name} must be {rule.wording}, got {resolved[name]:g}")
        xi0 = resolved.pop(self.initial_compensator, None) if self.initial_compensator else None
        return ControllerConfig(self, variant, MappingProxyType(resolved), xi0)


_TUPLES = {}


def _gain_tuple(name, kind, gains):
    import sys
    from collections import namedtuple
    key = (name, kind)
    if key not in _TUPLES:
        fields = (("goal_x", "goal_y", "goal_theta") if kind == "posture" else ()) + tuple(gains)
        cls = namedtuple(name.replace("-", "_") + "_fields", fields)
        cls.__module__ = __name__
        globals()[cls.__name__] = cls
        _TUPLES[key] = cls
    return _TUPLES[key]


def initial_state(config, v_d0, name):
    if config.controller.kind == "posture":
        return float(config.xi0) if config.controller.initial_compensator else 0.0
    if not config.controller.initial_compensator:
        return 0.0
    if config.xi0 is not None:
        return config.xi0
    if abs(v_d0) < 1e-9:
        from nonholo.errors import InfeasibleReferenceError
        raise InfeasibleReferenceError(
            f"robot {name!r}: xi0 defaults to v_d(0) = {v_d0:.3g}, the singular point of dynamic feedback; "
            "set gains.xi0 to a small non-zero speed of the sign of the intended motion")
    return v_d0


def follower_gains(values):
    for g in ("k1", "k2"):
        v = values[g]
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0):
            raise NonholoInputError(f"gains.{g}: must be > 0, got {v!r}")
    return dict(values)


@dataclass(frozen=True)
class ControllerConfig:
    """One tracking law with its gains. ``xi0`` is ξ(0) for laws with a compensator;
    ``None`` means "the reference speed v_d(0)" (spec §3.6)."""

    controller: TrackingController
    variant: str
    gains: Mapping[str, float]
    xi0: float | None = None

    @property
    def name(self) -> str:
        return self.controller.name

    @property
    def law(self) -> Callable:
        return self.controller.laws[self.variant]

    def gain_vector(self) -> np.ndarray:
        return np.array([self.gains[g] for g in self.controller.gains], dtype=float)

    def stiffness(self, v_d_max: float, omega_d_max: float) -> float:
        """The fastest closed-loop rate (1/s) the law can command; sets sub-stepping."""
        return float(self.controller.stiffness(self.gains, v_d_max, omega_d_max))

    def describe(self) -> dict:
        out = {"controller": self.name, "gains": dict(self.gains)}
        if len(self.controller.variants) > 1:
            out["variant"] = self.variant
        if self.controller.initial_compensator:
            out["xi0"] = self.xi0
        return out


def _scheduled_rate(g, v_d, omega_d):
    return 2 * g["zeta"] * math.sqrt(omega_d**2 + g["b"] * v_d**2) + g["b"] * v_d


CONTROLLERS: dict[str, TrackingController] = {c.name: c for c in (
    TrackingController(
        name="approximate-linearization", title="Approximate linearization",
        source="thesis §4.3 Eq 4.16-4.23; spec §3.1; De Luca, Oriolo & Vendittelli 2001",
        laws={"default": approximate_linearization_law}, gains=("zeta", "b"),
        defaults={"zeta": 0.5, "b": 2.0}, rules={"zeta": UNIT_INTERVAL, "b": POSITIVE},
        stiffness=_scheduled_rate),
    TrackingController(
        name="nonlinear", title="Nonlinear (Samson-type) design",
        source="thesis §4.6 Eq 4.27-4.31; spec §3.2; Samson & Ait-Abderrahim 1991",
        laws={"default": nonlinear_law}, gains=("zeta", "b"),
        defaults={"zeta": 0.5, "b": 2.0}, rules={"zeta": UNIT_INTERVAL, "b": POSITIVE},
        stiffness=_scheduled_rate),
    TrackingController(
        name="cascaded", title="Cascaded design",
        source="thesis §4.4 Eq 4.24-4.25; spec §3.3; Panteley, Lefeber, Loria & Nijmeijer 1998",
        laws={"linear": cascaded_linear_law, "sine": cascaded_sine_law}, gains=("c1", "c2", "c3"),
        defaults={"c1": 216.9, "c2": 1.355, "c3": -0.414},
        rules={"c1": POSITIVE, "c2": POSITIVE, "c3": ABOVE_MINUS_ONE},
        stiffness=lambda g, v_d, omega_d: max(g["c1"], g["c2"], abs(g["c3"]) * omega_d)),
    TrackingController(
        name="kanayama", title="Stable tracking (linearized error model)",
        source="thesis §4.5 Eq 4.26; spec §3.4; Kanayama, Kimura, Miyazaki & Noguchi 1990",
        laws={"default": kanayama_law}, gains=("kx", "ky", "ktheta"),
        defaults={"kx": 10.0, "ky": 0.0064, "ktheta": 0.16},
        rules={"kx": POSITIVE, "ky": POSITIVE, "ktheta": POSITIVE},
        stiffness=lambda g, v_d, omega_d: max(g["kx"], v_d * (math.sqrt(g["ky"]) + g["ktheta"]))),
    TrackingController(
        name="offset-point", title="Static input-output linearization of an offset point",
        source="thesis §4.8 Eq 4.34-4.38; spec §3.5; De Luca, Oriolo & Vendittelli 2001",
        laws={"default": offset_point_law}, gains=("d", "k1", "k2"),
        defaults={"d": 0.5, "k1": 1.0, "k2": 1.0},
        rules={"d": NONZERO, "k1": POSITIVE, "k2": POSITIVE},
        stiffness=lambda g, v_d, omega_d: max(g["k1"], g["k2"], (v_d + abs(g["d"]) * omega_d) / abs(g["d"]))),
    TrackingController(
        name="dynamic-feedback", title="Full-state linearization by dynamic feedback",
        source="thesis §4.9 Eq 4.39-4.50; spec §3.6; Oriolo, De Luca & Vendittelli 2002",
        laws={"default": dynamic_feedback_law}, gains=("kp1", "kp2", "kd1", "kd2", "xi_min"),
        defaults={"kp1": 1.0, "kp2": 1.0, "kd1": 0.7, "kd2": 0.7, "xi_min": 1e-3},
        rules={"kp1": POSITIVE, "kp2": POSITIVE, "kd1": POSITIVE, "kd2": POSITIVE, "xi_min": POSITIVE},
        aliases={"kp": ("kp1", "kp2"), "kd": ("kd1", "kd2")}, initial_compensator="xi0",
        needs_moving_reference=False,
        stiffness=lambda g, v_d, omega_d: max(g["kd1"], g["kd2"], math.sqrt(max(g["kp1"], g["kp2"])))),
)}


def controller(name: str, variant: str | None = None, **gains: float) -> ControllerConfig:
    """A configured tracking controller: ``controller("kanayama", kx=5)``.

    Unknown names list the valid ones; unknown gains list the controller's gains.
    """
    from nonholo.control.posture import POSTURE_CONTROLLERS
    spec = CONTROLLERS.get(name) or POSTURE_CONTROLLERS.get(name)
    if spec is None:
        raise NonholoInputError(f"unknown controller {name!r} (valid: {', '.join(CONTROLLERS)})")
    return spec.configure(gains, variant)
