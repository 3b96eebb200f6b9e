"""Safe parsing of user formulas into sympy expressions (references, system files).

``sympy.parse_expr`` and ``sympify`` evaluate Python code, so a scenario or system file
could run arbitrary commands. Here the string is parsed by Python's ``ast`` in expression
mode and the tree is rebuilt node by node from a whitelist: numbers, declared names,
``+ - * / **`` (``^`` also means power, as in the thesis and MATLAB, with the precedence
of ``**``), unary ``+``/``-`` and calls of a fixed set of functions. Nothing is ever
evaluated as code.
"""
from __future__ import annotations

import ast
from collections.abc import Mapping

import sympy as sp

from nonholo.errors import ExpressionError

FUNCTIONS = {
    "sin": (sp.sin, 1), "cos": (sp.cos, 1), "tan": (sp.tan, 1),
    "asin": (sp.asin, 1), "acos": (sp.acos, 1), "atan": (sp.atan, 1), "atan2": (sp.atan2, 2),
    "sinh": (sp.sinh, 1), "cosh": (sp.cosh, 1), "tanh": (sp.tanh, 1),
    "exp": (sp.exp, 1), "log": (sp.log, 1), "sqrt": (sp.sqrt, 1), "Abs": (sp.Abs, 1), "abs": (sp.Abs, 1),
}
CONSTANTS = {"pi": sp.pi, "E": sp.E}
RESERVED_NAMES = frozenset(FUNCTIONS) | frozenset(CONSTANTS)
MAX_LENGTH = 10_000

_BINARY_OPERATORS = {
    ast.Add: lambda a, b: a + b,
    ast.Sub: lambda a, b: a - b,
    ast.Mult: lambda a, b: a * b,
    ast.Div: lambda a, b: a / b,
    ast.Pow: lambda a, b: a**b,
}


def parse_expression(text: str, names: Mapping[str, sp.Expr]) -> sp.Expr:
    """The sympy expression written in ``text``; ``names`` maps the allowed names to
    symbols or values.

    >>> t = sp.Symbol("t")
    >>> parse_expression("6*sin(t/15 + 0.3) + 0.2*t", {"t": t})
    t/5 + 6*sin(t/15 + 3/10)
    """
    if not isinstance(text, str):
        raise ExpressionError(f"expected an expression string, got {type(text).__name__} {text!r}")
    if not text.strip():
        raise ExpressionError("empty expression")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"expression longer than {MAX_LENGTH} characters")
    try:
        # "^" is power in the thesis' MATLAB notation. Rewriting it before parsing gives it the
        # precedence of "**"; Python's "^" (xor) would bind looser than + and unary minus.
        tree = ast.parse(text.strip().replace("^", "**"), mode="eval")
    except SyntaxError as error:
        raise ExpressionError(f"cannot parse {text!r}: {error.msg}") from None
    try:
        return _build(tree.body, names, text)
    except RecursionError:
        raise ExpressionError(f"expression {text!r} is nested too deeply") from None


def _build(node: ast.AST, names: Mapping[str, sp.Expr], text: str) -> sp.Expr:
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise ExpressionError(f"unsupported constant {node.value!r} in {text!r}")
        # Rational of the decimal text keeps 0.5 exactly 1/2 instead of a binary float.
        return sp.Rational(repr(node.value)) if isinstance(node.value, float) else sp.Integer(node.value)
    if isinstance(node, ast.Name):
        if node.id in names:
            return sp.sympify(names[node.id])
        if node.id in CONSTANTS:
            return CONSTANTS[node.id]
        known = ", ".join(sorted(names)) or "none"
        raise ExpressionError(f"unknown symbol {node.id!r} in {text!r} (known: {known}, pi, E)")
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY_OPERATORS:
        return _BINARY_OPERATORS[type(node.op)](_build(node.left, names, text), _build(node.right, names, text))
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        operand = _build(node.operand, names, text)
        return -operand if isinstance(node.op, ast.USub) else operand
    if isinstance(node, ast.Call):
        return _build_call(node, names, text)
    snippet = ast.get_source_segment(text, node) or type(node).__name__
    raise ExpressionError(f"{snippet!r} is not allowed in {text!r} (use numbers, names, + - * / ^ and functions)")


def _build_call(node: ast.Call, names: Mapping[str, sp.Expr], text: str) -> sp.Expr:
    if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
        called = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
        raise ExpressionError(f"unknown function {called!r} in {text!r} (allowed: {', '.join(sorted(FUNCTIONS))})")
    function, arity = FUNCTIONS[node.func.id]
    if node.keywords or len(node.args) != arity:
        raise ExpressionError(f"{node.func.id} takes {arity} argument(s) in {text!r}")
    return function(*(_build(argument, names, text) for argument in node.args))
