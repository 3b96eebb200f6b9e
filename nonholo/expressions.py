"""Safe parsing of user formulas into sympy expressions.

User strings are never passed to ``eval`` (which ``sympy.parse_expr`` uses internally).
The string is parsed by Python's ``ast`` in expression mode and the tree is rebuilt
node by node from a whitelist: numbers, declared names, + − * / ** (and ^ as a power,
as users of MATLAB write it), unary ±, and calls of known functions.
"""
from __future__ import annotations

import ast
from collections.abc import Mapping

import sympy as sp

from nonholo.errors import ExpressionError

FUNCTIONS: dict[str, object] = {
    "sin": sp.sin, "cos": sp.cos, "tan": sp.tan,
    "asin": sp.asin, "acos": sp.acos, "atan": sp.atan, "atan2": sp.atan2,
    "sinh": sp.sinh, "cosh": sp.cosh, "tanh": sp.tanh,
    "exp": sp.exp, "log": sp.log, "sqrt": sp.sqrt, "abs": sp.Abs, "Abs": sp.Abs,
}
CONSTANTS: dict[str, sp.Expr] = {"pi": sp.pi, "e": sp.E, "E": sp.E}

_BINARY = {
    ast.Add: lambda a, b: a + b,
    ast.Sub: lambda a, b: a - b,
    ast.Mult: lambda a, b: a * b,
    ast.Div: lambda a, b: a / b,
    ast.Pow: lambda a, b: a**b,
}
_UNARY = {ast.USub: lambda a: -a, ast.UAdd: lambda a: a}
MAX_LENGTH = 10_000


def parse_expression(text: str, names: Mapping[str, sp.Expr]) -> sp.Expr:
    """The sympy expression of ``text``, whose free names must be keys of ``names``
    (symbols or numbers), pi/e, or whitelisted function calls.

    >>> t = sp.Symbol("t")
    >>> parse_expression("6*sin(t/15 + 0.3) + 0.2*t", {"t": t})
    0.2*t + 6*sin(t/15 + 0.3)
    """
    if not isinstance(text, str):
        raise ExpressionError(f"expected a formula as a string, got {type(text).__name__}")
    if not text.strip():
        raise ExpressionError("empty formula")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"formula longer than {MAX_LENGTH} characters")
    try:
        # ^ is a power for users; Python's ^ (xor) binds looser than -, so rewrite, not remap.
        tree = ast.parse(text.strip().replace("^", "**"), mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(f"cannot parse {text!r}: {exc.msg} at column {exc.offset}") from None
    try:
        return _build(tree.body, names, text)
    except RecursionError:
        raise ExpressionError(f"formula {text!r} is nested too deeply") from None


def _build(node: ast.AST, names: Mapping[str, sp.Expr], text: str) -> sp.Expr:
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        return sp.Integer(node.value) if isinstance(node.value, int) else sp.Float(node.value)
    if isinstance(node, ast.Name):
        if node.id in names:
            return sp.sympify(names[node.id])
        if node.id in CONSTANTS:
            return CONSTANTS[node.id]
        known = ", ".join(sorted(names)) or "none"
        raise ExpressionError(f"unknown name {node.id!r} in {text!r} (known names: {known}, pi, e)")
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        return _BINARY[type(node.op)](_build(node.left, names, text), _build(node.right, names, text))
    if isinstance(node, ast.UnaryOp) and type(node.op) in _UNARY:
        return _UNARY[type(node.op)](_build(node.operand, names, text))
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and not node.keywords:
        function = FUNCTIONS.get(node.func.id)
        if function is None:
            allowed = ", ".join(sorted(FUNCTIONS))
            raise ExpressionError(f"unknown function {node.func.id!r} in {text!r} (allowed: {allowed})")
        return function(*(_build(arg, names, text) for arg in node.args))
    snippet = ast.get_source_segment(text, node) or type(node).__name__
    raise ExpressionError(f"{snippet!r} is not allowed in a formula ({text!r}): use numbers, names, + - * / ^ and functions")
