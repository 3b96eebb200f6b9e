"""Built-in systems.

The unicycle and the two follower models are *not* typed here: their rates come from the
functions the simulator compiles (``nonholo.models``), called through ``.py_func`` with
sympy expressions, and the vector fields are read off as g_i = ∂f/∂u_i (issue 5, item 8).
The car and the unicycle with a trailer exist only for analysis; they reuse the unicycle
model for their tractor.
"""
from __future__ import annotations

import functools
from collections.abc import Callable

import sympy as sp

from nonholo.models.formation_kinematics import bearing_rate, separation_rate
from nonholo.models.unicycle import unicycle_rates

from .system import (ChainedFormTransform, ControlSystem, FlatParametrization,
                     control_affine_from_rates)


def _real(names: str) -> tuple[sp.Symbol, ...]:
    return sp.symbols(names, real=True, seq=True)


def _positive(names: str) -> tuple[sp.Symbol, ...]:
    return sp.symbols(names, positive=True, seq=True)


def _unicycle(v: sp.Expr, omega: sp.Expr, theta: sp.Expr) -> tuple[sp.Expr, sp.Expr, sp.Expr]:
    """(ẋ, ẏ, θ̇) from the simulator's single model definition."""
    return unicycle_rates.py_func(v, omega, sp.cos(theta), sp.sin(theta))


def _system(name: str, description: str, states, inputs, rates, **details) -> ControlSystem:
    drift, fields = control_affine_from_rates(rates, inputs)
    return ControlSystem(name=name, description=description, states=tuple(states),
                         inputs=tuple(inputs), fields=fields, drift=drift, **details)


@functools.cache
def unicycle() -> ControlSystem:
    """Thesis Eq 2.15 / 3.2 with its chained forms (Eq 3.30, corrected Eq 3.32) and flat
    outputs (x, y) (§3.5, spec leader.md §2)."""
    x, y, theta = _real("x y theta")
    v, omega = _real("v omega")
    v_1, v_2 = _real("v_1 v_2")
    eq_3_30 = ChainedFormTransform(
        "Eq 3.30", (x, sp.tan(theta), y), (v_1, v_2),
        (v_1 / sp.cos(theta), v_2 * sp.cos(theta) ** 2))
    z_3 = x * sp.sin(theta) - y * sp.cos(theta)
    eq_3_32 = ChainedFormTransform(  # corrected input map: spec leader.md erratum 3
        "Eq 3.32 (corrected)", (theta, x * sp.cos(theta) + y * sp.sin(theta), z_3), (v_1, v_2),
        (v_2 + z_3 * v_1, v_1))
    return _system(
        "unicycle", "Unicycle / differential-drive robot (thesis Eq 2.15, 3.2)",
        (x, y, theta), (v, omega), _unicycle(v, omega, theta),
        outputs=(x, y), body_frame=(x, y, theta), chained_forms=(eq_3_30, eq_3_32),
        flatness=_unicycle_flatness(x, y))


def _unicycle_flatness(x: sp.Symbol, y: sp.Symbol) -> FlatParametrization:
    # Forward motion (v > 0); spec leader.md §2 gives the backward branch s = −1.
    t = sp.Symbol("t", real=True)
    x_t, y_t = sp.Function("x", real=True)(t), sp.Function("y", real=True)(t)
    dx, dy = x_t.diff(t), y_t.diff(t)
    speed_squared = dx ** 2 + dy ** 2
    return FlatParametrization(
        time=t, flat_outputs=(x_t, y_t), output_map=(x, y),
        states=(x_t, y_t, sp.atan2(dy, dx)),
        inputs=(sp.sqrt(speed_squared), (dx * dy.diff(t) - dy * dx.diff(t)) / speed_squared),
        validity="ẋ² + ẏ² ≠ 0 (the robot is moving)")


@functools.cache
def separation_bearing() -> ControlSystem:
    """l–φ follower (spec follower-posture.md §2.1; thesis Eq 2.24). The leader's
    (v_l, ω_l, θ_l) are known signals sent over the radio link, frozen at the analysis
    instant; they make the leader's motion a drift term. Outputs (φ, θ_f) as in Eq 3.26."""
    separation, bearing, theta_f = (*_positive("l"), *_real("phi theta_f"))
    v_f, omega_f, v_l, omega_l, theta_l = _real("v_f omega_f v_l omega_l theta_l")
    (d,) = _positive("d")
    gamma = theta_l + bearing - theta_f
    rates = (
        separation_rate.py_func(v_f, omega_f, v_l, d, sp.cos(bearing), sp.cos(gamma),
                                sp.sin(gamma)),
        bearing_rate.py_func(v_f, omega_f, v_l, omega_l, separation, d, sp.sin(bearing),
                             sp.cos(gamma), sp.sin(gamma)),
        _unicycle(v_f, omega_f, theta_f)[2],  # the follower's own heading rate
    )
    return _system(
        "separation-bearing", "l–φ follower: separation l, bearing φ, heading θ_f "
        "(spec follower-posture.md §2.1)",
        (separation, bearing, theta_f), (v_f, omega_f), rates, outputs=(bearing, theta_f),
        parameters={str(p): p for p in (d, v_l, omega_l, theta_l)})


@functools.cache
def separation_separation() -> ControlSystem:
    """l–l follower of two leaders (spec follower-posture.md §3.1; thesis Eq 2.28). The
    leaders' speeds, headings and bearings are known signals frozen at the analysis instant.
    Outputs: the two separations it regulates."""
    l_1, l_2, theta_f = (*_positive("l_1 l_2"), *_real("theta_f"))
    v_f, omega_f = _real("v_f omega_f")
    v_1, v_2, theta_1, theta_2, phi_1, phi_2 = _real("v_1 v_2 theta_1 theta_2 phi_1 phi_2")
    (d,) = _positive("d")
    gamma_1, gamma_2 = theta_1 + phi_1 - theta_f, theta_2 + phi_2 - theta_f
    rates = (
        separation_rate.py_func(v_f, omega_f, v_1, d, sp.cos(phi_1), sp.cos(gamma_1),
                                sp.sin(gamma_1)),
        separation_rate.py_func(v_f, omega_f, v_2, d, sp.cos(phi_2), sp.cos(gamma_2),
                                sp.sin(gamma_2)),
        _unicycle(v_f, omega_f, theta_f)[2],
    )
    return _system(
        "separation-separation", "l–l follower: separations l_1, l_2 to two leaders, "
        "heading θ_f (spec follower-posture.md §3.1)",
        (l_1, l_2, theta_f), (v_f, omega_f), rates, outputs=(l_1, l_2),
        parameters={str(p): p for p in (d, v_1, v_2, theta_1, theta_2, phi_1, phi_2)})


@functools.cache
def car() -> ControlSystem:
    """Kinematic car (rear-axle reference point, wheelbase L, steering angle φ driven by
    ω_s): a unicycle whose turn rate is v tan φ / L."""
    x, y, theta, phi = _real("x y theta phi")
    v, omega_s = _real("v omega_s")
    (wheelbase,) = _positive("L")
    rates = (*_unicycle(v, v * sp.tan(phi) / wheelbase, theta), omega_s)
    return _system(
        "car", "Kinematic car: rear-axle position, heading θ, steering angle φ, wheelbase L",
        (x, y, theta, phi), (v, omega_s), rates, outputs=(x, y), body_frame=(x, y, theta),
        parameters={"L": wheelbase})


@functools.cache
def unicycle_trailer() -> ControlSystem:
    """Unicycle towing one trailer hitched at its axle midpoint, hitch length L."""
    x, y, theta, theta_1 = _real("x y theta theta_1")
    v, omega = _real("v omega")
    (hitch,) = _positive("L")
    rates = (*_unicycle(v, omega, theta), v * sp.sin(theta - theta_1) / hitch)
    trailer_axle = (x - hitch * sp.cos(theta_1), y - hitch * sp.sin(theta_1))
    return _system(
        "unicycle-trailer", "Unicycle with one trailer: tractor pose (x, y, θ), trailer "
        "heading θ_1, hitch length L; outputs: the trailer's axle midpoint (its flat output)",
        (x, y, theta, theta_1), (v, omega), rates, outputs=trailer_axle,
        body_frame=(x, y, theta), parameters={"L": hitch})


BUILTIN_SYSTEMS: dict[str, Callable[[], ControlSystem]] = {
    "unicycle": unicycle,
    "separation-bearing": separation_bearing,
    "separation-separation": separation_separation,
    "car": car,
    "unicycle-trailer": unicycle_trailer,
}
