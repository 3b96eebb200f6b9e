"""Posture stabilisers: drive a unicycle to a goal pose (x_g, y_g, θ_g) (thesis §4.10,
Eq 4.51–4.55 and 5.11–5.14; spec follower-posture.md §5, errata 10, 11, 13, 25–29).

All three laws are written for the goal at the origin with heading 0; a goal pose is
handled by first expressing the robot in the goal frame (spec §5, not stated in the thesis):

    x = cos θ_g (X − X_g) + sin θ_g (Y − Y_g),   y = −sin θ_g (X − X_g) + cos θ_g (Y − Y_g),
    θ̃ = θ − θ_g.

* ``time-varying`` (Eq 4.51 + 5.11, Samson-style, spec §5.1): the nonlinear tracking law
  with constant gains tracks a point x_d on the goal's x-axis that keeps moving while the
  lateral error e2 is non-zero. x_d is carried in the compensator slot ξ:

      ẋ_d = −k5 x_d + g,   g = tanh(k6 e2 / 2) · sin t   (bounded, |g| ≤ 1; erratum 25)
      v = v_d cos e3 + k1 e1,   ω = k2 v_d (sin e3 / e3) e2 + k3 e3,   v_d = ẋ_d, ω_d = 0.

* ``polar`` (Aicardi et al. 1995, Eq 4.52–4.54, spec §5.2): ψ = ‖(x, y)‖,
  φ = atan2(−y, −x), μ = wrap(φ − θ̃);  v = k1 ψ cos μ,
  ω = k2 μ + k1 (sin μ cos μ / μ)(μ + k3 φ); v = ω = 0 once ψ < ``tolerance``.

* ``dynamic-feedback-posture`` (Eq 4.55, spec §5.3): the dynamic compensator ξ = v with a
  PD law on the goal-frame position, r1 = −kp1 x − kd1 ẋ, r2 = −kp2 y − kd2 ẏ,
  ξ̇ = r1 cos θ̃ + r2 sin θ̃, ω = (r2 cos θ̃ − r1 sin θ̃) / ξ. ξ(0) must be non-zero (a
  small "kick", default +0.1 m/s). Where |ξ| < ξ_min (default 1e-9 m/s) the robot does
  not turn (ω = 0, counted as a singular sample): this happens only as it comes to rest at
  the goal, where ω = (…)/ξ is round-off over round-off and would spin the parked robot. **The final
  heading is not controlled by this law**: the robot arrives along the goal's x-axis,
  heading θ_g or θ_g + π depending on the initial conditions.

Signature: the tracking-law signature ``law(x, y, θ, cos θ, sin θ, ξ, ref, gains)`` of
``nonholo.control.linearization`` with ``ref[0]`` the time and the goal in the gain
tuple: posture laws are declared with ``kind="posture"``, so their gain tuple has the
fields ``goal_x, goal_y, goal_theta`` first, then the gains (``nonholo.control.declare``),
and the kernel runs posture and tracking robots alike.
"""
from __future__ import annotations

import math

from numba import njit

from collections.abc import Iterator, Mapping

from nonholo.control.declare import GOAL_FIELDS, POSITIVE, POSTURE_CONTROLLERS, Gain, GainRule, control_law
from nonholo.control.tracking_errors import tracking_errors
from nonholo.errors import NonholoInputError
from nonholo.numerics import sinc_of, sincos, wrap_angle

GOAL_SLOTS = len(GOAL_FIELDS)  # goal_x, goal_y, goal_theta precede the gains in the gain tuple
NONZERO_KICK = GainRule(lambda g: g != 0, "!= 0 (a robot at rest is the singular point of dynamic feedback)")


@njit(inline="always", error_model="numpy")
def goal_frame_pose(x, y, theta, gains):
    """Robot pose (x, y, θ̃) in the frame of the goal (gains.goal_x, goal_y, goal_theta)."""
    sin_g, cos_g = sincos(gains.goal_theta)
    dx, dy = x - gains.goal_x, y - gains.goal_y
    return cos_g * dx + sin_g * dy, -sin_g * dx + cos_g * dy, theta - gains.goal_theta


@njit(inline="always", error_model="numpy")
def excitation(e2, t, k6):
    """g(e, t) = tanh(k6 e2 / 2) · sin t: the corrected Eq 5.11 (|g| ≤ 1, odd in e2)."""
    return math.tanh(0.5 * k6 * e2) * math.sin(t)


@control_law("time-varying", kind="posture", title="Smooth time-varying posture feedback",
             source="thesis Eq 4.51, 5.11-5.12; spec follower-posture.md §5.1 (errata 10, 25, 26); Samson 1993",
             gains={"k1": Gain(0.5, POSITIVE), "k2": Gain(2.0, POSITIVE), "k3": Gain(1.0, POSITIVE),
                    "k5": Gain(1.0, POSITIVE), "k6": Gain(50.0, POSITIVE)},
             state="xi", initial=0.0, xi_is_speed=False,
             stiffness=lambda g, v, w: max(g["k1"], g["k3"], g["k5"]))
@njit(error_model="numpy", fastmath=False)
def time_varying_posture_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    """Spec §5.1. ξ is x_d, the moving point on the goal's x-axis (x_d(0) = 0)."""
    k1, k2, k3, k5, k6 = gains.k1, gains.k2, gains.k3, gains.k5, gains.k6
    gx, gy, gtheta = goal_frame_pose(x, y, theta, gains)
    sin_t, cos_t = sincos(gtheta)
    # e2 does not depend on v_d: evaluate the errors once against x_d, then form v_d.
    e1, e2, e3 = tracking_errors(gx, gy, gtheta, cos_t, sin_t, (ref[0], xi, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    v_d = -k5 * xi + excitation(e2, ref[0], k6)
    sin_e3, cos_e3 = sincos(e3)
    v = v_d * cos_e3 + k1 * e1
    omega = k2 * v_d * sinc_of(e3, sin_e3) * e2 + k3 * e3
    return v, omega, v_d, 0.0


@control_law("polar", kind="posture", title="Polar-coordinate posture law",
             source="thesis Eq 4.52-4.54, 5.13; spec §5.2 (errata 11, 28); Aicardi et al. 1995",
             gains={"k1": Gain(1.0, POSITIVE), "k2": Gain(3.0, POSITIVE), "k3": Gain(2.0, POSITIVE),
                    "tolerance": Gain(1e-9, POSITIVE)},
             stiffness=lambda g, v, w: max(g["k1"], g["k2"]))
@njit(error_model="numpy", fastmath=False)
def polar_posture_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    """Spec §5.2 (Aicardi et al.), angles wrapped to (−π, π]; stop below the tolerance."""
    gx, gy, gtheta = goal_frame_pose(x, y, theta, gains)
    return polar_command(math.sqrt(gx * gx + gy * gy), gx, gy, gtheta, gains)


@njit(inline="always", error_model="numpy")
def polar_command(psi, gx, gy, gtheta, gains):
    """(v, ω, 0, 0) of the polar law at distance ψ from the goal and goal-frame pose
    (gx, gy, gθ): φ the direction to the goal, μ = φ − gθ."""
    k1, k2, k3, tolerance = gains.k1, gains.k2, gains.k3, gains.tolerance
    phi = wrap_angle(math.atan2(-gy, -gx))   # in (−π, π]: atan2 gives −π for gy = +0.0 ahead of the goal
    mu = wrap_angle(phi - gtheta)
    sin_mu, cos_mu = sincos(mu)
    v = k1 * psi * cos_mu
    omega = k2 * mu + k1 * sinc_of(mu, sin_mu) * cos_mu * (mu + k3 * phi)
    moving = psi >= tolerance
    return (v if moving else 0.0), (omega if moving else 0.0), 0.0, 0.0


@control_law("dynamic-feedback-posture", kind="posture", title="Dynamic feedback linearization posture regulator",
             source="thesis Eq 4.55, 5.14; spec §5.3 (errata 13, 29); Oriolo, De Luca & Vendittelli 2002",
             gains={"kp1": Gain(2.0, POSITIVE), "kd1": Gain(3.0, POSITIVE), "kp2": Gain(12.0, POSITIVE),
                    "kd2": Gain(7.0, POSITIVE), "xi_min": Gain(1e-9, POSITIVE), "xi0": Gain(0.1, NONZERO_KICK)},
             state="xi", initial="gain:xi0", heading_controlled=False,
             stiffness=lambda g, v, w: max(g["kd1"], g["kd2"]))
@njit(error_model="numpy", fastmath=False)
def dynamic_feedback_posture_law(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    """Spec §5.3: PD on the goal-frame position through the compensator ξ = v."""
    kp1, kd1, kp2, kd2, xi_min = gains.kp1, gains.kd1, gains.kp2, gains.kd2, gains.xi_min
    gx, gy, gtheta = goal_frame_pose(x, y, theta, gains)
    sin_t, cos_t = sincos(gtheta)
    r1 = -kp1 * gx - kd1 * xi * cos_t
    r2 = -kp2 * gy - kd2 * xi * sin_t
    singular = abs(xi) < xi_min
    # Both sides of the select are computed in SIMD code: divide by 1 where ξ ≈ 0.
    omega = 0.0 if singular else (r2 * cos_t - r1 * sin_t) / (xi if not singular else 1.0)
    return xi, omega, r1 * cos_t + r2 * sin_t, 1.0 if singular else 0.0


class _HeadingControlled(Mapping):
    """Posture law name → whether it regulates the final heading (live view of the registry)."""

    def __getitem__(self, name: str) -> bool:
        return POSTURE_CONTROLLERS[name].heading_controlled

    def __iter__(self) -> Iterator[str]:
        return iter(POSTURE_CONTROLLERS)

    def __len__(self) -> int:
        return len(POSTURE_CONTROLLERS)


HEADING_CONTROLLED: Mapping[str, bool] = _HeadingControlled()


def posture_controller(name: str, **gains: float):
    """A configured posture stabiliser, e.g. ``posture_controller("polar", k2=4)``."""
    spec = POSTURE_CONTROLLERS.get(name)
    if spec is None:
        raise NonholoInputError(f"unknown posture controller {name!r} (valid: {', '.join(POSTURE_CONTROLLERS)})")
    return spec.configure(gains)
