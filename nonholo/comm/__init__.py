"""nonholo.comm: FIPA-ACL messaging for leader-follower fleets.

Layers (see docs/comm.md)::

    ACLMessage <-> ACL string (acl_encode / acl_decode)
      -> HMAC-SHA256 envelope with replay/freshness checks (envelope, keys, channel)
      -> Transport (transports.inproc | transports.tcp | transports.rfcomm | transports.zenoh)

Importing this package loads only the stdlib; transports are imported from their modules.
"""
from nonholo.comm.acl_decode import decode
from nonholo.comm.acl_encode import encode, encode_text
from nonholo.comm.channel import SecureChannel
from nonholo.comm.envelope import Opened, Opener, Sealer
from nonholo.comm.errors import (
    ACLEncodeError, ACLParseError, CommError, ContentError, EnvelopeError, ForgedMessage,
    KeyFileError, MalformedEnvelope, ProtocolError, ReplayedMessage, SenderMismatch, StaleMessage,
    UnknownKey,
)
from nonholo.comm.message import PERFORMATIVES, ACLMessage, AgentID, RelativeTime

__all__ = [
    "ACLEncodeError", "ACLMessage", "ACLParseError", "AgentID", "CommError", "ContentError",
    "EnvelopeError", "ForgedMessage", "KeyFileError", "MalformedEnvelope", "Opened", "Opener",
    "PERFORMATIVES", "ProtocolError", "RelativeTime", "ReplayedMessage", "SecureChannel",
    "Sealer", "SenderMismatch", "StaleMessage", "UnknownKey", "decode", "encode", "encode_text",
]
