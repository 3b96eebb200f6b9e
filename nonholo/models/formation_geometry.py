"""Follower geometry (spec follower-posture.md §1; thesis §2.5, Eq 2.22–2.23 with errata 1–4).

* Castor (offset) point of a robot: P = (x + d cos θ, y + d sin θ), a distance d **ahead**
  of the axle midpoint (erratum 1: Eq 2.22 puts it behind).
* Separation l: from the leader's axle midpoint C_l = (x_l, y_l) to the follower's
  castor point P_f. Bearing φ = atan2(P_fy − y_l, P_fx − x_l) − θ_l (leader body frame,
  counter-clockwise from the leader's heading; φ = π is straight behind).
* Relative heading γ = θ_l + φ − θ_f (the world direction of C_l → P_f minus θ_f).

``link_geometry`` is the compiled scalar form used by the formation kernel; the array
functions below are the same formulas for analysis, tests and scenario set-up.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from nonholo.numerics import array_wrap, sincos


@njit(inline="always", error_model="numpy")
def link_geometry(x_leader, y_leader, theta_leader, x_f, y_f, cos_f, sin_f, theta_f, d):
    """(l, φ, cos φ, sin φ, cos γ, sin γ) of one link, φ unwrapped (atan2 − θ_l).

    The trigonometric values come from the vector C_l → P_f itself, so they are exact
    whatever branch φ is later taken on.
    """
    dx = x_f + d * cos_f - x_leader
    dy = y_f + d * sin_f - y_leader
    separation = math.sqrt(dx * dx + dy * dy)
    direction = math.atan2(dy, dx)
    sin_l, cos_l = sincos(theta_leader)
    cos_a, sin_a = dx / separation, dy / separation
    cos_phi = cos_a * cos_l + sin_a * sin_l
    sin_phi = sin_a * cos_l - cos_a * sin_l
    cos_gamma = cos_a * cos_f + sin_a * sin_f
    sin_gamma = sin_a * cos_f - cos_a * sin_f
    return separation, direction - theta_leader, cos_phi, sin_phi, cos_gamma, sin_gamma


def castor_point(x, y, theta, d):
    """P = (x + d cos θ, y + d sin θ) (arrays broadcast)."""
    return np.asarray(x) + d * np.cos(theta), np.asarray(y) + d * np.sin(theta)


def separation_bearing(leader, follower, d):
    """(l, φ, γ) of a follower pose relative to a leader pose; poses are (x, y, θ) arrays
    (broadcast). φ and γ are wrapped to (−π, π]."""
    xl, yl, tl = (np.asarray(a, dtype=float) for a in leader)
    xf, yf, tf = (np.asarray(a, dtype=float) for a in follower)
    px, py = castor_point(xf, yf, tf, d)
    direction = np.arctan2(py - yl, px - xl)
    return np.hypot(px - xl, py - yl), wrap(direction - tl), wrap(direction - tf)


wrap = array_wrap   # angles wrapped to (−π, π], the spec convention (arrays or scalars)


def place_follower(leader, separation, bearing, theta_f, d):
    """Inverse map: the follower axle pose (x_f, y_f, θ_f) whose castor point lies at
    separation l and bearing φ from the leader pose (x_l, y_l, θ_l)."""
    xl, yl, tl = leader
    px = xl + separation * math.cos(tl + bearing)
    py = yl + separation * math.sin(tl + bearing)
    return px - d * math.cos(theta_f), py - d * math.sin(theta_f), theta_f


def pose_in_frame(frame, relative):
    """World pose of a pose given in the body frame of ``frame`` = (x, y, θ)."""
    x0, y0, t0 = frame
    xr, yr, tr = relative
    c, s = math.cos(t0), math.sin(t0)
    return x0 + c * xr - s * yr, y0 + s * xr + c * yr, t0 + tr


def pair_sin_gamma_difference(leader_1, leader_2, follower, d):
    """sin(γ1 − γ2) of an l–l follower (0 where its castor point and the two leaders'
    axle midpoints are collinear: the singularity of spec §3.2)."""
    _, _, g1 = separation_bearing(leader_1, follower, d)
    _, _, g2 = separation_bearing(leader_2, follower, d)
    return np.sin(g1 - g2)
