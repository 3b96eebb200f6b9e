"""The follower's watchdog (spec fleet.md §5, comm.md §3.4) as a pure state machine, used
alike by the centralized sampled-data simulator (age = t_k − t_j, inside its compiled
per-instant link step), a lockstep fleet run (the same age) and a realtime one (age measured
on the receiver's monotonic clock from the arrival).

Once per control instant: ``watchdog_step(config, state, age, new, v, omega, period)``
with the age of the oldest parent state in use (``math.inf`` when a parent has sent none
yet), ``new`` whether a state newer than the last one arrived since the previous instant,
and the law's command. While the parent is stale the command ramps to zero within the
deceleration limits and holds there; after ``resume_after`` consecutive instants with a new
state of age ≤ ``stale_after`` the law's command is used again. An age is stale when it
exceeds ``stale_after`` by more than ``TICK_TOLERANCE`` control periods (rounding of k·T).

``watchdog_update`` is the one implementation (compiled, on scalars, so that the
simulator's compiled link step calls it); ``watchdog_step`` is its form on the dataclasses.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from numba import njit

# Times on the control-instant grid are compared with this tolerance, in control periods: an
# age of three periods, 3 × 0.05 = 0.15000000000000002 s, is not beyond ``stale_after`` = 0.15 s,
# and a delay of exactly 2T makes a message usable two instants later (``nonholo.sim.links``).
TICK_TOLERANCE = 1e-9

FOLLOWING, STOPPING = "following", "stopping"
NO_EVENT, STOP, RESUME = 0, 1, 2          # ``watchdog_update``'s event codes
EVENTS = (None, "stop", "resume")


# The watchdog settings that must be positive: a zero age limit stops at once, a zero
# deceleration never stops.
POSITIVE_FIELDS = ("stale_after", "decel_v", "decel_omega")


@dataclass(frozen=True)
class WatchdogConfig:
    stale_after: float = 0.1    # s
    resume_after: int = 3       # consecutive fresh states
    decel_v: float = 2.0        # m/s², the most v may fall per second while stopping
    decel_omega: float = 8.0    # rad/s²

    def __post_init__(self) -> None:
        for name in POSITIVE_FIELDS:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < math.inf:
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if isinstance(self.resume_after, bool) or not isinstance(self.resume_after, int) or self.resume_after < 1:
            raise ValueError(f"resume_after must be a positive integer, got {self.resume_after!r}")


@dataclass(frozen=True)
class WatchdogState:
    mode: str = FOLLOWING
    fresh: int = 0             # consecutive fresh states while stopping
    v: float = 0.0             # the command last output
    omega: float = 0.0


# No fast-math (no FMA contraction): the formation kernels and the fleet's steps compile so.
@njit(cache=True, error_model="numpy")
def toward_zero(value, step):
    """``value`` moved ``step`` (≥ 0) toward zero, not past it."""
    return math.copysign(max(abs(value) - step, 0.0), value) if value else 0.0


@njit(cache=True, error_model="numpy")
def watchdog_update(stopping, fresh, last_v, last_omega, age, new, v, omega, stale_after, resume_after, decel_v,
                    decel_omega, period):
    """One control instant on scalars: ``stopping`` (bool) and ``fresh`` (int) the mode,
    ``last_v``, ``last_omega`` the command last output, ``v``, ``omega`` the law's. Returns
    ``(stopping, fresh, v out, ω out, event)``, event ``NO_EVENT``, ``STOP`` or ``RESUME``."""
    stale = not age <= stale_after + TICK_TOLERANCE * period   # NaN and inf are stale
    event = NO_EVENT
    if stale:
        fresh = 0
        if not stopping:
            stopping, event = True, STOP
    elif stopping and new:
        fresh += 1
        if fresh >= resume_after:
            stopping, fresh, event = False, 0, RESUME
    if stopping:
        v = toward_zero(last_v, decel_v * period)
        omega = toward_zero(last_omega, decel_omega * period)
    return stopping, fresh, v, omega, event


def watchdog_step(config: WatchdogConfig, state: WatchdogState, age: float, new: bool, v: float, omega: float,
                  period: float) -> tuple[WatchdogState, float, float, str | None]:
    """``(next state, v out, ω out, event)``; ``event`` is ``"stop"`` or ``"resume"`` at a
    change of mode, else None."""
    stopping, fresh, v, omega, event = watchdog_update(
        state.mode == STOPPING, int(state.fresh), float(state.v), float(state.omega), float(age), bool(new), float(v),
        float(omega), float(config.stale_after), int(config.resume_after), float(config.decel_v),
        float(config.decel_omega), float(period))
    return WatchdogState(STOPPING if stopping else FOLLOWING, fresh, v, omega), v, omega, EVENTS[event]
