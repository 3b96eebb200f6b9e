"""Formation targets over time: initial targets and run-time changes (thesis Eq 5.9;
spec follower-posture.md §2.5, erratum 22).

The targets z_d(t) of a follower and their rates ż_d(t) are evaluated into a table at
every RK4 stage time, like the leader's reference. A step switches for t > at: the sample
at t = at still shows the old target (its error is the old target's), as does a control
instant at t = at under sampled-data control (the new target is used from the next one).
Under continuous-time control the RK4 step that ends at ``at`` integrates the old target
throughout and the step that starts there the new one throughout: its first stage, at t =
at itself, takes the target just after ``at`` (the table's ``_after`` columns), so a step on
the output grid (or on a sub-step boundary) is integrated as exactly as the rest of the
run. (Taking the old target at that stage, as nonholo did before, left a first-order error:
thesis Eq 5.9 with dt = 0.01 s ended 9 mm and 0.005 rad off the ideal step.) A step inside
a sub-step takes effect at the next stage time. A ramp follows
the quintic smoothstep s(τ) = 10τ³ − 15τ⁴ + 6τ⁵, τ = (t − at)/T, whose rate
ż_d = Δ s'(τ)/T is fed forward, so the output error of an exact follower stays zero.

Bearings are kept on a continuous branch: a bearing target φ_new is resolved against the
previous target by the change's ``direction``, so that (π/3 → 4π/3, "counterclockwise")
is the thesis's Eq 5.9 switch with the castor point passing behind the leader.
"""
from __future__ import annotations

import math

import numpy as np

from nonholo.errors import FormationError

TAU = 2.0 * math.pi
TABLE_COLUMNS = ("output_1_d", "output_2_d", "output_1_d_rate", "output_2_d_rate", "output_1_d_after",
                 "output_2_d_after")
"""A target table's columns: the targets and their rates at each time (a step counted from
just after its time), then the targets just after each time (a step counted at its time)."""
EVENT_TOLERANCE = 1e-9
# |Δφ| this close to π is ambiguous under "shortest" (spec §2.5): the turn is decided by round-off.
AMBIGUOUS_TURN = 1e-6


def smoothstep(tau):
    """s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ on [0, 1] (C² ramp from 0 to 1)."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)


def smoothstep_rate(tau):
    """s'(τ) = 30τ²(1 − τ)², zero outside (0, 1)."""
    inside = (tau > 0.0) & (tau < 1.0)
    return np.where(inside, 30.0 * tau * tau * (1.0 - tau) ** 2, 0.0)


def resolve_bearing(previous: float, new: float, direction: str, follower: str = "?", where: str = "phi") -> float:
    """The value of φ_new on the 2π branch reached from ``previous`` turning in ``direction``."""
    if direction == "counterclockwise":
        turn = (new - previous) % TAU
    elif direction == "clockwise":
        turn = -((previous - new) % TAU)
    else:
        turn = (new - previous + math.pi) % TAU - math.pi
        if abs(abs(turn) - math.pi) < AMBIGUOUS_TURN:
            raise FormationError(follower, where,
                                 f"a bearing change of ±π ({previous:.6g} -> {new:.6g} rad) is ambiguous under "
                                 "direction = 'shortest': set direction = 'counterclockwise' (castor point passes "
                                 "behind the leader for φ ≈ π/3) or 'clockwise', or ramp it")
    return previous + turn


def target_segments(follower) -> list[list[tuple[float, float, float, float]]]:
    """Per output, the changes as (at, from, to, ramp duration) with bearings resolved."""
    current = list(follower.targets)
    segments: list[list[tuple[float, float, float, float]]] = [[], []]
    for j, change in enumerate(follower.changes):
        for output, name in enumerate(follower.outputs):
            if name not in change.targets:
                continue
            new = float(change.targets[name])
            if name == "phi":
                new = resolve_bearing(current[output], new, change.direction, follower.name, f"changes[{j}].phi")
            ramp = change.duration if change.mode == "ramp" else 0.0
            segments[output].append((change.at, current[output], new, ramp))
            current[output] = new
    return segments


def target_table(follower, times: np.ndarray) -> np.ndarray:
    """(len(times), 6): output targets and their rates at ``times``, then the targets just
    after ``times`` (``TABLE_COLUMNS``; the two differ only at a step's own time)."""
    times = np.asarray(times, dtype=float)
    table = np.zeros((times.size, len(TABLE_COLUMNS)))
    for output, segments in enumerate(target_segments(follower)):
        value = np.full(times.size, follower.targets[output])
        value_after = value.copy()
        rate = np.zeros(times.size)
        for at, start, end, ramp in segments:
            tolerance = EVENT_TOLERANCE * max(1.0, abs(at))
            after = times > at + tolerance
            if ramp == 0.0:
                value = np.where(after, end, value)
                value_after = np.where(times > at - tolerance, end, value_after)   # a step counted at its time
            else:   # continuous: the same either way
                tau = (times - at) / ramp
                ramped = start + (end - start) * smoothstep(tau)
                value, value_after = np.where(after, ramped, value), np.where(after, ramped, value_after)
                rate = rate + (end - start) * smoothstep_rate(tau) / ramp
        table[:, output] = value
        table[:, 2 + output] = rate
        table[:, 4 + output] = value_after
    return table


