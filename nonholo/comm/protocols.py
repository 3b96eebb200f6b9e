"""FIPA-Subscribe and FIPA-Request interaction protocols as transition tables.

Both ends of a conversation run the same machine over every message they send or
receive; ``role`` says who spoke (initiator: the follower subscribing or the agent
requesting; participant: the leader). A message the protocol does not allow in the
current state raises ProtocolError and leaves the state unchanged.
"""
from __future__ import annotations

from typing import Literal

from nonholo.comm.errors import ProtocolError
from nonholo.comm.message import ACLMessage

Role = Literal["initiator", "participant"]
I, P = "initiator", "participant"

# (state, speaker, performative) -> next state
SUBSCRIBE_TRANSITIONS: dict[tuple[str, str, str], str] = {
    ("start", I, "subscribe"): "requested",
    ("requested", P, "agree"): "subscribed",
    ("requested", P, "refuse"): "refused",
    ("requested", P, "not-understood"): "not-understood",
    ("requested", P, "failure"): "failed",
    ("subscribed", P, "inform"): "subscribed",
    ("subscribed", P, "failure"): "failed",
    ("subscribed", I, "cancel"): "cancelled",
    ("requested", I, "cancel"): "cancelled",
    # Informs already in flight when the cancel left, and the cancel's own answer.
    ("cancelled", P, "inform"): "cancelled",
    ("cancelled", P, "failure"): "cancelled",
}

REQUEST_TRANSITIONS: dict[tuple[str, str, str], str] = {
    ("start", I, "request"): "requested",
    ("requested", P, "agree"): "agreed",
    ("requested", P, "refuse"): "refused",
    ("requested", P, "not-understood"): "not-understood",
    ("requested", P, "inform"): "done",      # agree may be skipped for a quick action
    ("requested", P, "failure"): "failed",
    ("agreed", P, "inform"): "done",
    ("agreed", P, "failure"): "failed",
    ("requested", I, "cancel"): "cancelled",
    ("agreed", I, "cancel"): "cancelled",
}

PROTOCOLS = {"fipa-subscribe": SUBSCRIBE_TRANSITIONS, "fipa-request": REQUEST_TRANSITIONS}


class Conversation:
    """State of one conversation; ``advance`` checks and applies a message."""

    def __init__(self, protocol: str, conversation_id: str) -> None:
        if protocol not in PROTOCOLS:
            raise ValueError(f"unsupported protocol {protocol!r}; known: {sorted(PROTOCOLS)}")
        self.protocol = protocol
        self.conversation_id = conversation_id
        self.state = "start"
        self._transitions = PROTOCOLS[protocol]

    @property
    def finished(self) -> bool:
        return not any(state == self.state for state, _, _ in self._transitions)

    def advance(self, message: ACLMessage, speaker: Role) -> str:
        if message.protocol != self.protocol:
            raise ProtocolError(f"message protocol {message.protocol!r} is not {self.protocol}")
        if message.conversation_id != self.conversation_id:
            raise ProtocolError(f"conversation {message.conversation_id!r} is not "
                                f"{self.conversation_id!r}")
        next_state = self._transitions.get((self.state, speaker, message.performative))
        if next_state is None:
            raise ProtocolError(f"{speaker} may not send {message.performative} in state "
                                f"{self.state} of {self.protocol}")
        self.state = next_state
        return next_state
