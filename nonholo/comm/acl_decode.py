"""Strict decoder for the ACL string representation (SC00070I).

Works on bytes because byte-length-encoded strings (``#N"...``) count bytes. Recursion
depth equals the parenthesis depth, which is checked against ``max_depth`` before
descending, so no input can raise RecursionError; every fault raises ACLParseError with
the byte offset where it was detected.
"""
from __future__ import annotations

import math
from datetime import datetime
from typing import Callable, NoReturn

from nonholo.comm import acl_lexical as lex
from nonholo.comm.errors import ACLParseError
from nonholo.comm.message import (
    PARAMETER_ATTRIBUTES,
    PERFORMATIVES,
    ACLMessage,
    AgentID,
    Expression,
    RelativeTime,
)

Token = tuple[int, str, int]  # (kind, text, byte offset of the token's first byte)
_END = 0
_KIND_NAMES = {_END: "end of input", lex.OPEN: "'('", lex.CLOSE: "')'", lex.STRING: "a string",
               lex.BYTE_STRING: "a string", lex.ATOM: "a word"}


def decode(data: bytes | str, *, max_depth: int = lex.DEFAULT_MAX_DEPTH,
           max_size: int = lex.DEFAULT_MAX_SIZE) -> ACLMessage:
    """Parse one ACL message; raise ACLParseError (a ValueError) on any fault."""
    lex.check_limits(max_depth, max_size)
    if isinstance(data, str) and len(data) > max_size:  # at least as many bytes as characters
        raise ACLParseError(f"message is over {max_size} bytes, longer than the limit", max_size)
    if isinstance(data, str):
        try:
            data = data.encode("utf-8")
        except UnicodeEncodeError as exc:  # a lone surrogate has no UTF-8 form
            raise ACLParseError("text holds a lone surrogate, which is not Unicode text",
                                len(data[:exc.start].encode("utf-8", "surrogatepass"))) from None
    if len(data) > max_size:
        raise ACLParseError(f"message is {len(data)} bytes, longer than the {max_size}-byte limit",
                            max_size)
    return _Parser(bytes(data), max_depth).message()


def tokenize(data: bytes) -> list[Token]:
    """All tokens of ``data`` followed by an end token. One tight loop, because lexing is
    most of the decoding time; byte-length strings restart the scan after their body."""
    tokens: list[Token] = []
    append = tokens.append
    pos = 0
    while True:
        for match in lex.TOKEN.finditer(data, pos):
            if match.start() != pos:  # finditer skipped bytes that start no token
                _raise_lexical_error(data, pos)
            kind = match.lastindex
            pos = match.end()
            if kind == lex.ATOM:
                start = match.start(5)
                append((kind, _text(data[start:pos], start), start))
            elif kind == lex.OPEN or kind == lex.CLOSE:
                append((kind, "", pos - 1))
            elif kind == lex.STRING:
                start = match.start(3)
                append((kind, _text(data[start:pos - 1].replace(b'\\"', b'"'), start), start - 1))
            else:
                length = int(match.group(4))
                if pos + length > len(data):
                    raise ACLParseError(f"byte-length string declares {length} bytes but only "
                                        f"{len(data) - pos} remain", match.start(4) - 1)
                append((lex.BYTE_STRING, _text(data[pos:pos + length], pos), match.start(4) - 1))
                pos += length
                break
        else:
            end = lex.WHITESPACE.match(data, pos).end()
            if end != len(data):
                _raise_lexical_error(data, pos)
            append((_END, "", end))
            return tokens


def _text(raw: bytes, offset: int) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ACLParseError("invalid UTF-8", offset + exc.start) from None


def _raise_lexical_error(data: bytes, pos: int) -> NoReturn:
    pos = lex.WHITESPACE.match(data, pos).end()
    byte = data[pos]
    if byte == ord('"'):
        raise ACLParseError("unterminated string literal", pos)
    if byte == ord("#"):
        raise ACLParseError('malformed byte-length string header, expected #<digits>"', pos)
    raise ACLParseError(f"unexpected control byte 0x{byte:02x}", pos)


class _Parser:
    __slots__ = ("tokens", "index", "max_depth")

    def __init__(self, data: bytes, max_depth: int) -> None:
        self.tokens = tokenize(data)
        self.index = 0
        self.max_depth = max_depth

    def next(self) -> Token:
        token = self.tokens[self.index]
        self.index += 1
        return token

    def expect_open(self, what: str) -> Token:
        token = self.next()
        if token[0] != lex.OPEN:
            self.fail(token, f"expected '(' to start {what}")
        return token

    @staticmethod
    def fail(token: Token, message: str):
        kind, text, offset = token
        found = repr(text if len(text) <= 40 else text[:40] + "...") if kind in (lex.ATOM, lex.STRING, lex.BYTE_STRING) else _KIND_NAMES[kind]
        raise ACLParseError(f"{message}, found {found}", offset)

    def check_depth(self, depth: int, token: Token) -> None:
        if depth > self.max_depth:
            raise ACLParseError(f"nesting deeper than the limit of {self.max_depth}", token[2])

    # -- message ------------------------------------------------------------------------
    def message(self) -> ACLMessage:
        self.expect_open("a message")
        token = self.next()
        performative = token[1].lower()
        if token[0] != lex.ATOM or performative not in PERFORMATIVES:
            self.fail(token, "expected one of the 22 FIPA performatives")
        fields: dict[str, object] = {}
        user: dict[str, Expression] = {}
        seen: set[str] = set()
        while True:
            token = self.next()
            if token[0] == lex.CLOSE:
                break
            if token[0] == _END:
                raise ACLParseError("missing ')' at the end of the message", token[2])
            if token[0] != lex.ATOM or not token[1].startswith(":"):
                self.fail(token, "expected a parameter such as :content, or ')'")
            name = token[1][1:].lower()
            if name in seen:
                raise ACLParseError(f"duplicate parameter :{name}", token[2])
            seen.add(name)
            if name in PARAMETER_ATTRIBUTES:
                fields[PARAMETER_ATTRIBUTES[name]] = self._PARAMETER_READERS[name](self, token)
            elif name.startswith("x-") and len(name) > 2:
                user[token[1][3:]] = self.top_expression(token)
            else:
                raise ACLParseError(f"unknown parameter {token[1]} (user parameters start "
                                    f"with :X-)", token[2])
        trailing = self.next()
        if trailing[0] != _END:
            raise ACLParseError("trailing data after the message", trailing[2])
        return ACLMessage(performative, user_params=user, **fields)  # type: ignore[arg-type]

    # -- parameter values ---------------------------------------------------------------
    def value_token(self, parameter: Token) -> Token:
        # Every parameter takes a value, so the token after a parameter name is always a
        # value, even a word starting with ":" (a Word of the grammar).
        token = self.next()
        if token[0] in (lex.CLOSE, _END):
            self.fail(token, f"expected a value for {parameter[1]}")
        return token

    def top_expression(self, parameter: Token) -> Expression:
        return self.expression(self.value_token(parameter), 1)

    def content(self, parameter: Token) -> str:
        token = self.value_token(parameter)
        if token[0] not in (lex.STRING, lex.BYTE_STRING):
            self.fail(token, ":content must be a string (quoted or byte-length encoded)")
        return token[1]

    def protocol(self, parameter: Token) -> str:
        token = self.value_token(parameter)
        if token[0] != lex.ATOM or not isinstance(self.atom(token), str):
            self.fail(token, ":protocol must be a word")
        return token[1]

    def reply_by(self, parameter: Token) -> datetime | RelativeTime:
        token = self.value_token(parameter)
        value = self.atom(token) if token[0] == lex.ATOM else None
        if not isinstance(value, (datetime, RelativeTime)):
            self.fail(token, ":reply-by must be a date-time such as 20250101T120005000Z")
        return value

    def sender(self, parameter: Token) -> AgentID:
        return self.agent_id(self.value_token(parameter), 1)

    def agent_set(self, parameter: Token) -> tuple[AgentID, ...]:
        return self.collection(self.value_token(parameter), 1, "set", self.agent_id)

    _PARAMETER_READERS: dict[str, Callable[["_Parser", Token], object]] = {
        "sender": sender, "receiver": agent_set, "reply-to": agent_set, "content": content,
        "reply-with": top_expression, "reply-by": reply_by, "in-reply-to": top_expression,
        "encoding": top_expression, "language": top_expression, "ontology": top_expression,
        "protocol": protocol, "conversation-id": top_expression,
    }

    # -- expressions --------------------------------------------------------------------
    def expression(self, token: Token, depth: int) -> Expression:
        kind = token[0]
        if kind == lex.ATOM:
            return self.atom(token)
        if kind in (lex.STRING, lex.BYTE_STRING):
            return token[1]
        if kind != lex.OPEN:
            self.fail(token, "expected an expression")
        self.check_depth(depth + 1, token)
        items: list[Expression] = []
        while True:
            item = self.next()
            if item[0] == lex.CLOSE:
                return tuple(items)
            if item[0] == _END:
                raise ACLParseError("missing ')' for this '('", token[2])
            items.append(self.expression(item, depth + 1))

    def atom(self, token: Token) -> Expression:
        text, offset = token[1], token[2]
        first = text[0]
        if first in lex.NUMBER_START:
            if lex.INTEGER.fullmatch(text):
                try:
                    return int(text)
                except ValueError:  # beyond Python's int-from-string digit limit
                    raise ACLParseError("integer literal too long", offset) from None
            if lex.FLOAT.fullmatch(text):
                number = float(text)
                if not math.isfinite(number):
                    raise ACLParseError("number out of the range of a double", offset)
                return number
            match = lex.DATETIME.fullmatch(text)
            if match:
                try:
                    return lex.datetime_from_match(match)
                except ValueError as exc:
                    raise ACLParseError(f"invalid date-time: {exc}", offset) from None
            if first not in "+.":
                raise ACLParseError(f"{text!r} is neither a number, a date-time nor a word",
                                    offset)
        elif first in "#@":
            raise ACLParseError(f"a word cannot start with {first!r}", offset)
        return text

    # -- agent identifiers --------------------------------------------------------------
    def collection(self, token: Token, depth: int, keyword: str, read_item):
        if token[0] != lex.OPEN:
            self.fail(token, f"expected ({keyword} ...)")
        self.check_depth(depth + 1, token)
        head = self.next()
        if head[0] != lex.ATOM or head[1].lower() != keyword:
            self.fail(head, f"expected the keyword {keyword!r}")
        items = []
        while True:
            item = self.next()
            if item[0] == lex.CLOSE:
                return tuple(items)
            if item[0] == _END:
                raise ACLParseError("missing ')' for this '('", token[2])
            items.append(read_item(item, depth + 1))

    def url(self, token: Token, depth: int) -> str:
        if token[0] not in (lex.ATOM, lex.STRING, lex.BYTE_STRING) or (
                token[0] == lex.ATOM and not lex.is_word(token[1])):
            self.fail(token, "expected an address (URL): a word or a string")
        return token[1]

    def agent_id(self, token: Token, depth: int) -> AgentID:
        if token[0] != lex.OPEN:
            self.fail(token, "expected (agent-identifier ...)")
        self.check_depth(depth + 1, token)
        head = self.next()
        if head[0] != lex.ATOM or head[1].lower() != "agent-identifier":
            self.fail(head, "expected the keyword 'agent-identifier'")
        slots: dict[str, object] = {}
        user: dict[str, Expression] = {}
        seen: set[str] = set()
        while True:
            slot = self.next()
            if slot[0] == lex.CLOSE:
                break
            if slot[0] != lex.ATOM or not slot[1].startswith(":"):
                self.fail(slot, "expected :name, :addresses, :resolvers, :X-... or ')'")
            name = slot[1][1:].lower()
            if name in seen:
                raise ACLParseError(f"duplicate agent-identifier slot :{name}", slot[2])
            seen.add(name)
            if name == "name":
                value = self.value_token(slot)
                if value[0] not in (lex.ATOM, lex.STRING, lex.BYTE_STRING) or not value[1] or (
                        value[0] == lex.ATOM and not lex.is_word(value[1])):
                    self.fail(value, "agent :name must be a non-empty word or string")
                slots["name"] = value[1]
            elif name == "addresses":
                slots["addresses"] = self.collection(self.value_token(slot), depth + 1,
                                                     "sequence", self.url)
            elif name == "resolvers":
                slots["resolvers"] = self.collection(self.value_token(slot), depth + 1,
                                                     "sequence", self.agent_id)
            elif name.startswith("x-") and len(name) > 2:
                user[slot[1][3:]] = self.expression(self.value_token(slot), depth + 1)
            else:
                raise ACLParseError(f"unknown agent-identifier slot {slot[1]}", slot[2])
        if "name" not in slots:
            raise ACLParseError("agent-identifier without :name", token[2])
        return AgentID(user_params=user, **slots)  # type: ignore[arg-type]
