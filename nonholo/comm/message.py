"""The FIPA-ACL message model (SC00061G): performatives, agent identifiers, expressions.

Values are plain Python objects so that messages compare with ``==`` and build without
ceremony:

* a Word and a String both become ``str`` (the encoder quotes only what must be quoted,
  so the distinction carries no meaning of its own once decoded);
* a Number becomes ``int`` or ``float`` (always finite);
* an absolute DateTime becomes a ``datetime`` (timezone-aware UTC when it carried ``Z``,
  naive, i.e. local, when it carried no designator); a relative one a ``RelativeTime``;
* a nested expression ``( ... )`` becomes a ``tuple`` of expressions.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from typing import Mapping, Union

PERFORMATIVES: frozenset[str] = frozenset(
    {
        "accept-proposal", "agree", "cancel", "cfp", "confirm", "disconfirm", "failure",
        "inform", "inform-if", "inform-ref", "not-understood", "propagate", "propose",
        "proxy", "query-if", "query-ref", "refuse", "reject-proposal", "request",
        "request-when", "request-whenever", "subscribe",
    }
)


@dataclass(frozen=True, slots=True)
class RelativeTime:
    """A signed DateTime offset such as ``+00000000T000500000`` (plus five minutes).

    Kept as its calendar fields because years and months have no fixed length.
    """

    negative: bool
    years: int = 0
    months: int = 0
    days: int = 0
    hours: int = 0
    minutes: int = 0
    seconds: int = 0
    milliseconds: int = 0

    def __post_init__(self) -> None:
        widths = {"years": 9999, "months": 99, "days": 99, "hours": 99, "minutes": 99,
                  "seconds": 99, "milliseconds": 999}
        for name, largest in widths.items():
            value = getattr(self, name)
            if type(value) is not int or not 0 <= value <= largest:
                raise ValueError(f"RelativeTime.{name} must be an int in 0..{largest}, got {value!r}")


Expression = Union[str, int, float, datetime, RelativeTime, tuple["Expression", ...]]
DateTimeValue = Union[datetime, RelativeTime]


def _frozen_mapping(value: Mapping[str, Expression] | None) -> dict[str, Expression]:
    return dict(value or {})


@dataclass(frozen=True, slots=True)
class AgentID:
    """``(agent-identifier :name ... :addresses (sequence ...) :resolvers (sequence ...))``.

    ``user_params`` holds the ``:X-`` slots, keyed by name without the ``X-`` prefix.
    Equality is structural; hashing uses the name only, as JADE compares AIDs by name.
    """

    name: str
    addresses: tuple[str, ...] = ()
    resolvers: tuple["AgentID", ...] = ()
    user_params: Mapping[str, Expression] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"agent name must be a non-empty string, got {self.name!r}")
        object.__setattr__(self, "addresses", tuple(self.addresses))
        object.__setattr__(self, "resolvers", tuple(self.resolvers))
        object.__setattr__(self, "user_params", _frozen_mapping(self.user_params))

    def __hash__(self) -> int:
        return hash(self.name)


@dataclass(frozen=True, slots=True)
class ACLMessage:
    """One communicative act. Only ``performative`` is mandatory.

    ``receivers``/``reply_to`` are ``None`` when absent and a tuple (possibly empty, which
    encodes as ``(set)``) when present. ``user_params`` holds ``:X-`` parameters keyed by
    name without the prefix.
    """

    performative: str
    sender: AgentID | None = None
    receivers: tuple[AgentID, ...] | None = None
    reply_to: tuple[AgentID, ...] | None = None
    content: str | None = None
    language: Expression | None = None
    encoding: Expression | None = None
    ontology: Expression | None = None
    protocol: str | None = None
    conversation_id: Expression | None = None
    reply_with: Expression | None = None
    in_reply_to: Expression | None = None
    reply_by: DateTimeValue | None = None
    user_params: Mapping[str, Expression] = field(default_factory=dict)

    def __post_init__(self) -> None:
        performative = self.performative.lower()
        if performative not in PERFORMATIVES:
            raise ValueError(f"unknown performative {self.performative!r}")
        object.__setattr__(self, "performative", performative)
        if self.receivers is not None:
            object.__setattr__(self, "receivers", tuple(self.receivers))
        if self.reply_to is not None:
            object.__setattr__(self, "reply_to", tuple(self.reply_to))
        object.__setattr__(self, "user_params", _frozen_mapping(self.user_params))

    __hash__ = None  # type: ignore[assignment]  # mutable mappings inside: not hashable


# Parameter names in the order JADE's StringACLCodec writes them; the ACL spelling maps to
# the attribute name of ACLMessage.
PARAMETER_ATTRIBUTES: dict[str, str] = {
    "sender": "sender",
    "receiver": "receivers",
    "reply-to": "reply_to",
    "content": "content",
    "reply-with": "reply_with",
    "reply-by": "reply_by",
    "in-reply-to": "in_reply_to",
    "encoding": "encoding",
    "language": "language",
    "ontology": "ontology",
    "protocol": "protocol",
    "conversation-id": "conversation_id",
}
