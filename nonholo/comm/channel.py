"""Codec plus envelope: ACL message -> authenticated frame and back, verifying before parsing."""
from __future__ import annotations

from collections import Counter
from typing import Mapping

from nonholo.comm.acl_decode import decode
from nonholo.comm.acl_encode import encode
from nonholo.comm.acl_lexical import DEFAULT_MAX_DEPTH, DEFAULT_MAX_SIZE
from nonholo.comm.envelope import Opened, Opener, Sealer
from nonholo.comm.errors import CommError, SenderMismatch
from nonholo.comm.message import ACLMessage

_REQUIRED = object()


class SecureChannel:
    """``pack`` encodes and seals; ``unpack`` authenticates, checks freshness and replay,
    only then decodes, and finally checks that the ACL ``:sender`` is the agent the
    envelope's authenticated sender id belongs to. Either side may be omitted for a
    send-only or receive-only end.

    ``senders`` (required with an opener) maps each envelope sender id to the one agent
    name it may write in ``:sender``; a message without ``:sender``, from an id not in the
    map, or naming another agent raises ``SenderMismatch``. Names compare exactly. Pass
    ``senders=None`` only if the application binds names itself.

    ``rejected`` counts every rejection ``unpack`` raised, by exception class name.
    """

    def __init__(self, sealer: Sealer | None = None, opener: Opener | None = None, *,
                 senders: Mapping[int, str] | None = _REQUIRED,  # type: ignore[assignment]
                 max_depth: int = DEFAULT_MAX_DEPTH, max_size: int = DEFAULT_MAX_SIZE) -> None:
        if senders is _REQUIRED:
            if opener is not None:
                raise TypeError("a receiving SecureChannel needs senders= (envelope sender "
                                "id -> the agent name its :sender must carry), or "
                                "senders=None to bind names in the application")
            senders = None
        self.sealer = sealer
        self.opener = opener
        self.senders = None if senders is None else dict(senders)
        self.max_depth = max_depth
        self.max_size = max_size
        self.rejected: Counter[str] = Counter()

    def pack(self, message: ACLMessage) -> bytes:
        if self.sealer is None:
            raise RuntimeError("this channel has no sealing key")
        return self.sealer.seal(encode(message, max_depth=self.max_depth, max_size=self.max_size))

    def unpack(self, frame: bytes) -> tuple[Opened, ACLMessage]:
        if self.opener is None:
            raise RuntimeError("this channel has no verification keys")
        try:
            opened = self.opener.open(frame)
            message = decode(opened.payload, max_depth=self.max_depth, max_size=self.max_size)
            self._check_sender(opened, message)
        except CommError as exc:
            self.rejected[type(exc).__name__] += 1
            raise
        return opened, message

    def _check_sender(self, opened: Opened, message: ACLMessage) -> None:
        if self.senders is None:
            return
        expected = self.senders.get(opened.sender_id)
        actual = None if message.sender is None else message.sender.name
        if expected is None or actual != expected:
            raise SenderMismatch(f"envelope sender {opened.sender_id} "
                                 f"({expected or 'unknown'}) wrote :sender {actual!r}")
