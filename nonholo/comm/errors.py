"""Exceptions of the communication layer. All are ``ValueError`` subclasses so that one
``except ValueError`` at a trust boundary catches every rejection of foreign input."""
from __future__ import annotations


class CommError(ValueError):
    """Base class of every rejection raised by ``nonholo.comm``."""


class ACLParseError(CommError):
    """The bytes are not a valid ACL message. ``offset`` is the byte offset of the fault."""

    def __init__(self, message: str, offset: int) -> None:
        super().__init__(f"{message} (at byte {offset})")
        self.reason = message
        self.offset = offset


class ACLEncodeError(CommError):
    """The message cannot be written in the string representation (e.g. NaN, bad Word)."""


class EnvelopeError(CommError):
    """A frame failed authentication or freshness checks; drop it (and count it)."""


class MalformedEnvelope(EnvelopeError):
    """Too short, wrong magic/version, or the length field disagrees with the frame."""


class UnknownKey(EnvelopeError):
    """The key id is not in the receiver's keyring (or not allowed for that sender)."""


class ForgedMessage(EnvelopeError):
    """The HMAC tag does not match the bytes."""


class ReplayedMessage(EnvelopeError):
    """The (sender, epoch, seq) was already accepted, is out of order, or too old for the
    replay window, or the epoch was retired by a reboot."""


class SenderMismatch(EnvelopeError):
    """The ACL ``:sender`` is missing or names another agent than the one the envelope's
    authenticated sender id belongs to (an authentic sender impersonating another)."""


class StaleMessage(EnvelopeError):
    """The send time is older than the freshness limit or too far in the future."""


class KeyFileError(CommError):
    """A key source is missing, malformed, or readable by other users."""


class ContentError(CommError):
    """The ACL message is well formed but its content breaks the ontology."""


class ProtocolError(CommError):
    """A message is not allowed in the current state of its interaction protocol."""
