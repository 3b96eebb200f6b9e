"""The follower's watchdog (spec fleet.md §5, comm.md §3.4) as a pure state machine, used
alike by a lockstep run (age = t_k − t_j), a realtime run (age measured on the receiver's
monotonic clock from the arrival) and the centralized sampled-data simulator.

Once per control instant: ``watchdog_step(config, state, age, new, v, omega, period)``
with the age of the oldest parent state in use (``math.inf`` when a parent has sent none
yet), ``new`` whether a state newer than the last one arrived since the previous instant,
and the law's command. While the parent is stale the command ramps to zero within the
deceleration limits and holds there; after ``resume_after`` consecutive instants with a new
state of age ≤ ``stale_after`` the law's command is used again.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

FOLLOWING, STOPPING = "following", "stopping"


@dataclass(frozen=True)
class WatchdogConfig:
    stale_after: float = 0.1    # s
    resume_after: int = 3       # consecutive fresh states
    decel_v: float = 2.0        # m/s², the most v may fall per second while stopping
    decel_omega: float = 8.0    # rad/s²


@dataclass(frozen=True)
class WatchdogState:
    mode: str = FOLLOWING
    fresh: int = 0             # consecutive fresh states while stopping
    v: float = 0.0             # the command last output
    omega: float = 0.0


def _toward_zero(value: float, step: float) -> float:
    return math.copysign(max(abs(value) - step, 0.0), value) if value else 0.0


def watchdog_step(config: WatchdogConfig, state: WatchdogState, age: float, new: bool, v: float, omega: float,
                  period: float) -> tuple[WatchdogState, float, float, str | None]:
    """``(next state, v out, ω out, event)``; ``event`` is ``"stop"`` or ``"resume"`` at a
    change of mode, else None."""
    stale = not age <= config.stale_after   # NaN and inf are stale
    event = None
    mode, fresh = state.mode, state.fresh
    if stale:
        fresh = 0
        if mode == FOLLOWING:
            mode, event = STOPPING, "stop"
    elif mode == STOPPING and new:
        fresh += 1
        if fresh >= config.resume_after:
            mode, fresh, event = FOLLOWING, 0, "resume"
    if mode == STOPPING:
        v = _toward_zero(state.v, config.decel_v * period)
        omega = _toward_zero(state.omega, config.decel_omega * period)
    return WatchdogState(mode, fresh, v, omega), v, omega, event
