"""Compiled steps of one robot, made of the very functions the centralized kernel inlines
(``nonholo.sim.kernel``), so that a robot program computes bit for bit what the
sampled-data kernel computes for that robot (spec fleet.md §6).

The kernel compiles formations without FMA contraction and lone roots with it; each step
here exists in both flavours (``contract``) and a robot uses its group's.
"""
from __future__ import annotations

from functools import cache

import numpy as np
from numba import njit

from nonholo.models.formation_geometry import link_geometry
from nonholo.numerics import sincos
from nonholo.sim import kernel as kn


def _options(contract: bool) -> dict:
    return dict(cache=True, error_model="numpy", fastmath={"contract"} if contract else False)


def _identify(functions, identity: str) -> None:
    """Deterministic disk-cache identities for closures (see ``kernel.stable_cache_identity``)."""
    for function in functions:
        function._set_uuid(f"{__name__}[{identity}].{function.py_func.__name__}")


@cache
def plant_steps(contract: bool):
    """``(hold, xi_after)``: one output step of the unicycle under a held command (``plan``
    RK4 sub-steps of dt/m, in place on a pose array (3,)), and the law state ξ after it."""
    options = _options(contract)

    @njit(**options)
    def hold(pose, v, omega, dt, m):
        h = dt / m
        x, y, theta = pose[0], pose[1], pose[2]
        for _ in range(m):
            x, y, theta, _ = kn.unicycle_step(x, y, theta, 0.0, v, omega, 0.0, h)
        pose[0], pose[1], pose[2] = x, y, theta

    @njit(**options)
    def xi_after(xi, xi_dot, dt, m):
        h = dt / m
        for _ in range(m):
            xi = xi + h * xi_dot
        return xi

    _identify((hold, xi_after), f"plant|{int(contract)}")
    return hold, xi_after


@cache
def follower_steps(contract: bool):
    """``(bearing, pair)``: an l–φ follower's command (v, ω, sat v, sat ω, new branch) with
    its bearing moved to the branch at this instant, and an l–l follower's command
    (v, ω, singular, sat v, sat ω)."""
    options = _options(contract)

    @njit(**options)
    def bearing(x, y, theta, px, py, ptheta, pv, pomega, branch, l_d, phi_d, l_rate, phi_rate, k1, k2, d, v_max,
                omega_max):
        sin_t, cos_t = sincos(theta)
        _, raw, _, _, _, _ = link_geometry(px, py, ptheta, x, y, cos_t, sin_t, theta, d)
        branch = kn.continuous_bearing(raw, branch)
        v, omega, sat_v, sat_w, _, _, _, _, _, _ = kn.bearing_command(
            x, y, theta, px, py, ptheta, pv, pomega, branch, l_d, phi_d, l_rate, phi_rate, k1, k2, d, v_max,
            omega_max)
        return v, omega, sat_v, sat_w, branch

    @njit(**options)
    def pair(x, y, theta, p1x, p1y, p1theta, p1v, p2x, p2y, p2theta, p2v, l1_d, l2_d, l1_rate, l2_rate, k1, k2, d,
             sin_floor, v_max, omega_max):
        v, omega, sat_v, sat_w, singular, _, _, _, _, _, _, _ = kn.pair_command(
            x, y, theta, p1x, p1y, p1theta, p1v, p2x, p2y, p2theta, p2v, l1_d, l2_d, l1_rate, l2_rate, k1, k2, d,
            sin_floor, v_max, omega_max)
        return v, omega, singular, sat_v, sat_w

    _identify((bearing, pair), f"follower|{int(contract)}")
    return bearing, pair


@cache
def root_step(law, gains, contract: bool):
    """A root's command under ``law`` with field namedtuple class ``gains``:
    ``command(fields (MAX_FIELDS,), x, y, θ, ξ, rows, row, v_max, ω_max)`` →
    (v, ω, ξ̇, singular, sat v, sat ω), the reference read from ``rows[row]``."""
    options = _options(contract)
    n_fields = len(gains._fields)
    kn.stable_cache_identity(law)
    root_command = kn.root_command if contract else kn.root_command_exact

    @njit(**options)
    def command(fields, x, y, theta, xi, rows, row, v_max, omega_max):
        packed = fields.reshape((fields.size, 1, 1))
        v, omega, xi_dot, singular, sat_v, sat_w, _, _ = root_command(
            law, gains(*kn.field_row(packed, 0, 0)[:n_fields]), x, y, theta, xi, kn.row_values(rows, row), v_max,
            omega_max)
        return v, omega, xi_dot, singular, sat_v, sat_w

    _identify((command,), f"root|{law._MemoMixin__uuid}|{int(contract)}")
    return command


def empty_fields() -> np.ndarray:
    return np.zeros(kn.MAX_FIELDS)
