"""Lexical rules of the ACL string representation (SC00070I), shared by decoder and encoder.

Every pattern here is linear-time: character classes with possessive repeats and no
nested alternation that could backtrack, so hostile input cannot make them slow.
"""
from __future__ import annotations

import re
from datetime import datetime, timedelta, timezone

from nonholo.comm.message import RelativeTime

DEFAULT_MAX_DEPTH = 32
DEFAULT_MAX_SIZE = 64 * 1024
# Recursion in the parser is bounded by the depth limit; this ceiling keeps a caller
# from configuring a limit that could reach Python's recursion limit.
HARD_MAX_DEPTH = 200
# Ceiling for a configured size limit: far above any message a robot sends, low enough
# that reading up to the limit cannot exhaust memory.
HARD_MAX_SIZE = 16 * 1024 * 1024


def check_limits(max_depth: int, max_size: int) -> None:
    """ValueError unless both limits are integers within their ceilings."""
    if isinstance(max_depth, bool) or not isinstance(max_depth, int) \
            or not 1 <= max_depth <= HARD_MAX_DEPTH:
        raise ValueError(f"max_depth must be an integer in 1..{HARD_MAX_DEPTH}")
    if isinstance(max_size, bool) or not isinstance(max_size, int) \
            or not 1 <= max_size <= HARD_MAX_SIZE:
        raise ValueError(f"max_size must be an integer in 1..{HARD_MAX_SIZE}")

# One token after optional whitespace. Group numbers identify the token kind:
# 1 "(", 2 ")", 3 string-literal body, 4 byte-length header digits, 5 atom (word/number/
# date-time/parameter name). A string body is any run of non-quote bytes where a
# backslash is literal unless it precedes a quote: \" is the only escape.
# An atom that starts like a Word (SC00070I: not a control, space, "(", ")", "#", digit,
# "-" or "@") runs to the next space or parenthesis, '"' included; any other atom (a
# number, a date-time, or an invalid word the parser names) stops at a '"' as well, as a
# longest-match lexer of the grammar would. A '"' always opens a string literal: the
# grammar's Word would also admit it as a first character, which is ambiguous with
# StringLiteral, so the string reading wins (as in every implementation seen).
TOKEN = re.compile(
    rb'[ \t\r\n\f]*+(?:(\()|(\))|"((?:[^"\\]++|\\"|\\(?!"))*+)"|\#([0-9]{1,9})"'
    rb'|([^\x00-\x20()"#0-9\-@][^\x00-\x20()]*+|[^\x00-\x20()"][^\x00-\x20()"]*+))'
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
# The grammar's Word (SC00070I), with '"' excluded as a first character (see TOKEN).
WORD = re.compile(r'[^\x00-\x20()"#0-9\-@][^\x00-\x20()]*+')
# The Words every reader seen takes: printable ASCII (JADE 4.6.5 reads no other word
# character), no '"' (older readers end a word there) and no leading ":" (older readers
# take it for a parameter name). The encoder writes a value bare only in this form.
PORTABLE_WORD = re.compile(r"[!$-'*+,./;-?A-~][!#-'*-~]*+")
NUMBER_START = frozenset("0123456789+-.")


def looks_like_number_or_datetime(text: str) -> bool:
    return bool(INTEGER.fullmatch(text) or FLOAT.fullmatch(text) or DATETIME.fullmatch(text))


def is_word(text: str) -> bool:
    """True if ``text`` is a Word of the grammar that reads back as the same ``str`` (not a
    number or date-time look-alike)."""
    return WORD.fullmatch(text) is not None and not (
        text[0] in NUMBER_START and looks_like_number_or_datetime(text)
    )


def is_portable_word(text: str) -> bool:
    """True if ``text`` can be written unquoted for every reader (see PORTABLE_WORD; every
    portable word is a Word of the grammar)."""
    return PORTABLE_WORD.fullmatch(text) is not None and not (
        text[0] in NUMBER_START and looks_like_number_or_datetime(text)
    )


# The one-letter time zones (the military/nautical letters of ISO 8601 practice): Z is UTC,
# A..M (no J) are 1..12 hours east, N..Y 1..12 hours west, J is the observer's local time.
_ZONE_HOURS = {**{letter: hours + 1 for hours, letter in enumerate("ABCDEFGHIKLM")},
               **{letter: -(hours + 1) for hours, letter in enumerate("NOPQRSTUVWXY")}, "Z": 0}


def datetime_from_match(match: re.Match[str]) -> datetime | RelativeTime:
    """Build the value of a DATETIME match; raises ValueError for impossible dates. A
    designator letter gives the time zone (Z: UTC; none or J: local, a naive datetime);
    on a relative time (leading sign) it carries no meaning and is ignored."""
    sign, year, month, day, hour, minute, second, millis, designator = match.groups()
    fields = [int(g) for g in (year, month, day, hour, minute, second, millis)]
    if sign:
        return RelativeTime(sign == "-", *fields)
    offset = _ZONE_HOURS.get(designator.upper()) if designator else None
    tz = None if offset is None else (timezone.utc if offset == 0
                                      else timezone(timedelta(hours=offset)))
    value = datetime(*fields[:6], fields[6] * 1000, tzinfo=tz)
    try:  # the encoder writes UTC: refuse what has no UTC form (the first and last hours)
        value.astimezone(timezone.utc)
    except (OverflowError, OSError):
        raise ValueError("the time lies outside the range of UTC dates") from None
    return value


def format_datetime(value: datetime | RelativeTime) -> str:
    """DateTime text; absolute times always in UTC with ``Z`` (naive means local time)."""
    if isinstance(value, RelativeTime):
        sign = "-" if value.negative else "+"
        return (f"{sign}{value.years:04d}{value.months:02d}{value.days:02d}T{value.hours:02d}"
                f"{value.minutes:02d}{value.seconds:02d}{value.milliseconds:03d}")
    utc = value.astimezone(timezone.utc)
    return (f"{utc.year:04d}{utc.month:02d}{utc.day:02d}T{utc.hour:02d}{utc.minute:02d}"
            f"{utc.second:02d}{utc.microsecond // 1000:03d}Z")
