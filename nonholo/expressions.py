"""Safe parsing of user formulas into sympy expressions (references, system files).

``sympy.parse_expr`` and ``sympify`` evaluate Python code, so a scenario or system file
could run arbitrary commands. Here the string is parsed by Python's ``ast`` in expression
mode and the tree is rebuilt node by node from a whitelist: numbers, declared names,
``+ - * / **`` (``^`` also means power, as in the thesis and MATLAB, with the precedence
of ``**``), unary ``+``/``-`` and calls of a fixed set of functions. Nothing is ever
evaluated as code.

Limits, applied while parsing so that neither Python's parser nor sympy ever recurses
deeply or computes a huge number (every violation is one ``ExpressionError`` line):

* at most ``MAX_LENGTH`` characters and ``MAX_TOKENS`` tokens (numbers, names,
  operators, brackets), counted by ``tokenize`` before ``ast.parse`` runs;
* at most ``MAX_NESTING`` levels of brackets, calls, powers and signs inside one another
  (a chain ``a + b - c + …`` or ``a * b / c …`` is one level, however long);
* only plain decimal numbers (no ``0x10``, ``1_000``, ``1j``), each finite in floating
  point; no control or invisible characters, no character that Python would silently
  read as another (``ｔ`` is ``t``);
* a numeric exponent at most ``MAX_EXPONENT`` in size (``MAX_COMPLEX_EXPONENT`` if the
  base may be complex), and no power that would build an exact number of more than
  ``MAX_POWER_BITS`` bits (``10**10**10`` would take hours);
* no infinite or undefined value (``1/0``, ``log(0)``) and no constant beyond the
  floating-point range;
* at most ``MAX_SYMBOLIC_STEPS`` steps of symbolic work (``symbolic_budget``), the
  backstop for what sympy does beyond these limits.
"""
from __future__ import annotations

import ast
import io
import keyword
import math
import re
import sys
import threading
import tokenize
import unicodedata
from collections.abc import Mapping
from contextlib import contextmanager

import sympy as sp

from nonholo.errors import ExpressionError, NonholoInputError
from nonholo.tomlfile import describe_value

FUNCTIONS = {
    "sin": (sp.sin, 1), "cos": (sp.cos, 1), "tan": (sp.tan, 1),
    "asin": (sp.asin, 1), "acos": (sp.acos, 1), "atan": (sp.atan, 1), "atan2": (sp.atan2, 2),
    "sinh": (sp.sinh, 1), "cosh": (sp.cosh, 1), "tanh": (sp.tanh, 1),
    "exp": (sp.exp, 1), "log": (sp.log, 1), "sqrt": (sp.sqrt, 1), "Abs": (sp.Abs, 1), "abs": (sp.Abs, 1),
}
CONSTANTS = {"pi": sp.pi, "E": sp.E}
RESERVED_NAMES = frozenset(FUNCTIONS) | frozenset(CONSTANTS)

MAX_LENGTH = 10_000
"""Characters of one formula."""
MAX_TOKENS = 1_000
"""Numbers, names, operators and brackets of one formula: a 90-term Fourier series or a
degree-160 polynomial, the largest of which build into a reference in about a second. It
also keeps Python's parser, which nests one level per term of a sum, far from its
recursion limit."""
MAX_NESTING = 32
"""Brackets, calls, powers and signs inside one another (a realistic formula needs < 10);
sympy's differentiation and printing recurse about ten frames per level."""
MAX_NAME_LENGTH = 64
"""Characters of a declared name (a state, input or parameter)."""
MAX_EXPONENT = 1_000
"""Largest |exponent| of a power whose exponent is a number; a fractional exponent whose
denominator is larger (a root of higher degree) is used as a float."""
MAX_COMPLEX_EXPONENT = 16
"""Largest |exponent| of a power whose base sympy cannot prove real (acos(t), log(t),
sqrt(t - 1)): deciding the sign of a function of it, sympy expands the power into real
and imaginary parts, in loops of big-integer arithmetic (1.5 s at 16, 8 s at 64, minutes
at 1,000) that no step count sees."""
MAX_SYMBOLIC_STEPS = 10_000_000
"""Python function calls that sympy may make for one formula (``symbolic_budget``): about
three times what the largest accepted formulas need (3.5 million, 1.3 s here)."""
MAX_POWER_BITS = 4_096
"""Largest exact number a power may build (bits): a power of numbers is computed exactly,
and so is the numeric factor of a power of a product ((2*t)**n is 2**n * t**n)."""

_FLOAT_MAX = int(sys.float_info.max)
_DECIMAL = re.compile(r"(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_NON_ASCII = re.compile(r"[^\x00-\x7f]")
_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]")
_MAX_NUMBER_LENGTH = 400  # characters of one number literal (a float has at most ~330)
_OPERATORS = frozenset({"(", ")", ",", "+", "-", "*", "/", "**"})
_UNARY_CONTEXT = frozenset({None, "(", ",", "+", "-", "*", "/", "**"})  # a sign may follow these
_ALLOWED = "use numbers, names, + - * / ^ and functions"
_NON_FINITE = (sp.zoo, sp.nan, sp.oo, -sp.oo)
_ADD, _MUL = (ast.Add, ast.Sub), (ast.Mult, ast.Div)
_SHOWN = 60  # characters of a formula quoted in a message
_BUDGET = threading.local()  # .active: a symbolic budget runs in this thread; .counter: its tracer


@contextmanager
def formula_of(label: str | None):
    """Tag an ``ExpressionError`` raised inside with the formula it is about (``label``),
    unless an inner one already did: a file reader then points to that formula's field."""
    try:
        yield
    except ExpressionError as exc:
        if label and exc.formula is None:
            exc.formula = label
        raise


def parse_expression(text: str, names: Mapping[str, sp.Expr], label: str | None = None) -> sp.Expr:
    """The sympy expression written in ``text``; ``names`` maps the allowed names to
    symbols or values. ``label`` (for example ``"x"``) names the formula in messages.

    >>> t = sp.Symbol("t")
    >>> parse_expression("6*sin(t/15 + 0.3) + 0.2*t", {"t": t})
    t/5 + 6*sin(t/15 + 3/10)
    """
    with formula_of(label):
        return _parsed(text, names, label)


def _parsed(text: str, names: Mapping[str, sp.Expr], label: str | None) -> sp.Expr:
    if not isinstance(text, str):
        raise ExpressionError(f"expected a formula (a string), got {describe_value(text)}"
                              + (f" for {label}" if label else ""))
    where = f"{label} = {quote(text)}" if label else quote(text)
    if not text.strip():
        raise ExpressionError(f"empty formula{' for ' + label if label else ''}")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"formula longer than {MAX_LENGTH:,} characters ({len(text):,}) in {where}")
    # "^" is power in the thesis' MATLAB notation. Rewriting it before parsing gives it the
    # precedence of "**"; Python's "^" (xor) would bind looser than + and unary minus.
    source = text.strip().replace("^", "**")
    problem = _scan(source)
    if problem:
        raise ExpressionError(f"{problem} in {where}")
    try:
        tree = ast.parse(source, mode="eval")
    except SyntaxError as error:
        raise ExpressionError(f"cannot parse {where}: {error.msg}") from None
    except (RecursionError, MemoryError):  # not reached within the limits above; kept as a backstop
        raise ExpressionError(f"formula too complex to parse in {where}") from None
    if _nesting(tree.body) > MAX_NESTING:
        raise ExpressionError(f"formula nested more than {MAX_NESTING} levels deep in {where}")
    with symbolic_budget(where), sympy_failures(where):
        expression = _Builder(names, source, where).build(tree.body)
        check_constants(expression, where)
    return expression


class _OverBudget(BaseException):
    """Raised inside sympy by the step counter of ``symbolic_budget``: a BaseException, so
    that sympy's own ``except Exception`` clauses cannot swallow it."""


class symbolic_budget:  # noqa: N801 - used as ``with symbolic_budget(where):``, a context manager's name
    """Bound the symbolic work done in this block to ``MAX_SYMBOLIC_STEPS`` Python function
    calls, else one ``ExpressionError`` line naming ``where``. Blocks nested in a bounded
    one share its budget.

    The size limits above keep honest formulas well inside it; this is the backstop for
    what they cannot foresee: sympy's assumption system expands, for example, the real and
    imaginary parts of ``(acos(t) + asin(t) + log(t))**12`` to decide the sign of a cosh of
    it (5 s), and more for larger exponents. Counting calls with a trace function is
    portable (no signal, no thread, no process) and deterministic: a formula is accepted or
    refused alike on every machine and under any load. It slows the bounded work about
    2.5 times; any other tracer (a debugger, coverage) keeps being called.

    Python drops a trace function that raises. When the step that crosses the budget runs
    in a finalizer (a generator closed by the garbage collector, whose exceptions Python
    only reports as unraisable), the counter is put back from ``sys.unraisablehook``, so
    the next call raises where it cannot be swallowed. Should sympy itself swallow the
    exception, the block is refused when it ends all the same. The counter never raises in
    this class's own ``__exit__`` (the block's last traced call), which turns every way the
    budget ran out into the one ``ExpressionError``.
    """

    def __init__(self, where: str):
        self.where, self.nested = where, False

    def __enter__(self):
        if getattr(_BUDGET, "active", False):
            self.nested = True
            return self
        self.previous, self.limit = previous, limit = sys.gettrace(), MAX_SYMBOLIC_STEPS
        steps = 0

        def count(frame, event, arg):   # (a closure's variable: this runs at every Python call)
            nonlocal steps
            steps += 1
            if steps > limit and frame.f_code is not _BUDGET_EXIT:
                raise _OverBudget
            return previous(frame, event, arg) if previous is not None else None

        self.exhausted = lambda: steps > limit
        _BUDGET.active, _BUDGET.counter = True, count
        _watch_finalizers(True)
        sys.settrace(count)
        return self

    def __exit__(self, kind, error, traceback):
        if self.nested:
            return False
        sys.settrace(self.previous)   # first: nothing below is counted
        _BUDGET.active, _BUDGET.counter = False, None
        _watch_finalizers(False)
        if kind is _OverBudget or (self.exhausted() and (kind is None or issubclass(kind, Exception))):
            raise ExpressionError(f"{self.where}: symbolic work beyond its budget of {self.limit:,} steps "
                                  "(write a simpler formula)") from None
        return False


_BUDGET_EXIT = symbolic_budget.__exit__.__code__
_HOOK = threading.Lock()
_HOOK_USERS = 0  # budgets running in any thread
_HOOK_PREVIOUS = None  # sys.unraisablehook before the first of them


def _watch_finalizers(start: bool) -> None:
    """Install ``_unraisable`` while any budget runs (``start``), else restore the hook it
    replaced (unless someone replaced it meanwhile)."""
    global _HOOK_USERS, _HOOK_PREVIOUS
    with _HOOK:
        if start:
            if _HOOK_USERS == 0:
                current = sys.unraisablehook
                # (never our own hook as the one to restore: it may have been put back by
                # someone who saved it while a budget ran)
                _HOOK_PREVIOUS = None if current is _unraisable else current
                sys.unraisablehook = _unraisable
            _HOOK_USERS += 1
        else:
            _HOOK_USERS -= 1
            if _HOOK_USERS == 0:
                if sys.unraisablehook is _unraisable:
                    sys.unraisablehook = _HOOK_PREVIOUS or sys.__unraisablehook__
                _HOOK_PREVIOUS = None


def _unraisable(info) -> None:
    """``sys.unraisablehook`` while a budget runs: the budget's ``_OverBudget`` raised in a
    finalizer puts its counter back (Python dropped it); anything else goes to the hook
    that was there before."""
    counter = getattr(_BUDGET, "counter", None)
    if counter is not None and isinstance(info.exc_value, _OverBudget):
        sys.settrace(counter)
        return
    (_HOOK_PREVIOUS or sys.__unraisablehook__)(info)


@contextmanager
def sympy_failures(where: str):
    """Any failure of sympy itself while working on a formula (one of its bugs, an
    overflow, a recursion) as one ``ExpressionError`` line naming ``where``."""
    try:
        yield
    except NonholoInputError:
        raise
    except (ArithmeticError, AttributeError, LookupError, TypeError, ValueError, RecursionError,
            MemoryError) as error:
        raise ExpressionError(f"sympy cannot handle {where} ({type(error).__name__}: {quote(str(error))})") from None


def quote(text: str) -> str:
    """``text`` quoted for a message, at most about 60 characters of it."""
    return describe_value(text, _SHOWN, typed=False)


def check_name(name) -> str | None:
    """Why ``name`` cannot be declared for use in formulas (None if it can): it must be an
    identifier of at most ``MAX_NAME_LENGTH`` characters, not a Python keyword, written as
    Python reads it, and not a function or constant name."""
    if not isinstance(name, str):
        return f"expected a name, got {describe_value(name)}"
    if not name.isidentifier() or keyword.iskeyword(name):
        return f"{quote(name)} is not a name (letters, digits and _, not starting with a digit)"
    if len(name) > MAX_NAME_LENGTH:
        return f"{quote(name)} is longer than {MAX_NAME_LENGTH} characters"
    normal = unicodedata.normalize("NFKC", name)
    if normal != name:
        return f"{quote(name)} would be read as {quote(normal)}: write it so"
    if name in RESERVED_NAMES:
        return f"{name!r} is reserved (a function or constant name)"
    return None


def exact_number(value) -> sp.Rational:
    """A finite real number as an exact sympy number: the decimal written is kept
    (0.1 becomes 1/10, not the nearest binary fraction). ``ExpressionError`` otherwise,
    whose message callers prefix with the name of the value."""
    if (isinstance(value, bool) or not isinstance(value, (int, float))
            or isinstance(value, float) and not math.isfinite(value) or abs(value) > _FLOAT_MAX):
        raise ExpressionError(f"expected a finite number, got {describe_value(value)}")
    return sp.Rational(repr(value)) if isinstance(value, float) else sp.Integer(value)


def check_constants(expression: sp.Expr, where: str) -> None:
    """``ExpressionError`` if ``expression`` has an infinite or undefined value, or a
    number beyond the floating-point range (it would evaluate to inf)."""
    if expression.has(*_NON_FINITE):
        raise ExpressionError(f"{where} is not finite (a division by zero or an undefined value)")
    if expression.has(sp.I):
        raise ExpressionError(f"{where} is not real (it involves sqrt(-1))")
    for number in expression.atoms(sp.Number):
        if _too_large(number):
            raise ExpressionError(f"{where} has a constant beyond the floating-point range "
                                  f"(about 1e{_log10(number):.0f})")


def expression_size(expression: sp.Expr, limit: int | None = None) -> int:
    """Nodes of ``expression``'s tree, counted without recursion; counting stops past
    ``limit``."""
    count, stack = 0, [expression]
    while stack:
        node = stack.pop()
        count += 1
        if limit is not None and count > limit:
            break
        stack.extend(node.args)
    return count


def _scan(source: str) -> str | None:
    """The first limit ``source`` breaks, found from its tokens before it is parsed."""
    if not source.isascii():
        for character in dict.fromkeys(_NON_ASCII.findall(source)):  # in order of appearance
            if unicodedata.category(character)[0] == "C":
                return f"invisible or control character U+{ord(character):04X}"
            normal = unicodedata.normalize("NFKC", character)
            if normal != character:
                return f"character {character!r} (U+{ord(character):04X}) would be read as {normal!r}: write that"
    control = _CONTROL.search(source)
    if control:
        return f"control character U+{ord(control.group()):04X}"
    count, previous, name = 0, None, None
    runs = [0]  # per open bracket: powers and signs since the last + - * / or comma
    try:
        for token in tokenize.generate_tokens(io.StringIO(source).readline):
            kind, string = token.type, token.string
            if kind in (tokenize.NEWLINE, tokenize.NL, tokenize.ENDMARKER, tokenize.INDENT, tokenize.DEDENT):
                continue
            count += 1
            if count > MAX_TOKENS:
                return f"formula of more than {MAX_TOKENS:,} tokens (numbers, names, operators, brackets)"
            if kind == tokenize.NUMBER:
                if len(string) > _MAX_NUMBER_LENGTH:
                    return f"number of more than {_MAX_NUMBER_LENGTH} characters"
                if not _DECIMAL.fullmatch(string):
                    return f"{quote(string)} is not a decimal number"
            elif kind == tokenize.NAME:
                name = string
                if keyword.iskeyword(string):
                    return f"{string!r} is not allowed ({_ALLOWED})"
            elif kind == tokenize.OP and string in _OPERATORS:
                if string == "(":
                    if previous == tokenize.NAME and name not in FUNCTIONS:
                        return _unknown_function(name)
                    runs.append(0)
                elif string == ")":
                    if len(runs) > 1:  # an unmatched ")" is left to the parser
                        runs.pop()
                elif string == "**" or (string in "+-" and previous in _UNARY_CONTEXT):
                    runs[-1] += 1
                else:
                    runs[-1] = 0
                if len(runs) - 1 + sum(runs) > MAX_NESTING:
                    return f"formula nested more than {MAX_NESTING} levels deep"
            else:
                shown = string if kind != tokenize.ERRORTOKEN else string.strip() or repr(string)
                return f"{quote(shown)} is not allowed ({_ALLOWED})"
            previous = string if kind == tokenize.OP else kind
    except (tokenize.TokenError, SyntaxError) as error:  # unbalanced brackets and the like
        message = error.args[0] if error.args else "syntax error"
        return f"cannot parse: {message}"
    return None


def _unknown_function(name: str) -> str:
    return f"unknown function {quote(name)} (allowed: {', '.join(sorted(FUNCTIONS))})"


def _nesting(root: ast.AST) -> int:
    """Operations of ``root`` inside one another (a name or number is 0, ``-t`` is 1), a
    chain of + - or of * / counting once; found without recursion, and no further than
    ``MAX_NESTING + 1``."""
    deepest, stack = 0, [(root, 0)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, (ast.Name, ast.Constant)):
            continue
        depth += 1
        deepest = max(deepest, depth)
        if deepest > MAX_NESTING:
            break
        for child in ast.iter_child_nodes(node):
            same_chain = (isinstance(node, ast.BinOp) and child is node.left and isinstance(child, ast.BinOp)
                          and _chain(node) is not None and _chain(child) == _chain(node))
            if not isinstance(child, (ast.operator, ast.unaryop, ast.expr_context)):
                stack.append((child, depth - 1 if same_chain else depth))
    return deepest


def _chain(node: ast.BinOp):
    return _ADD if isinstance(node.op, _ADD) else _MUL if isinstance(node.op, _MUL) else None


def _too_large(number: sp.Number) -> bool:
    if number.is_Rational:
        return abs(number.p) > _FLOAT_MAX * number.q
    return not math.isfinite(float(number))


def _log10(number: sp.Number) -> float:
    if number.is_Rational:
        return (abs(number.p).bit_length() - number.q.bit_length()) * math.log10(2)
    return math.inf


def _bits(number: sp.Rational) -> int:
    return max(abs(number.p).bit_length(), number.q.bit_length())


class _Builder:
    """Rebuilds a parsed formula as sympy, node by node from the whitelist."""

    def __init__(self, names: Mapping[str, sp.Expr], source: str, where: str):
        self.names = names
        self.source = source
        self.where = where

    def fail(self, node: ast.AST, problem: str):
        raise ExpressionError(f"{quote(self.snippet(node))}: {problem} in {self.where}")

    def snippet(self, node: ast.AST) -> str:
        return ast.get_source_segment(self.source, node) or type(node).__name__

    def build(self, node: ast.AST) -> sp.Expr:
        if isinstance(node, ast.Constant):
            return self.constant(node)
        if isinstance(node, ast.Name):
            return self.name(node)
        if isinstance(node, ast.BinOp) and _chain(node) is not None:
            return self.chain(node)
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            return self.power(node)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            operand = self.build(node.operand)
            return -operand if isinstance(node.op, ast.USub) else operand
        if isinstance(node, ast.Call):
            return self.call(node)
        raise ExpressionError(f"{quote(self.snippet(node))} is not allowed ({_ALLOWED}) in {self.where}")

    def constant(self, node: ast.Constant) -> sp.Expr:
        try:  # exact: 0.5 is 1/2, not a binary float
            return exact_number(node.value)
        except ExpressionError:
            self.fail(node, "beyond the floating-point range")

    def name(self, node: ast.Name) -> sp.Expr:
        if node.id in self.names:
            value = self.names[node.id]
            if isinstance(value, sp.Basic):
                return value
            try:
                return exact_number(value)
            except ExpressionError as exc:
                raise ExpressionError(f"{node.id}: {exc}") from None
        if node.id in CONSTANTS:
            return CONSTANTS[node.id]
        known = ", ".join(sorted(self.names)) or "none"
        if node.id in FUNCTIONS:
            raise ExpressionError(f"{node.id!r} is a function: call it, as in {node.id}(t), in {self.where}")
        raise ExpressionError(f"unknown symbol {quote(node.id)} in {self.where} (known: {known}, pi, E)")

    def chain(self, node: ast.BinOp) -> sp.Expr:
        """a + b - c … (or a * b / c …) as one sympy Add (Mul), built without recursing
        along the chain: a sum of a thousand terms is one level, and linear to build."""
        kind, links, left = _chain(node), [], node
        while isinstance(left, ast.BinOp) and _chain(left) == kind:
            links.append(left)
            left = left.left
        operands = [self.build(left)]
        for link in reversed(links):
            value = self.build(link.right)
            if isinstance(link.op, ast.Sub):
                value = -value
            elif isinstance(link.op, ast.Div):
                if value.is_zero:
                    self.fail(link, "division by zero")
                value = sp.Pow(value, -1)
            operands.append(value)
        return self.checked(sp.Add(*operands) if kind == _ADD else sp.Mul(*operands), node)

    def power(self, node: ast.BinOp) -> sp.Expr:
        base, exponent = self.build(node.left), self.build(node.right)
        if exponent.is_Rational and exponent.q > MAX_EXPONENT:
            # a root of high degree: sympy would look for it exactly (2**(1/10**300) takes hours)
            exponent = sp.Float(exponent, 17)
        if exponent.is_Number:
            if abs(exponent) > MAX_EXPONENT:
                self.fail(node, f"exponent {_short_number(exponent)} is too large (at most {MAX_EXPONENT:,} in size)")
            if abs(exponent) > MAX_COMPLEX_EXPONENT and base.is_extended_real is not True:
                self.fail(node, f"exponent {_short_number(exponent)} is too large for a base that may be complex "
                                f"(at most {MAX_COMPLEX_EXPONENT})")
            numbers = [base] if base.is_Rational else base.atoms(sp.Rational)
            bits = max((_bits(n) for n in numbers), default=0) * abs(exponent)
            if bits > MAX_POWER_BITS:
                self.fail(node, f"power too large: it may build a number of about {int(bits * 0.30103):,} digits "
                                f"(at most {int(MAX_POWER_BITS * 0.30103):,})")
        if base.is_zero and exponent.is_negative:
            self.fail(node, "division by zero")
        if base.is_number and base.is_negative and not exponent.is_number and not exponent.is_integer:
            self.fail(node, "not real: a negative number to a power that need not be an integer")
        return self.checked(sp.Pow(base, exponent), node)

    def call(self, node: ast.Call) -> sp.Expr:
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            called = node.func.id if isinstance(node.func, ast.Name) else self.snippet(node.func)
            raise ExpressionError(f"{_unknown_function(called)} in {self.where}")
        function, arity = FUNCTIONS[node.func.id]
        if node.keywords or len(node.args) != arity or any(isinstance(a, ast.Starred) for a in node.args):
            raise ExpressionError(f"{node.func.id} takes {arity} argument(s) in {self.where}")
        return self.checked(function(*(self.build(argument) for argument in node.args)), node)

    def checked(self, value: sp.Expr, node: ast.AST) -> sp.Expr:
        """``value``, unless sympy made it infinite or undefined (1/0, log(0), tan(pi/2)),
        or it is a constant beyond the floating-point range or not real. Constants are
        checked as they are built, so sympy never evaluates a function of a huge number
        (``tan(cosh(1e20))`` would need pi to 10^20 digits)."""
        if value in _NON_FINITE:
            self.fail(node, "not finite (a division by zero or an undefined value)")
        if value.is_Number:
            if _too_large(value):
                self.fail(node, f"beyond the floating-point range (about 1e{_log10(value):.0f})")
        elif value.is_number:  # a constant such as cosh(20): its arguments are checked already
            number = complex(value.evalf(20))
            if not (math.isfinite(number.real) and math.isfinite(number.imag)):
                self.fail(node, "beyond the floating-point range")
            if abs(number.imag) > 1e-12 * max(1.0, abs(number.real)):
                self.fail(node, "not a real number")
        return value


def _short_number(number: sp.Number) -> str:
    if number.is_Integer:
        return str(number) if abs(number.p).bit_length() < 100 else f"about 1e{_log10(number):.0f}"
    return f"{float(number):g}"
