"""What every reference trajectory offers: flat outputs and their derivatives at any
times, the feedforward table the simulator consumes, and a feasibility check."""
from __future__ import annotations

import math
import numbers
from abc import ABC, abstractmethod

import numpy as np

from nonholo.errors import InfeasibleReferenceError, ScenarioError
from nonholo.references.feedforward import table_rows
from nonholo.tomlfile import describe_value

FORWARD, BACKWARD = 1, -1
DIRECTIONS = {"forward": FORWARD, "backward": BACKWARD}


TABLE_PIECE = 16384   # times per piece of a long reference table (``Reference.table``; 4096: 23 % slower)


class Reference(ABC):
    """A planar reference p_d(t) = (x_d(t), y_d(t)), twice differentiable.

    Subclasses implement ``flat_outputs``; everything else derives from it.
    ``direction`` is +1 (drive forward along the path) or −1 (backward).
    """

    kind: str = "reference"

    def __init__(self, direction: int = FORWARD, default_duration: float | None = None):
        if not (isinstance(direction, numbers.Integral) and not isinstance(direction, bool)
                and direction in (FORWARD, BACKWARD)):
            raise ScenarioError(f"{self.kind} reference", "direction",
                                f"expected +1 (forward) or -1 (backward), got {describe_value(direction)}")
        self.direction = direction
        self.default_duration = default_duration

    @abstractmethod
    def flat_outputs(self, t: np.ndarray) -> np.ndarray:
        """(6, len(t)) array: x_d, y_d, ẋ_d, ẏ_d, ẍ_d, ÿ_d at times ``t``."""

    @abstractmethod
    def describe(self) -> dict:
        """Parameters and formulas, for reports and JSON."""

    def table(self, t) -> np.ndarray:
        """Rows (len(t), 10) with the columns of ``feedforward.REF_COLUMNS``. Long tables are
        computed in pieces of ``TABLE_PIECE`` times, so that the formulas' temporary arrays
        stay small (cache-resident, reused by the allocator) whatever the length."""
        t = np.asarray(t, dtype=float).ravel()
        if t.size <= TABLE_PIECE:
            return self._table_piece(t, np.empty((t.size, 10)))
        rows = np.empty((t.size, 10))
        for start in range(0, t.size, TABLE_PIECE):
            self._table_piece(t[start:start + TABLE_PIECE], rows[start:start + TABLE_PIECE])
        return rows

    def _table_piece(self, t: np.ndarray, rows: np.ndarray) -> np.ndarray:
        return table_rows(t, self.flat_outputs(t), self.direction, rows)

    def speed(self, t) -> np.ndarray:
        flat = self.flat_outputs(np.atleast_1d(np.asarray(t, dtype=float)))
        return np.hypot(flat[2], flat[3])

    def vanishing_speed_times(self, t0: float, t1: float, samples: int = 20_001) -> list[float]:
        """Times in [t0, t1] where |ṗ_d| = 0 (to within 1e-9 of the peak speed).

        The speed is sampled on a fine grid; every local minimum below 1e-3 of the
        peak is refined with a bounded scalar minimization, so that zeros between grid
        points (cusps, rest points) are found too. The minimization finds the time only to
        about √eps·|t|, and speed generically vanishes linearly (ṗ_d ≈ p̈_d (t − t*)), so
        its minimum value can stay ~1e-8 of p̈_d above zero: the velocity's closest approach
        to zero on its tangent line there, |ṗ × p̈| / |p̈| at time t − ṗ·p̈ / |p̈|², decides.
        """
        from scipy.optimize import minimize_scalar   # here: scipy.optimize costs every command 0.2 s to import

        t = np.linspace(t0, t1, samples)
        speed = self.speed(t)
        scale = max(1.0, float(speed.max()))
        candidates = np.flatnonzero(speed < 1e-3 * scale)
        zeros: list[float] = []
        for i in candidates:
            if 0 < i < samples - 1 and not (speed[i] <= speed[i - 1] and speed[i] <= speed[i + 1]):
                continue
            lo, hi = t[max(i - 1, 0)], t[min(i + 1, samples - 1)]
            best = minimize_scalar(lambda s: float(self.speed(s)[0]), bounds=(lo, hi), method="bounded",
                                   options={"xatol": 1e-12 * max(1.0, abs(hi))})
            t_min, s_min = (float(best.x), float(best.fun)) if best.fun < speed[i] else (float(t[i]), float(speed[i]))
            _, _, vx, vy, ax, ay = self.flat_outputs(np.array([t_min]))[:, 0]
            accel_sq = ax * ax + ay * ay
            if accel_sq > 0.0:   # the tangent line's closest approach, if it lies in the bracket
                t_line = t_min - (vx * ax + vy * ay) / accel_sq
                s_line = abs(vx * ay - vy * ax) / math.sqrt(accel_sq)
                if lo <= t_line <= hi and s_line < s_min:
                    t_min, s_min = float(t_line), float(s_line)
            if s_min <= 1e-9 * scale and not any(abs(t_min - z) < 1e-6 for z in zeros):
                zeros.append(t_min)
        return zeros

    def check_speed(self, t0: float, t1: float, who: str = "this controller") -> None:
        """Raise ``InfeasibleReferenceError`` naming the times where v_d vanishes."""
        if self.speed(np.linspace(t0, t1, 101)).max() < 1e-12:
            raise InfeasibleReferenceError(f"the reference does not move on [{t0:g}, {t1:g}] s: {who} needs v_d != 0")
        zeros = self.vanishing_speed_times(t0, t1)
        if zeros:
            shown = ", ".join(f"t = {round(z, 9):.6g} s" for z in zeros[:5])   # (to the ns: 0, not 7e-16)
            more = f" and {len(zeros) - 5} more" if len(zeros) > 5 else ""
            raise InfeasibleReferenceError(
                f"reference speed |dp_d/dt| vanishes at {shown}{more}: the feedforward theta_d, omega_d is "
                f"undefined there and {who} needs v_d != 0 (use dynamic-feedback, or a reference that keeps moving)"
            )
