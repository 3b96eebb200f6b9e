"""Lexical rules of the ACL string representation (SC00070I), shared by decoder and encoder.

Every pattern here is linear-time: character classes with possessive repeats and no
nested alternation that could backtrack, so hostile input cannot make them slow.
"""
from __future__ import annotations

import re
from datetime import datetime, timezone

from nonholo.comm.message import RelativeTime

DEFAULT_MAX_DEPTH = 32
DEFAULT_MAX_SIZE = 64 * 1024
# Recursion in the parser is bounded by the depth limit; this ceiling keeps a caller
# from configuring a limit that could reach Python's recursion limit.
HARD_MAX_DEPTH = 200

# One token after optional whitespace. Group numbers identify the token kind:
# 1 "(", 2 ")", 3 string-literal body, 4 byte-length header digits, 5 atom (word/number/
# date-time/parameter name). A string body is any run of non-quote bytes where a
# backslash is literal unless it precedes a quote: \" is the only escape.
TOKEN = re.compile(
    rb'[ \t\r\n\f]*+(?:(\()|(\))|"((?:[^"\\]++|\\"|\\(?!"))*+)"|\#([0-9]{1,9})"|([^\x00-\x20()"]++))'
)
WHITESPACE = re.compile(rb"[ \t\r\n\f]*+")
OPEN, CLOSE, STRING, BYTE_STRING, ATOM = 1, 2, 3, 4, 5

INTEGER = re.compile(r"[+-]?[0-9]++")
FLOAT = re.compile(
    r"[+-]?(?:(?:[0-9]++\.[0-9]*+|\.[0-9]++)(?:[eE][+-]?[0-9]++)?|[0-9]++[eE][+-]?[0-9]++)"
)
DATETIME = re.compile(
    r"([+-]?)([0-9]{4})([0-9]{2})([0-9]{2})[Tt]([0-9]{2})([0-9]{2})([0-9]{2})([0-9]{3})([A-Za-z]?)"
)
# A bare Word as the encoder may emit it: the grammar's Word minus a leading ":" (which
# reads as a parameter name) and minus '"' (JADE ends words there).
WORD = re.compile(r'[^\x00-\x20()"#0-9\-@:][^\x00-\x20()"]*+')
NUMBER_START = frozenset("0123456789+-.")


def looks_like_number_or_datetime(text: str) -> bool:
    return bool(INTEGER.fullmatch(text) or FLOAT.fullmatch(text) or DATETIME.fullmatch(text))


def is_bare_word(text: str) -> bool:
    """True if ``text`` can be written unquoted and reads back as the same ``str``."""
    return WORD.fullmatch(text) is not None and not (
        text[0] in NUMBER_START and looks_like_number_or_datetime(text)
    )


def datetime_from_match(match: re.Match[str]) -> datetime | RelativeTime:
    """Build the value of a DATETIME match; raises ValueError for impossible dates."""
    sign, year, month, day, hour, minute, second, millis, designator = match.groups()
    fields = [int(g) for g in (year, month, day, hour, minute, second, millis)]
    if sign:
        if designator:
            raise ValueError("a relative date-time takes no time zone designator")
        return RelativeTime(sign == "-", *fields)
    if designator and designator not in "Zz":
        raise ValueError(f"time zone designator {designator!r} is not supported; use Z (UTC)")
    tz = timezone.utc if designator else None
    return datetime(*fields[:6], fields[6] * 1000, tzinfo=tz)


def format_datetime(value: datetime | RelativeTime) -> str:
    """DateTime text; absolute times always in UTC with ``Z`` (naive means local time)."""
    if isinstance(value, RelativeTime):
        sign = "-" if value.negative else "+"
        return (f"{sign}{value.years:04d}{value.months:02d}{value.days:02d}T{value.hours:02d}"
                f"{value.minutes:02d}{value.seconds:02d}{value.milliseconds:03d}")
    utc = value.astimezone(timezone.utc)
    return (f"{utc.year:04d}{utc.month:02d}{utc.day:02d}T{utc.hour:02d}{utc.minute:02d}"
            f"{utc.second:02d}{utc.microsecond // 1000:03d}Z")
