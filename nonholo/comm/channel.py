"""Codec plus envelope: ACL message -> authenticated frame and back, verifying before parsing."""
from __future__ import annotations

from nonholo.comm.acl_decode import decode
from nonholo.comm.acl_encode import encode
from nonholo.comm.acl_lexical import DEFAULT_MAX_DEPTH, DEFAULT_MAX_SIZE
from nonholo.comm.envelope import Opened, Opener, Sealer
from nonholo.comm.message import ACLMessage


class SecureChannel:
    """``pack`` encodes and seals; ``unpack`` authenticates, checks freshness and replay,
    and only then decodes. Either side may be omitted for a send-only or receive-only end."""

    def __init__(self, sealer: Sealer | None = None, opener: Opener | None = None, *,
                 max_depth: int = DEFAULT_MAX_DEPTH, max_size: int = DEFAULT_MAX_SIZE) -> None:
        self.sealer = sealer
        self.opener = opener
        self.max_depth = max_depth
        self.max_size = max_size

    def pack(self, message: ACLMessage) -> bytes:
        if self.sealer is None:
            raise RuntimeError("this channel has no sealing key")
        return self.sealer.seal(encode(message, max_depth=self.max_depth, max_size=self.max_size))

    def unpack(self, frame: bytes) -> tuple[Opened, ACLMessage]:
        if self.opener is None:
            raise RuntimeError("this channel has no verification keys")
        opened = self.opener.open(frame)
        return opened, decode(opened.payload, max_depth=self.max_depth, max_size=self.max_size)
