"""The four reference trajectories of the thesis's Chapter 5 (spec leader.md §5.1), with
the thesis parameters as defaults. Each is an exact formula, so they share the
expression machinery (exact derivatives)."""
from __future__ import annotations

import numbers

import sympy as sp

from nonholo.errors import ScenarioError
from nonholo.references.base import FORWARD
from nonholo.references.expression import T, ExpressionReference
from nonholo.tomlfile import describe_value


def _number(kind: str, name: str, value) -> sp.Expr:
    """A finite real number (a Python number or a sympy constant such as 40*pi)."""
    if isinstance(value, sp.Basic):
        number = value
    elif isinstance(value, numbers.Real) and not isinstance(value, bool):
        number = sp.Float(value)
    else:
        raise ScenarioError(f"{kind} reference", name, f"expected a number, got {describe_value(value)}")
    if not (number.is_number and number.is_extended_real and number.is_finite):
        raise ScenarioError(f"{kind} reference", name, f"expected a finite real number, got {describe_value(value)}")
    return number


def _period(kind: str, name: str, value) -> sp.Expr:
    """A period or speed scale: finite and positive (a zero period has no reference)."""
    number = _number(kind, name, value)
    if not number.is_positive:
        raise ScenarioError(f"{kind} reference", name, f"expected a positive number, got {describe_value(value)}")
    return number


def _pair(kind: str, name: str, value) -> tuple[sp.Expr, sp.Expr]:
    if not (isinstance(value, (tuple, list)) and len(value) == 2):
        raise ScenarioError(f"{kind} reference", name, f"expected two numbers (x, y), got {describe_value(value)}")
    return _number(kind, f"{name}[0]", value[0]), _number(kind, f"{name}[1]", value[1])


class ThesisReference(ExpressionReference):
    """An ExpressionReference that reports its kind and named parameters."""

    def __init__(self, kind: str, x, y, parameters: dict, default_duration, direction: int = FORWARD):
        self.kind = kind
        super().__init__(x, y, direction, float(default_duration),
                         {k: float(v) for k, v in parameters.items()})

    def describe(self) -> dict:
        return {**super().describe(), "kind": self.kind}


def eight(amplitude_x=10, amplitude_y=10, period_x=40 * sp.pi, period_y=80 * sp.pi,
          direction: int = FORWARD) -> ThesisReference:
    """Test 1, figure eight: x_d = A_x sin(2πt/T_x), y_d = A_y sin(2πt/T_y)
    (thesis: 10 sin(t/20), 10 sin(t/40); one cycle in 80π ≈ 251.33 s)."""
    ax, ay = _number("eight", "amplitude_x", amplitude_x), _number("eight", "amplitude_y", amplitude_y)
    tx, ty = _period("eight", "period_x", period_x), _period("eight", "period_y", period_y)
    x = ax * sp.sin(2 * sp.pi * T / tx)
    y = ay * sp.sin(2 * sp.pi * T / ty)
    params = {"amplitude_x": ax, "amplitude_y": ay, "period_x": tx, "period_y": ty}
    return ThesisReference("eight", x, y, params, sp.Max(tx, ty), direction)


def line(speed=1, heading=sp.pi / 2, start=(0, 0), direction: int = FORWARD) -> ThesisReference:
    """Test 2, straight line: p_d = start + speed·t·(cos heading, sin heading)
    (thesis: (0, t), T = 500 s)."""
    s, h = _number("line", "speed", speed), _number("line", "heading", heading)
    x0, y0 = _pair("line", "start", start)
    params = {"speed": s, "heading": h, "start_x": x0, "start_y": y0}
    return ThesisReference("line", x0 + s * T * sp.cos(h), y0 + s * T * sp.sin(h), params, 500, direction)


def sinusoid(speed=1, amplitude=10, period=2 * sp.pi, direction: int = FORWARD) -> ThesisReference:
    """Test 3, sinusoid: x_d = speed·t, y_d = A sin(2πt/T) (thesis: (t, 10 sin t), T = 1000 s)."""
    s, a = _number("sinusoid", "speed", speed), _number("sinusoid", "amplitude", amplitude)
    p = _period("sinusoid", "period", period)
    params = {"speed": s, "amplitude": a, "period": p}
    return ThesisReference("sinusoid", s * T, a * sp.sin(2 * sp.pi * T / p), params, 1000, direction)


def circle(radius=10, period=40 * sp.pi, center=(0, 0), direction: int = FORWARD) -> ThesisReference:
    """Test 4, circle: p_d = center + R (cos 2πt/T, sin 2πt/T), counter-clockwise
    (thesis: 10 (cos t/20, sin t/20), one lap in 40π ≈ 125.66 s)."""
    r, (cx, cy) = _number("circle", "radius", radius), _pair("circle", "center", center)
    p = _period("circle", "period", period)
    phase = 2 * sp.pi * T / p
    params = {"radius": r, "period": p, "center_x": cx, "center_y": cy}
    return ThesisReference("circle", cx + r * sp.cos(phase), cy + r * sp.sin(phase), params, p, direction)


THESIS_TESTS = {"eight": eight, "line": line, "sinusoid": sinusoid, "circle": circle}
