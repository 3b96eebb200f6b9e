"""Encoder for the ACL string representation, following JADE's layout (one parameter per
line, lower-case keywords, receivers as ``(set (agent-identifier ...))``).

Quoting rule (spec comm.md §1.3, encoder rules 2–3): a ``str`` goes out bare only if it is
a printable-ASCII Word that reads back as the same word (``acl_lexical.is_portable_word``);
a value with a backslash or a control character goes out as a byte-length string
``#N"...`` (N counted in UTF-8 bytes): the standard has no escape for a backslash, so
``"C:\\"`` would not end, and ``\\"`` inside a literal reads differently in different readers
(one that takes ``\\\\`` for an escaped backslash sees the quote after it end the string, and
what follows as parameters of their own, under the same MAC); every other value as a string
literal with ``\\"`` for quotes. Content is never trimmed.
"""
from __future__ import annotations

import math
import re
from datetime import datetime

from nonholo.comm import acl_lexical as lex
from nonholo.comm.errors import ACLEncodeError
from nonholo.comm.message import PARAMETER_ATTRIBUTES, ACLMessage, AgentID, Expression, RelativeTime


def encode(message: ACLMessage, *, max_depth: int = lex.DEFAULT_MAX_DEPTH,
           max_size: int = lex.DEFAULT_MAX_SIZE) -> bytes:
    """The UTF-8 bytes of ``message``; raises ACLEncodeError if it cannot be represented
    or would exceed the limits a strict decoder enforces (ValueError for limits outside
    their ceilings)."""
    lex.check_limits(max_depth, max_size)
    try:
        data = _message_text(message, max_depth).encode("utf-8")
        if len(data) > max_size:   # one line (newlines are optional): a message read at the limit goes out again
            data = _message_text(message, max_depth, " :").encode("utf-8")
    except UnicodeEncodeError as exc:
        raise ACLEncodeError(f"text is not encodable as UTF-8: {exc.reason}") from None
    if len(data) > max_size:
        raise ACLEncodeError(f"encoded message is {len(data)} bytes, over the {max_size}-byte limit")
    return data


def encode_text(message: ACLMessage, **limits: int) -> str:
    return encode(message, **limits).decode("utf-8")


def _message_text(message: ACLMessage, max_depth: int, lead: str = "\n :") -> str:
    parts = ["(", message.performative]
    for acl_name, attribute in PARAMETER_ATTRIBUTES.items():
        value = getattr(message, attribute)
        if value is not None:
            parts.append(f"{lead}{acl_name} ")
            parts.append(_PARAMETER_WRITERS[acl_name](value, max_depth))
    for name, value in _user_params(message.user_params):
        parts.append(f"{lead}X-{name} ")
        parts.append(_expression(value, 1, max_depth))
    parts.append(")")
    return "".join(parts)


def _user_params(params) -> list[tuple[str, Expression]]:
    seen: set[str] = set()
    for name in params:
        if not isinstance(name, str) or not name or not lex.WORD.fullmatch("x" + name):
            raise ACLEncodeError(f"user parameter name {name!r} is not a valid word")
        if name.lower() in seen:
            raise ACLEncodeError(f"user parameter X-{name} appears twice (names ignore case)")
        seen.add(name.lower())
    return list(params.items())


_CONTROL = re.compile("[\x00-\x1f\x7f]")


def string_literal(text: str) -> str:
    if not isinstance(text, str):
        raise ACLEncodeError(f"expected a string, got {type(text).__name__}")
    if "\\" not in text and not _CONTROL.search(text):
        return '"' + text.replace('"', '\\"') + '"'
    return f'#{len(text.encode("utf-8"))}"{text}'


def word_or_string(text: str) -> str:
    if isinstance(text, str) and text and lex.is_portable_word(text):
        return text
    return string_literal(text)


def _expression(value: Expression, depth: int, max_depth: int) -> str:
    if isinstance(value, str):
        return word_or_string(value)
    if isinstance(value, bool):
        raise ACLEncodeError("booleans have no ACL form; use the words true/false")
    if isinstance(value, int):
        try:
            return str(value)
        except ValueError:  # beyond Python's int-to-string digit limit
            raise ACLEncodeError(f"integer of {value.bit_length()} bits is too long to "
                                 "write (the decoder's limit)") from None
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ACLEncodeError(f"{value} has no ACL number form")
        return repr(value)
    if isinstance(value, (datetime, RelativeTime)):
        return _datetime(value)
    if isinstance(value, (tuple, list)):
        if depth + 1 > max_depth:
            raise ACLEncodeError(f"expression nested deeper than the limit of {max_depth}")
        return "(" + " ".join(_expression(item, depth + 1, max_depth) for item in value) + ")"
    raise ACLEncodeError(f"{type(value).__name__} is not an ACL expression")


def _datetime(value: datetime | RelativeTime) -> str:
    try:
        return lex.format_datetime(value)
    except (OverflowError, ValueError) as exc:
        raise ACLEncodeError(f"date-time {value!r} cannot be written: {exc}") from None


def _agent_id(aid: AgentID, depth: int, max_depth: int) -> str:
    if not isinstance(aid, AgentID):
        raise ACLEncodeError(f"expected an AgentID, got {type(aid).__name__}")
    if depth + 1 > max_depth:
        raise ACLEncodeError(f"agent identifier nested deeper than the limit of {max_depth}")
    if (aid.addresses or aid.resolvers) and depth + 2 > max_depth:
        raise ACLEncodeError(f"agent identifier sequences nested deeper than the limit of {max_depth}")
    parts = ["(agent-identifier :name ", word_or_string(aid.name)]
    if aid.addresses:
        parts.append(" :addresses (sequence ")
        parts.append(" ".join(word_or_string(url) for url in aid.addresses))
        parts.append(")")
    if aid.resolvers:
        parts.append(" :resolvers (sequence ")
        parts.append(" ".join(_agent_id(r, depth + 2, max_depth) for r in aid.resolvers))
        parts.append(")")
    for name, value in _user_params(aid.user_params):
        parts.append(f" :X-{name} ")
        parts.append(_expression(value, depth + 1, max_depth))
    parts.append(")")
    return "".join(parts)


def _agent_set(aids: tuple[AgentID, ...], max_depth: int) -> str:
    return "(set" + "".join(" " + _agent_id(aid, 2, max_depth) for aid in aids) + ")"


def _protocol(value: str, max_depth: int) -> str:
    if not isinstance(value, str) or not value or not lex.is_word(value):
        raise ACLEncodeError(f":protocol must be a word, got {value!r}")
    return value


def _reply_by(value, max_depth: int) -> str:
    if not isinstance(value, (datetime, RelativeTime)):
        raise ACLEncodeError(f":reply-by must be a datetime or RelativeTime, got {value!r}")
    return _datetime(value)


_PARAMETER_WRITERS = {
    "sender": lambda aid, max_depth: _agent_id(aid, 1, max_depth),
    "receiver": _agent_set,
    "reply-to": _agent_set,
    "content": lambda text, max_depth: string_literal(text),
    "reply-with": lambda value, max_depth: _expression(value, 1, max_depth),
    "reply-by": _reply_by,
    "in-reply-to": lambda value, max_depth: _expression(value, 1, max_depth),
    "encoding": lambda value, max_depth: _expression(value, 1, max_depth),
    "language": lambda value, max_depth: _expression(value, 1, max_depth),
    "ontology": lambda value, max_depth: _expression(value, 1, max_depth),
    "protocol": _protocol,
    "conversation-id": lambda value, max_depth: _expression(value, 1, max_depth),
}
