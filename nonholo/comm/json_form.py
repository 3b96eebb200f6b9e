"""JSON form of ACL messages, for the CLI and for tools that are not Python.

Keys are the ACL parameter names (``performative``, ``sender``, ``receiver``, ``reply-to``,
``content``, ``conversation-id``, ...) and ``X-name`` for user parameters. Agent
identifiers are objects ``{"name", "addresses", "resolvers", "X-...": ...}``. Nested
expressions are arrays; DateTimes are ``{"datetime": "20250101T120005000Z"}``.
"""
from __future__ import annotations

from datetime import datetime
from typing import Any

from nonholo.comm import acl_lexical as lex
from nonholo.comm.errors import CommError
from nonholo.comm.message import PARAMETER_ATTRIBUTES, ACLMessage, AgentID, Expression, RelativeTime

JSONValue = Any


class JSONFormError(CommError):
    """The JSON does not describe an ACL message; ``path`` locates the fault."""


def message_to_json(message: ACLMessage) -> dict[str, JSONValue]:
    out: dict[str, JSONValue] = {"performative": message.performative}
    for acl_name, attribute in PARAMETER_ATTRIBUTES.items():
        value = getattr(message, attribute)
        if value is None:
            continue
        if acl_name == "sender":
            out[acl_name] = _agent_to_json(value)
        elif acl_name in ("receiver", "reply-to"):
            out[acl_name] = [_agent_to_json(aid) for aid in value]
        else:
            out[acl_name] = _expression_to_json(value)
    out.update({f"X-{k}": _expression_to_json(v) for k, v in message.user_params.items()})
    return out


def _agent_to_json(aid: AgentID) -> dict[str, JSONValue]:
    out: dict[str, JSONValue] = {"name": aid.name}
    if aid.addresses:
        out["addresses"] = list(aid.addresses)
    if aid.resolvers:
        out["resolvers"] = [_agent_to_json(r) for r in aid.resolvers]
    out.update({f"X-{k}": _expression_to_json(v) for k, v in aid.user_params.items()})
    return out


def _expression_to_json(value: Expression) -> JSONValue:
    if isinstance(value, tuple):
        return [_expression_to_json(item) for item in value]
    if isinstance(value, (datetime, RelativeTime)):
        return {"datetime": lex.format_datetime(value)}
    return value


def message_from_json(data: JSONValue) -> ACLMessage:
    """Inverse of ``message_to_json``; JSONFormError on unknown keys or wrong types."""
    obj = _object(data, "$")
    if "performative" not in obj:
        raise JSONFormError("$: missing performative")
    fields: dict[str, Any] = {}
    user: dict[str, Expression] = {}
    for key, value in obj.items():
        path = f"$.{key}"
        if key == "performative":
            continue
        if key == "sender":
            fields["sender"] = _agent_from_json(value, path)
        elif key in ("receiver", "reply-to"):
            fields[PARAMETER_ATTRIBUTES[key]] = tuple(
                _agent_from_json(item, f"{path}[{i}]") for i, item in enumerate(_array(value, path)))
        elif key in ("content", "protocol"):
            fields[PARAMETER_ATTRIBUTES[key]] = _string(value, path)
        elif key == "reply-by":
            fields["reply_by"] = _datetime_from_json(value, path)
        elif key in PARAMETER_ATTRIBUTES:
            fields[PARAMETER_ATTRIBUTES[key]] = _expression_from_json(value, path, 0)
        elif key[:2] in ("X-", "x-") and len(key) > 2:
            user[key[2:]] = _expression_from_json(value, path, 0)
        else:
            raise JSONFormError(f"{path}: unknown parameter")
    try:
        return ACLMessage(_string(obj["performative"], "$.performative"), user_params=user, **fields)
    except ValueError as exc:
        raise JSONFormError(f"$: {exc}") from None


def _agent_from_json(data: JSONValue, path: str) -> AgentID:
    obj = _object(data, path)
    slots: dict[str, Any] = {}
    user: dict[str, Expression] = {}
    for key, value in obj.items():
        if key == "name":
            slots["name"] = _string(value, f"{path}.name")
        elif key == "addresses":
            slots["addresses"] = tuple(_string(a, f"{path}.addresses[{i}]")
                                       for i, a in enumerate(_array(value, f"{path}.addresses")))
        elif key == "resolvers":
            slots["resolvers"] = tuple(_agent_from_json(r, f"{path}.resolvers[{i}]")
                                       for i, r in enumerate(_array(value, f"{path}.resolvers")))
        elif key[:2] in ("X-", "x-") and len(key) > 2:
            user[key[2:]] = _expression_from_json(value, f"{path}.{key}", 0)
        else:
            raise JSONFormError(f"{path}.{key}: unknown agent-identifier slot")
    try:
        return AgentID(user_params=user, **slots)
    except (TypeError, ValueError) as exc:
        raise JSONFormError(f"{path}: {exc}") from None


def _expression_from_json(value: JSONValue, path: str, depth: int) -> Expression:
    if depth > lex.HARD_MAX_DEPTH:
        raise JSONFormError(f"{path}: nested too deeply")
    if isinstance(value, list):
        return tuple(_expression_from_json(item, f"{path}[{i}]", depth + 1)
                     for i, item in enumerate(value))
    if isinstance(value, dict):
        return _datetime_from_json(value, path)
    if isinstance(value, bool) or value is None:
        raise JSONFormError(f"{path}: {value!r} has no ACL form")
    if isinstance(value, (str, int, float)):
        return value
    raise JSONFormError(f"{path}: unsupported value")


def _datetime_from_json(value: JSONValue, path: str) -> datetime | RelativeTime:
    obj = _object(value, path)
    text = obj.get("datetime")
    match = lex.DATETIME.fullmatch(text) if isinstance(text, str) and len(obj) == 1 else None
    if match is None:
        raise JSONFormError(f'{path}: expected {{"datetime": "YYYYMMDDThhmmssmmmZ"}}')
    try:
        return lex.datetime_from_match(match)
    except ValueError as exc:
        raise JSONFormError(f"{path}: {exc}") from None


def _object(value: JSONValue, path: str) -> dict[str, JSONValue]:
    if not isinstance(value, dict):
        raise JSONFormError(f"{path}: expected an object")
    return value


def _array(value: JSONValue, path: str) -> list[JSONValue]:
    if not isinstance(value, list):
        raise JSONFormError(f"{path}: expected an array")
    return value


def _string(value: JSONValue, path: str) -> str:
    if not isinstance(value, str):
        raise JSONFormError(f"{path}: expected a string")
    return value
