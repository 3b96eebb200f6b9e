"""Declaring a control law beside its code: its name, named gains with defaults and
rules, its stiffness and its internal state (docs/controllers-api.md has the recipe).

    @control_law("kanayama", title="Stable tracking (linearized error model)", source="thesis §4.5 Eq 4.26",
                 gains={"kx": Gain(10.0, POSITIVE), "ky": Gain(0.0064, POSITIVE), "ktheta": Gain(0.16, POSITIVE)},
                 stiffness=lambda g, v_d, omega_d: max(g["kx"], v_d * (math.sqrt(g["ky"]) + g["ktheta"])))
    @njit(error_model="numpy", fastmath=False)
    def kanayama_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
        ... gains.kx, gains.ky, gains.ktheta ...

Every law has the signature ``law(x, y, theta, cos_theta, sin_theta, xi, ref, gains) ->
(v, omega, xi_dot, singular)``; ``gains`` is an instance of the law's namedtuple
``spec.gain_tuple`` (fields ``spec.fields``: for posture laws ``goal_x, goal_y,
goal_theta`` first, then the declared gains in declaration order), so a law reads its
gains by name. A wrong declaration fails here, at registration, with one
``ControllerDeclarationError`` line naming the law and the problem.

This module depends only on the standard library and ``nonholo.errors``, so that law
modules can import it without import cycles; ``nonholo.control.registry`` imports the
law modules (the list of built-in laws).
"""
from __future__ import annotations

import collections
import hashlib
import inspect
import keyword
import math
import numbers
import re
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from nonholo.errors import InfeasibleReferenceError, NonholoInputError
from nonholo.numerics import is_real
from nonholo.tomlfile import describe_value

LAW_PARAMETERS = ("x", "y", "theta", "cos_theta", "sin_theta", "xi", "ref", "gains")
GOAL_FIELDS = ("goal_x", "goal_y", "goal_theta")
MAX_LAW_FIELDS = 10
KINDS = ("tracking", "posture")
STATES = ("xi",)  # this version: at most one compensator state, ξ
REFERENCE_SPEED = "reference-speed"
STATE_GAIN = "xi0"  # the optional gain that overrides ξ(0) = v_d(0) of a "reference-speed" law
_KEBAB = re.compile(r"[a-z][a-z0-9]*(-[a-z0-9]+)*")


class ControllerDeclarationError(ValueError):
    """A control-law declaration that cannot be registered (a programming error in the
    law's module, raised when it is imported)."""


@dataclass(frozen=True)
class GainRule:
    """Admissible values of one gain, as a predicate and its wording."""

    holds: Callable[[float], bool]
    wording: str


POSITIVE = GainRule(lambda g: g > 0, "> 0")
NONZERO = GainRule(lambda g: g != 0, "!= 0")
UNIT_INTERVAL = GainRule(lambda g: 0 < g < 1, "in (0, 1)")
ABOVE_MINUS_ONE = GainRule(lambda g: g > -1, "> -1")
ANY = GainRule(lambda g: True, "finite")


@dataclass(frozen=True)
class Gain:
    """One declared gain: its default (a finite number that obeys ``rule``) and rule."""

    default: float
    rule: GainRule = ANY
    doc: str = ""


def _no_stiffness(gains, v_d, omega_d):
    return 0.0


def check_gains(owner: str, values: Mapping, accepted: tuple[str, ...], defaults: Mapping[str, float],
                rules: Mapping[str, GainRule], aliases: Mapping[str, tuple[str, ...]] = MappingProxyType({})) -> dict:
    """User gains resolved against defaults and validated: the one gain check of the
    package (tracking, posture and follower gains). Raises NonholoInputError with a
    one-line message naming ``owner`` and the gain."""
    resolved = dict(defaults)
    for name, value in values.items():
        if name not in accepted:
            raise NonholoInputError(f"unknown gain {name!r} for {owner} (gains: {', '.join(accepted)})")
        if not is_real(value):
            raise NonholoInputError(f"gain {name!r} of {owner} must be a finite number, got "
                                    f"{describe_value(value, typed=False)}")
    for alias, targets in aliases.items():
        if alias in values:
            clash = [t for t in targets if t in values]
            if clash:
                raise NonholoInputError(
                    f"gain {alias!r} of {owner} conflicts with {', '.join(clash)}: give one or the other")
            resolved.update({t: float(values[alias]) for t in targets})
    resolved.update({k: float(v) for k, v in values.items() if k not in aliases})
    for name, rule in rules.items():
        if name in resolved and not rule.holds(resolved[name]):
            raise NonholoInputError(f"gain {name!r} of {owner} must be {rule.wording}, got {resolved[name]:g}")
    return resolved


@dataclass(frozen=True)
class ControlLaw:
    """A registered law family (tracking or posture) and its declaration.

    ``laws``: variant → compiled law; ``gains``: the declared gain names in order (those
    in the gain tuple; the initial-state gain, if any, is not); ``gain_tuple``: the
    namedtuple class the law receives; ``state``/``initial``: the internal state and the
    rule for its initial value (see ``initial_state``).
    """

    name: str
    title: str
    source: str
    kind: str
    laws: Mapping[str, Callable]
    gains: tuple[str, ...]
    defaults: Mapping[str, float]
    rules: Mapping[str, GainRule]
    gain_tuple: type
    aliases: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    state: str | None = None
    initial: float | str | None = None
    xi_is_speed: bool = False
    needs_moving_reference: bool = True
    direction: int | Callable[[Mapping[str, float]], int] = 0
    heading_controlled: bool = True
    goal_relative: bool = True
    stiffness: Callable[[Mapping[str, float], float, float], float] = _no_stiffness

    @property
    def variants(self) -> tuple[str, ...]:
        return tuple(self.laws)

    @property
    def fields(self) -> tuple[str, ...]:
        """Every field of the gain tuple (the goal first for posture laws)."""
        return self.gain_tuple._fields

    @property
    def n_fields(self) -> int:
        return len(self.gain_tuple._fields)

    @property
    def initial_gain(self) -> str | None:
        """The gain that sets the state's initial value (``xi0``), if the law has one."""
        if self.initial == REFERENCE_SPEED:
            return STATE_GAIN
        if isinstance(self.initial, str) and self.initial.startswith("gain:"):
            return self.initial[len("gain:"):]
        return None

    @property
    def initial_compensator(self) -> str | None:
        """Deprecated name of ``initial_gain``."""
        return self.initial_gain

    @property
    def accepted_gains(self) -> tuple[str, ...]:
        extra = (self.initial_gain,) if self.initial_gain else ()
        return (*self.gains, *self.aliases, *extra)

    def configure(self, gains: Mapping[str, float] | None = None, variant: str | None = None) -> "ControllerConfig":
        """Validate user gains (defaults fill the rest) and pick a variant."""
        variant = variant or self.variants[0]
        if variant not in self.laws:
            raise NonholoInputError(f"unknown variant {variant!r} of {self.name} (valid: {', '.join(self.variants)})")
        resolved = check_gains(self.name, dict(gains or {}), self.accepted_gains, self.defaults, self.rules,
                               self.aliases)
        xi0 = resolved.pop(self.initial_gain, None) if self.initial_gain else None
        return ControllerConfig(self, variant, MappingProxyType(resolved), xi0)


    def __repr__(self) -> str:
        variants = f", variants {', '.join(self.variants)}" if len(self.variants) > 1 else ""
        return f"<{self.kind} law {self.name!r}: gains {', '.join(self.accepted_gains) or '-'}{variants}>"


TrackingController = ControlLaw  # the former name


@dataclass(frozen=True)
class ControllerConfig:
    """One law with its gains. ``xi0`` is the value of the law's initial-state gain
    (``spec.initial_gain``); for "reference-speed" laws ``None`` means "the reference
    speed v_d(0)" (spec leader.md §3.6)."""

    controller: ControlLaw
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
        """The gains in the gain tuple's order, without the goal of a posture law (the
        simulator puts the goal first): ``spec.gain_tuple(*goal, *vector)``."""
        return np.array([self.gains[g] for g in self.controller.gains], dtype=float)

    def gain_values(self, goal: tuple[float, float, float] | None = None):
        """The gain tuple itself (``goal`` required for posture laws), e.g. to call a
        law's ``py_func`` from Python."""
        head = () if self.controller.kind == "tracking" else tuple(float(v) for v in goal)
        return self.controller.gain_tuple(*head, *(self.gains[g] for g in self.controller.gains))

    def direction_of(self) -> int:
        """The direction of motion this configuration can follow: +1 forward only, −1
        backward only, 0 both (the law's declared ``direction``, evaluated at these gains)."""
        rule = self.controller.direction
        return int(rule(self.gains)) if callable(rule) else rule

    def stiffness(self, v_d_max: float, omega_d_max: float) -> float:
        """The fastest closed-loop rate (1/s) the law can command; sets sub-stepping."""
        return float(self.controller.stiffness(self.gains, v_d_max, omega_d_max))

    def __repr__(self) -> str:
        """As it would be written: ``controller('kanayama', kx=10, ky=0.0064, ktheta=0.16)``."""
        args = [repr(self.name)]
        if len(self.controller.variants) > 1:
            args.append(f"variant={self.variant!r}")
        args += [f"{name}={value:g}" for name, value in self.gains.items()]
        if self.xi0 is not None:
            args.append(f"{self.controller.initial_gain}={self.xi0:g}")
        return f"controller({', '.join(args)})"

    def describe(self) -> dict:
        out = {"controller": self.name, "gains": dict(self.gains)}
        if len(self.controller.variants) > 1:
            out["variant"] = self.variant
        if self.controller.initial_gain:
            out["xi0"] = self.xi0
        return out


def initial_state(config: ControllerConfig, v_d0: float, robot_name: str) -> float:
    """The initial value of a law's internal state ξ: 0.0 for stateless laws; the
    declared constant (``initial=0.0``); the gain ``xi0`` (``initial="gain:xi0"``); or for
    ``initial="reference-speed"`` the given ``xi0`` else the reference speed v_d(0), which
    must not be zero (spec leader.md §3.6)."""
    spec = config.controller
    if spec.state is None:
        return 0.0
    if spec.initial == REFERENCE_SPEED:
        if config.xi0 is not None:
            return float(config.xi0)
        if abs(v_d0) < 1e-9:
            raise InfeasibleReferenceError(
                f"robot {robot_name!r}: xi0 defaults to v_d(0) = {v_d0:.3g}, the singular point of dynamic feedback; "
                "set gains.xi0 to a small non-zero speed of the sign of the intended motion")
        return float(v_d0)
    if spec.initial_gain:
        return float(config.xi0)
    return float(spec.initial)


# ------------------------------------------------------------------ the registry

LAWS: dict[str, ControlLaw] = {}          # every registered law, tracking and posture
CONTROLLERS: dict[str, ControlLaw] = {}   # tracking laws (kept in step by registration)
POSTURE_CONTROLLERS: dict[str, ControlLaw] = {}
_BY_KIND = {"tracking": CONTROLLERS, "posture": POSTURE_CONTROLLERS}


def _fail(name, problem: str):
    raise ControllerDeclarationError(f"control law {name!r}: {problem}")


def _check_function(name, variant: str, function) -> None:
    py_func = getattr(function, "py_func", None)
    if py_func is None or not callable(function):
        _fail(name, f"variant {variant!r} must be a compiled law (decorate it with @njit(error_model=\"numpy\") "
                    f"below @control_law), got {function!r}")
    try:
        parameters = inspect.signature(py_func).parameters.values()
    except (TypeError, ValueError):
        _fail(name, f"variant {variant!r}: cannot read the signature of {py_func!r}")
    plain = all(p.kind == p.POSITIONAL_OR_KEYWORD and p.default is p.empty for p in parameters)
    names = tuple(p.name for p in parameters)
    if names != LAW_PARAMETERS or not plain:
        found = ", ".join(map(str, parameters))
        _fail(name, f"variant {variant!r} ({py_func.__qualname__}) has the signature ({found}), "
                    f"expected ({', '.join(LAW_PARAMETERS)}) without defaults")
    # numba compiles a function that does not choose its floating-point options with those of
    # the compiled code that calls it first: a law first called by a kernel that fuses
    # multiply-adds would keep them in every later kernel, and results would depend on the
    # order of runs. A law states its own (IEEE, no fusion) unless it chose otherwise.
    options = getattr(function, "targetoptions", None)
    if isinstance(options, dict):
        options.setdefault("fastmath", False)
        options.setdefault("error_model", "numpy")


def _gain_tuple(name: str, fields: tuple[str, ...], module_name: str) -> type:
    """The law's namedtuple class, picklable by reference: it is a global of the law's
    module under a unique name (numba's disk cache pickles it with the kernels). The name
    holds a digest of the fields in order: the cache keys of compiled code that reads the
    gains by position then change when a declaration reorders or renames them (a pickle by
    reference holds the name only)."""
    digest = hashlib.sha256(",".join(fields).encode()).hexdigest()[:10]
    qualname = f"_GainTuple_{name.replace('-', '_')}_{digest}"
    cls = collections.namedtuple(qualname, fields)
    cls.__module__ = module_name
    cls.__qualname__ = qualname
    module = sys.modules.get(module_name)
    if module is not None:
        setattr(module, qualname, cls)
    return cls


def _normalise_initial(name, state, initial, gains: Mapping[str, Gain]):
    if state is None:
        if initial is not None:
            _fail(name, f"initial={initial!r} given without a state (declare state=\"xi\")")
        return None
    if not isinstance(state, str):
        _fail(name, f"state must be one name, got {state!r}: at most one compensator state (\"xi\") in this version")
    if state not in STATES:
        _fail(name, f"unknown state {state!r}: this version has at most one compensator state, \"xi\"")
    if initial is None:
        _fail(name, f"state {state!r} needs its initial value rule: initial=\"{REFERENCE_SPEED}\", a number, "
                    "or \"gain:<name>\"")
    if isinstance(initial, bool):
        _fail(name, f"unknown initial={initial!r}")
    if isinstance(initial, numbers.Real):
        if not math.isfinite(initial):
            _fail(name, f"initial={initial!r} must be finite")
        return float(initial)
    if initial == REFERENCE_SPEED:
        if STATE_GAIN in gains:
            _fail(name, f"gain {STATE_GAIN!r} is implied by initial=\"{REFERENCE_SPEED}\" (optional, default v_d(0)): "
                        "do not declare it")
        return initial
    if isinstance(initial, str) and initial.startswith("gain:"):
        gain = initial[len("gain:"):]
        if gain not in gains:
            _fail(name, f"initial={initial!r} names an undeclared gain {gain!r} (gains: {', '.join(gains)})")
        return initial
    _fail(name, f"unknown initial={initial!r} (valid: \"{REFERENCE_SPEED}\", a number, or \"gain:<name>\")")


def control_law(name: str, *, title: str, source: str, gains: Mapping[str, Gain], kind: str = "tracking",
                variant: str = "default", aliases: Mapping[str, tuple[str, ...]] | None = None,
                state: str | None = None, initial: float | str | None = None, xi_is_speed: bool | None = None,
                stiffness: Callable[[Mapping[str, float], float, float], float] | None = None,
                needs_moving_reference: bool | None = None, direction: int | Callable = 0,
                heading_controlled: bool = True, goal_relative: bool = True):
    """Register the decorated compiled law under ``name`` (its first variant ``variant``).

    ``gains``: name → ``Gain(default, rule)`` in the order the gain tuple takes them;
    ``aliases``: a convenience gain setting several (``{"kp": ("kp1", "kp2")}``);
    ``state="xi"`` with ``initial`` = ``"reference-speed"`` (ξ(0) = v_d(0) unless gain
    ``xi0`` is given), a number, or ``"gain:<name>"`` (a declared gain, kept out of the
    gain tuple); ``xi_is_speed``: ξ is a speed, so |ξ̇/ξ| is a rate (default: True for the
    speed-like initial rules); ``stiffness(gains, v_d_max, omega_d_max)``: the fastest
    closed-loop rate (1/s); ``needs_moving_reference`` (default: True for tracking laws):
    the law needs v_d ≠ 0; ``direction`` (tracking laws): the direction of motion the law can
    follow, +1 forward only (v_d > 0), −1 backward only, 0 both (default), or a function of the
    gains giving one of these; a reference driven the other way is refused (``direction_of``);
    ``heading_controlled`` (posture laws): the final heading is
    regulated; ``goal_relative`` (posture laws): the law reads the pose only relative to its
    goal, as the spec's laws do (``goal_frame_pose``), so the simulator may integrate it with
    the goal as origin (full precision near the goal); False for a law that reads the world
    frame itself. Returns the law unchanged.
    """

    def register(function):
        if not isinstance(name, str) or not _KEBAB.fullmatch(name):
            _fail(name, "the name must be lower-case kebab-case (letters, digits and single dashes, e.g. \"my-law\")")
        if name in LAWS:
            first = next(iter(LAWS[name].laws.values()))
            where = getattr(getattr(first, "py_func", first), "__module__", "another module")
            _fail(name, f"already registered (by {where}): choose another name")
        if kind not in KINDS:
            _fail(name, f"unknown kind {kind!r} (valid: {', '.join(KINDS)})")
        if not isinstance(variant, str) or not variant:
            _fail(name, f"variant must be a non-empty string, got {variant!r}")
        _check_function(name, variant, function)
        if not isinstance(gains, Mapping):
            _fail(name, f"gains must be a mapping of name to Gain(default, rule), got {type(gains).__name__}")
        for gain, declared in gains.items():
            if not isinstance(gain, str) or not gain.isidentifier() or keyword.iskeyword(gain) or gain.startswith("_"):
                _fail(name, f"gain name {gain!r} is not a Python identifier (without a leading underscore)")
            if gain in GOAL_FIELDS:
                _fail(name, f"gain name {gain!r} collides with the goal fields {', '.join(GOAL_FIELDS)}")
            if not isinstance(declared, Gain):
                _fail(name, f"gain {gain!r} must be declared as Gain(default, rule), got {declared!r}")
            default = declared.default
            if isinstance(default, bool) or not isinstance(default, numbers.Real) or not math.isfinite(default):
                _fail(name, f"gain {gain!r}: the default must be a finite number, got {default!r}")
            if not isinstance(declared.rule, GainRule):
                _fail(name, f"gain {gain!r}: the rule must be a GainRule (e.g. POSITIVE), got {declared.rule!r}")
            if not declared.rule.holds(float(default)):
                _fail(name, f"gain {gain!r}: the default {default:g} violates its own rule ({declared.rule.wording})")
        alias_map = {a: tuple(t) if not isinstance(t, str) else (t,) for a, t in (aliases or {}).items()}
        for alias, targets in alias_map.items():
            if not isinstance(alias, str) or not alias.isidentifier():
                _fail(name, f"alias {alias!r} is not a Python identifier")
            if alias in gains:
                _fail(name, f"alias {alias!r} is also a gain name")
            unknown = [t for t in targets if t not in gains]
            if unknown or not targets:
                _fail(name, f"alias {alias!r} refers to unknown gain(s) {', '.join(map(repr, unknown)) or '(none)'} "
                            f"(gains: {', '.join(gains)})")
        initial_rule = _normalise_initial(name, state, initial, gains)
        by_gain = isinstance(initial_rule, str) and initial_rule.startswith("gain:")
        initial_gain = initial_rule[len("gain:"):] if by_gain else None
        if initial_rule == REFERENCE_SPEED and STATE_GAIN in alias_map:
            _fail(name, f"alias {STATE_GAIN!r} collides with the initial-state gain")
        tuple_gains = tuple(g for g in gains if g != initial_gain)
        if initial_gain and any(initial_gain in t for t in alias_map.values()):
            _fail(name, f"gain {initial_gain!r} sets the initial state: no alias may set it")
        fields = (GOAL_FIELDS if kind == "posture" else ()) + tuple_gains
        if len(fields) > MAX_LAW_FIELDS:
            _fail(name, f"{len(fields)} gain-tuple fields ({', '.join(fields)}), at most {MAX_LAW_FIELDS}")
        law_stiffness = _no_stiffness if stiffness is None else stiffness
        if not callable(law_stiffness):
            _fail(name, f"stiffness must be a function (gains, v_d, omega_d) -> rate, got {stiffness!r}")
        defaults = {g: float(d.default) for g, d in gains.items()}
        try:
            rate = float(law_stiffness(MappingProxyType(defaults), 1.0, 1.0))
        except Exception as exc:  # noqa: BLE001 - reported as a declaration error
            _fail(name, f"stiffness fails on the default gains: {type(exc).__name__}: {exc}")
        if not (rate >= 0.0):
            _fail(name, f"stiffness must be a rate >= 0 (1/s), got {rate!r} on the default gains")
        moving = kind == "tracking" if needs_moving_reference is None else bool(needs_moving_reference)
        if kind == "posture" and (moving or direction != 0):
            _fail(name, "a posture law does not read the reference: needs_moving_reference must be False and "
                        "direction 0")
        try:
            follows = direction(MappingProxyType(defaults)) if callable(direction) else direction
        except Exception as exc:  # noqa: BLE001 - reported as a declaration error
            _fail(name, f"direction fails on the default gains: {type(exc).__name__}: {exc}")
        if isinstance(follows, bool) or follows not in (-1, 0, 1):
            _fail(name, f"direction must be +1 (forward only), -1 (backward only), 0 (both) or a function of the "
                        f"gains giving one of these, got {follows!r}")
        if xi_is_speed is None:  # ξ(0) = v_d(0) or a kick speed: ξ is a speed
            speed = initial_rule == REFERENCE_SPEED or initial_gain is not None
        else:
            speed = bool(xi_is_speed)
        if speed and state is None:
            _fail(name, "xi_is_speed=True without a state")
        spec = ControlLaw(
            name=name, title=title, source=source, kind=kind, laws={variant: function}, gains=tuple_gains,
            defaults=MappingProxyType(defaults),
            rules=MappingProxyType({g: d.rule for g, d in gains.items() if d.rule is not ANY}),
            gain_tuple=_gain_tuple(name, fields, function.py_func.__module__),
            aliases=MappingProxyType(alias_map), state=state, initial=initial_rule, xi_is_speed=speed,
            needs_moving_reference=moving, direction=direction, heading_controlled=bool(heading_controlled),
            goal_relative=bool(goal_relative), stiffness=law_stiffness)
        LAWS[name] = spec
        _BY_KIND[kind][name] = spec
        return function

    return register


def _add_variant(name: str, variant: str):
    """``@control_law.variant("cascaded", "sine")``: another law of a registered family
    (same gains, state and stiffness)."""

    def register(function):
        spec = LAWS.get(name)
        if spec is None:
            _fail(name, f"variant {variant!r} of an unregistered law: declare the law with @control_law first")
        if not isinstance(variant, str) or not variant:
            _fail(name, f"variant must be a non-empty string, got {variant!r}")
        if variant in spec.laws:
            _fail(name, f"variant {variant!r} is already registered")
        _check_function(name, variant, function)
        spec.laws[variant] = function
        return function

    return register


control_law.variant = _add_variant


def unregister(name: str) -> None:
    """Remove a registered law (for tests that register laws of their own)."""
    spec = LAWS.pop(name, None)
    if spec is not None:
        _BY_KIND[spec.kind].pop(name, None)
