"""TOML input (scenario files, analysis system files) read within limits, and values
shown briefly in error messages.

``tomllib`` trusts its input: it reads a whole file into memory, recurses once per
nested array or inline table (1,000 levels end in ``RecursionError``), spends time and
memory quadratic in the number of parts of one dotted key (``a.a.a…`` with 300,000
parts exhausts the memory of the machine), and lets a ``ValueError`` through for an
integer of more than 4,300 digits. Here the limits are applied before ``tomllib`` sees the
text:

* at most ``MAX_BYTES`` bytes, enforced while reading (at most ``MAX_BYTES + 1`` bytes are
  ever read, so ``/dev/zero`` or a multi-gigabyte file costs nothing);
* UTF-8 only, a leading byte-order mark accepted and dropped;
* at most ``MAX_NESTING`` arrays and inline tables inside one another and at most
  ``MAX_NESTING`` parts in one dotted key, found by a linear scan that skips strings and
  comments (it never recurses); the parsed data is checked for the same depth.

Every problem is an ``InputFileError`` (a ``NonholoInputError``) whose one-line message
names the source; ``describe_value`` keeps any value quoted in a message short.
"""
from __future__ import annotations

import re
import reprlib
import tomllib
from pathlib import Path

from nonholo.errors import InputFileError

MAX_BYTES = 1_000_000
"""Largest file (bytes) or text (characters) read: about 30,000 waypoints. tomllib parses
1 MB in 0.2-0.7 s."""
MAX_NESTING = 32
"""Arrays/inline tables inside one another, parts of one dotted key, and depth of the
parsed data (a scenario needs 4)."""
DESCRIBE_LIMIT = 100
"""Characters of a value shown in an error message."""

_BOM = "\ufeff"
# Strings and comments, removed (keeping their line breaks) before brackets and dots are
# counted, so that a "[" or "." inside a string never counts.
_STRINGS_AND_COMMENTS = re.compile(r'''
      """(?:[^"\\]++|\\[\s\S]|"{1,2}(?!"))*+"""(?:"{1,2}(?!"))?
    | \'\'\'[\s\S]*?\'\'\'(?:'{1,2}(?!'))?
    | "(?:[^"\\\n]++|\\[^\n])*+"
    | '[^'\n]*+'
    | \#[^\n]*+
''', re.VERBOSE)  # possessive (*+): a long unterminated string costs no backtracking memory
_BRACKETS = re.compile(r"[\[\]{}]")


def read_toml(path, *, max_bytes: int = MAX_BYTES) -> dict:
    """The TOML file at ``path`` as a dict; ``InputFileError`` naming the file otherwise.

    At most ``max_bytes + 1`` bytes are read.
    """
    source = str(path)
    try:
        with Path(path).open("rb") as file:
            data = file.read(max_bytes + 1)
    except OSError as exc:
        raise InputFileError(source, f"cannot read: {exc.strerror or exc}") from None
    if len(data) > max_bytes:
        raise InputFileError(source, f"larger than {max_bytes:,} bytes: not read")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputFileError(source, f"not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start})") from None
    return parse_toml(text, source, max_bytes=max_bytes)


def parse_toml(text: str, source: str = "<toml>", *, max_bytes: int = MAX_BYTES) -> dict:
    """TOML ``text`` as a dict, within the limits; ``InputFileError`` naming ``source``
    otherwise. ``max_bytes`` bounds the number of characters."""
    if not isinstance(text, str):
        raise InputFileError(source, f"expected TOML text, got {describe_value(text)}")
    if len(text) > max_bytes:
        raise InputFileError(source, f"longer than {max_bytes:,} characters: not read")
    if text.startswith(_BOM):
        text = text[1:]
    problem = _nesting_problem(text)
    if problem:
        raise InputFileError(source, problem)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputFileError(source, f"not valid TOML: {exc}") from None
    except ValueError:  # an integer beyond Python's 4,300-digit conversion limit
        raise InputFileError(source, "not valid TOML: a number with too many digits") from None
    except RecursionError:  # not reached when the scan above is right; kept as a backstop
        raise InputFileError(source, f"nested more than {MAX_NESTING} levels deep") from None
    depth = _data_depth(data, MAX_NESTING + 1)
    if depth > MAX_NESTING:
        raise InputFileError(source, f"tables nested more than {MAX_NESTING} levels deep")
    return data


def _nesting_problem(text: str, limit: int = MAX_NESTING) -> str | None:
    """Why ``text`` is nested too deeply for ``tomllib`` (None if it is not): more than
    ``limit`` arrays or inline tables inside one another, or a dotted key of more than
    ``limit`` parts. Regular expressions and one pass over the brackets; no recursion."""
    bare = _STRINGS_AND_COMMENTS.sub(lambda match: "\n" * match.group().count("\n"), text)
    unterminated = min((i for i in (bare.find('"'), bare.find("'")) if i >= 0), default=len(bare))
    bare = bare[:unterminated]  # tomllib reports an unterminated string itself
    # limit dots with no newline, "=", "," or bracket between them: a key of limit + 1 parts
    dotted = re.search(r"\.(?:[^\n=,\[\]{}.]*\.){%d}" % (limit - 1), bare)
    if dotted:
        line = bare.count("\n", 0, dotted.start()) + 1
        return f"line {line}: a dotted key of more than {limit} parts"
    depth = 0
    for match in _BRACKETS.finditer(bare):
        depth += 1 if match.group() in "[{" else -1
        if depth > limit:
            line = bare.count("\n", 0, match.start()) + 1
            return f"line {line}: arrays or tables nested more than {limit} levels deep"
    return None


def _data_depth(value, limit: int) -> int:
    """Nesting depth of dicts and lists in ``value`` (a scalar is 0), counted without
    recursion and no further than ``limit``."""
    deepest = 0
    stack = [(value, 0)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            children = item.values()
        elif isinstance(item, list):
            children = item
        else:
            continue
        depth += 1
        deepest = max(deepest, depth)
        if deepest >= limit:
            return deepest
        stack.extend((child, depth) for child in children if isinstance(child, (dict, list)))
    return deepest


class _ShortRepr(reprlib.Repr):
    """reprlib showing a few items, and large integers by their size (``repr`` of an
    integer of more than 4,300 digits raises ``ValueError``)."""

    def __init__(self):
        super().__init__()
        self.maxlevel, self.maxlist, self.maxtuple, self.maxdict, self.maxset = 3, 6, 6, 4, 4
        self.maxstring, self.maxother = 60, 40

    def repr_int(self, x, level):
        if x.bit_length() > 200:
            return f"<an integer of about {int(x.bit_length() * 0.30103) + 1} digits>"
        return repr(x)


_SHORT = _ShortRepr()


def describe_value(value, limit: int = DESCRIBE_LIMIT, *, typed: bool = True) -> str:
    """``value`` for an error message: its type (unless ``typed`` is false) and at most
    about ``limit`` characters of it, whatever its size; the size of a long string or
    list is given in words.

    >>> describe_value("fast")
    "str 'fast'"
    >>> describe_value([0] * 1_000_000)
    'list of 1,000,000 items [0, 0, 0, 0, 0, 0, ...]'
    """
    shown = _SHORT.repr(value)
    if len(shown) > limit:
        shown = shown[:max(limit - 3, 1)] + "..."
    shown_items = _SHORT.maxdict if isinstance(value, dict) else _SHORT.maxlist
    if isinstance(value, str) and len(value) > _SHORT.maxstring:
        size = f"{len(value):,} characters"
    elif isinstance(value, (list, tuple, dict, set)) and len(value) > shown_items:
        size = f"{len(value):,} items"
    else:
        size = None
    if not typed:
        return f"{shown} ({size})" if size else shown
    kind = type(value).__name__
    return f"{kind} of {size} {shown}" if size else f"{kind} {shown}"
