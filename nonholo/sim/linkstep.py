"""The link model in the centralized sampled-data simulator (spec fleet.md §3–6): at each
control instant every follower computes its command from the newest state of each parent
that its link has delivered, under the watchdog, as a lockstep fleet's robot program does
(``nonholo.fleet.robot``), so that the two runs are equal.

The kernel is not recompiled for it (no compile-time variant): ``integrate_linked`` runs the
kernel one control period at a time (its ``k_start``/``k_stop`` resume), and at each control
instant, between two calls,

1. the kernel's ``evaluate`` gives every root's command at the instant (roots do not listen);
2. ``link_instant`` (compiled once, for every kernel) goes through the robots parents first:
   a follower takes each parent's message of the instant its link's schedule names
   (``nonholo.sim.links.link_schedule``; age (k − j) T, none yet: age ∞), computes its l–φ
   or l–l command from those messages (the parent's pose and command at t_j, with
   ``predict`` the pose advanced along the command's arc over the age, ``unicycle_arc``;
   zero when a parent has delivered nothing yet), passes it through the watchdog
   (``nonholo.sim.watchdog.watchdog_update``) and holds the result; every robot with
   followers then sends its message of the instant (pose, held command) into a ring of the
   last ``depth`` instants;
3. the kernel integrates the period with those commands held (``held_given``); its outputs,
   errors and statistics are those of the true states, as the fleet's result is scored.

Arrays of the link step, for R robots and B copies: ``schedule`` (C, 2, R, B) int64, C
control instants; ``ring`` (5, depth, R, B) the messages (x, y, θ, v, ω) sent;
``inbox`` (5, 2, R, B) the message in use per follower and parent slot; ``used`` (2, R, B)
int64 its index (−1: none yet); ``guard`` (3, R, B) the watchdog's mode (1: stopping),
its count of fresh states and the l–φ bearing's branch as the follower sees it;
``watchdog`` (4, B) stale_after, resume_after, decel_v, decel_omega of each copy;
``predict`` (B,) 1.0 where a copy's followers predict, else 0.0. ``stats``: the kernel's
statistics, whose rows ``WATCHDOG_STOPS`` and ``WATCHDOG_STOPPED`` count each follower's
watchdog stops and the control periods it spent stopping or stopped (an instant's period
counts as far as it lies in the run: ``lived``, 0 for an instant at the run's end).
"""
from __future__ import annotations

import math
import sys
from dataclasses import astuple

import numpy as np
from numba import njit

from nonholo.models.formation_geometry import link_geometry
from nonholo.models.unicycle import unicycle_arc
from nonholo.numerics import sincos
from nonholo.sim import kernel as kn
from nonholo.sim.links import group_schedules
from nonholo.sim.watchdog import STOP, watchdog_update

MESSAGE = 5          # x, y, θ, v, ω
G_MODE, G_FRESH, G_BRANCH = range(3)
GUARD_COUNT = 3


# As the formation kernels and the fleet's follower steps compile: no fast-math, no FMA
# contraction, so that a follower's command here is bit for bit the robot program's.
@njit(cache=True, error_model="numpy")
def link_instant(c, period, lived, state, fields, limits, targets, target_row, offsets, kinds, order, parents, feeds,
                 sin_floor, instant, held, schedule, ring, inbox, used, guard, watchdog, predict, stats):
    """Control instant ``c`` (see the module docstring): sets ``held`` (HELD_COUNT, R, B) of
    every robot from the roots' commands in ``instant`` and the followers' linked commands;
    ``lived``: the part of its period that lies in the run (1, less for a last period cut
    short, 0 at the run's end), as it counts in ``WATCHDOG_STOPPED``."""
    n_batch = state.shape[2]
    depth = ring.shape[1]
    slot_now = c % depth
    target_row = target_row if targets.shape[0] > 1 else 0   # one row: constant targets
    for position in range(order.size):
        r = order[position]
        kind = kinds[r]
        for b in range(n_batch):
            x, y, theta = state[0, r, b], state[1, r, b], state[2, r, b]
            if kind == kn.ROOT_A or kind == kn.ROOT_B:
                for field in range(kn.HELD_COUNT):
                    held[field, r, b] = instant[field, r, b]
            else:
                slots = 1 if kind == kn.SEPARATION_BEARING else 2
                age, new, have = 0.0, False, True
                for slot in range(slots):
                    j = schedule[c, slot, r, b]
                    if j < 0:
                        age, have = math.inf, False
                        continue
                    if j > used[slot, r, b]:   # a newer message is in use from this instant
                        p = parents[slot, r]
                        for field in range(MESSAGE):
                            inbox[field, slot, r, b] = ring[field, j % depth, p, b]
                        used[slot, r, b] = j
                        new = True
                    age = max(age, (c - j) * period)
                v = omega = xi_dot = singular = sat_v = sat_w = 0.0
                if have:
                    o1, o2 = offsets[0, r, b], offsets[1, r, b]
                    z1_d, z2_d = targets[target_row, 0, r] + o1, targets[target_row, 1, r] + o2
                    rate_1, rate_2 = targets[target_row, 2, r], targets[target_row, 3, r]
                    k1, k2, d = fields[kn.K1, r, b], fields[kn.K2, r, b], fields[kn.OFFSET_D, r, b]
                    v_max, omega_max = limits[0, r, b], limits[1, r, b]
                    px, py, ptheta = parent_pose(inbox, 0, r, b, (c - used[0, r, b]) * period, predict[b])
                    if kind == kn.SEPARATION_BEARING:
                        # The bearing moves to its branch from the parent's pose in the message
                        # (the robot program's ``bearing`` step).
                        sin_t, cos_t = sincos(theta)
                        _, raw, _, _, _, _ = link_geometry(px, py, ptheta, x, y, cos_t, sin_t, theta, d)
                        branch = kn.continuous_bearing(raw, guard[G_BRANCH, r, b])
                        guard[G_BRANCH, r, b] = branch
                        v, omega, sat_v, sat_w, _, _, _, _, _, _ = kn.bearing_command(
                            x, y, theta, px, py, ptheta, inbox[3, 0, r, b], inbox[4, 0, r, b], branch, z1_d, z2_d,
                            rate_1, rate_2, k1, k2, d, v_max, omega_max)
                    else:
                        qx, qy, qtheta = parent_pose(inbox, 1, r, b, (c - used[1, r, b]) * period, predict[b])
                        v, omega, sat_v, sat_w, singular, _, _, _, _, _, _, _ = kn.pair_command(
                            x, y, theta, px, py, ptheta, inbox[3, 0, r, b], qx, qy, qtheta, inbox[3, 1, r, b], z1_d,
                            z2_d, rate_1, rate_2, k1, k2, d, sin_floor, v_max, omega_max)
                stopping, fresh, v_out, omega_out, event = watchdog_update(
                    guard[G_MODE, r, b] != 0.0, int(guard[G_FRESH, r, b]), held[kn.HELD_V, r, b],
                    held[kn.HELD_OMEGA, r, b], age, new, v, omega, watchdog[0, b], int(watchdog[1, b]),
                    watchdog[2, b], watchdog[3, b], period)
                guard[G_MODE, r, b] = 1.0 if stopping else 0.0
                stats[kn.WATCHDOG_STOPS, r, b] += 1.0 if event == STOP else 0.0
                stats[kn.WATCHDOG_STOPPED, r, b] += lived if stopping else 0.0
                guard[G_FRESH, r, b] = fresh
                if stopping:
                    v, omega, xi_dot, singular, sat_v, sat_w = v_out, omega_out, 0.0, 0.0, 0.0, 0.0
                held[kn.HELD_V, r, b], held[kn.HELD_OMEGA, r, b], held[kn.HELD_XI_DOT, r, b] = v, omega, xi_dot
                held[kn.HELD_SINGULAR, r, b], held[kn.HELD_SAT_V, r, b] = singular, sat_v
                held[kn.HELD_SAT_OMEGA, r, b] = sat_w
            if feeds[r] != 0:
                ring[0, slot_now, r, b], ring[1, slot_now, r, b], ring[2, slot_now, r, b] = x, y, theta
                ring[3, slot_now, r, b], ring[4, slot_now, r, b] = held[kn.HELD_V, r, b], held[kn.HELD_OMEGA, r, b]


@njit(cache=True, error_model="numpy")
def parent_pose(inbox, slot, r, b, age, predict):
    """The parent pose a follower uses from its message in ``slot``: as sent, or with
    ``predict`` (≠ 0) advanced along the arc of the message's command over ``age`` s."""
    x, y, theta, v, omega = (inbox[0, slot, r, b], inbox[1, slot, r, b], inbox[2, slot, r, b], inbox[3, slot, r, b],
                             inbox[4, slot, r, b])
    if predict != 0.0:
        return unicycle_arc(x, y, theta, v, omega, age)
    return x, y, theta


def linked(group) -> bool:
    """Whether any copy of ``group`` has a link that is not ideal (then it runs the link step)."""
    if not group.followers:
        return False
    for member, indices in group.copies:
        network = group.scenarios[member].network
        if network is None or network.ideal:
            continue
        names = group.scenarios[member].names
        for j, i in enumerate(indices):
            for slot in range(2):
                p = group.parents[slot, j]
                if p >= 0 and not network.link(names[indices[p]], names[i]).ideal:
                    return True
    return False


def integrate_linked(integrate, evaluate, args, scenario, group, outputs, progress: bool = False) -> None:
    """The run of a group with its link model: ``args`` the kernel's leading arguments (as
    ``nonholo.sim.simulator`` packs them), ``outputs`` its (stats, pair_stats, record, held,
    step_rate); see the module docstring."""
    state, fields, limits, rows, row_start, _, targets = args[:7]
    branch = args[12]
    n_steps, every = scenario.n_steps, scenario.hold_every
    period = scenario.dt * every
    instants = len(range(0, n_steps + 1, every))
    n_robots, n_batch = state.shape[1:]
    copies = group.copies
    names = [[group.scenarios[m].robots[i].name for i in indices] for m, indices in copies]
    settings = [group.scenarios[m].network for m, _ in copies]
    schedule, depth = group_schedules(settings, names, group.parents, instants, period)
    watchdog = np.empty((4, n_batch))
    for b, links in enumerate(settings):
        # ideal links (None): every state fresh, the watchdog never acts
        watchdog[:, b] = astuple(links.watchdog) if links is not None else (math.inf, 1, 0.0, 0.0)
    predict = np.array([1.0 if links is not None and links.predict else 0.0 for links in settings])
    ring = np.zeros((MESSAGE, depth, n_robots, n_batch))
    inbox = np.zeros((MESSAGE, 2, n_robots, n_batch))
    used = np.full((2, n_robots, n_batch), -1, dtype=np.int64)
    guard = np.zeros((GUARD_COUNT, n_robots, n_batch))
    guard[G_BRANCH] = branch   # the bearing's branch as each follower sees it (the kernel's: true states)
    instant = np.zeros((kn.INSTANT_COUNT, n_robots, n_batch))
    held = outputs[3]
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n_steps, unit="step", desc=f"{scenario.name}: {n_robots * n_batch} robots", file=sys.stderr)
    try:
        for c in range(instants):
            k = c * every
            row = int(row_start[k])
            evaluate(state, fields, limits, tuple(rows[row]), targets, row, group.offsets, group.kinds, group.order,
                     group.parents, branch, scenario.sin_floor, instant)
            k_stop = min(k + every, n_steps)
            link_instant(c, period, (k_stop - k) / every, state, fields, limits, targets, row, group.offsets,
                         group.kinds, group.order, group.parents, group.feeds, scenario.sin_floor, instant, held,
                         schedule, ring, inbox, used, guard, watchdog, predict, outputs[0])
            # The kernel processes output step k_stop too when it is the last one: stop short of
            # it when it is a control instant (the next pass sets its commands first).
            last = n_steps + 1 if k < n_steps and k_stop == n_steps and n_steps % every == 0 else n_steps
            integrate(*args, k, k_stop, last, *outputs, True)
            if bar is not None:
                bar.update(k_stop - k)
    finally:
        if bar is not None:
            bar.close()
