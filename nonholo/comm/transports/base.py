"""The transport interface shared by every link."""
from __future__ import annotations

import abc
import asyncio
from dataclasses import dataclass

from nonholo.comm.envelope import OVERHEAD
from nonholo.comm.acl_lexical import DEFAULT_MAX_SIZE
from nonholo.comm.errors import CommError

# Largest frame: the largest ACL message the decoder accepts plus the envelope.
DEFAULT_MAX_FRAME = DEFAULT_MAX_SIZE + OVERHEAD


class TransportClosed(ConnectionError):
    """The transport (or its only peer) is gone; ``recv`` raises it instead of blocking."""


class UnknownPeer(CommError):
    """``send(..., to=name)`` named a peer this transport does not know."""


class FramingError(CommError):
    """A stream carried a frame length of zero or above the limit; the stream is closed
    because resynchronising inside a byte stream is unsafe."""


@dataclass(frozen=True, slots=True)
class Capabilities:
    reliable: bool     # no silent loss while the link is up
    ordered: bool      # frames from one sender arrive in send order
    broadcast: bool    # one send reaches all peers without per-peer copies on the wire
    max_frame: int     # largest frame in bytes


class Transport(abc.ABC):
    """Frames (bytes) between named endpoints. ``to=None`` sends to every peer."""

    name: str
    capabilities: Capabilities

    @abc.abstractmethod
    async def send(self, frame: bytes, to: str | None = None) -> None:
        """Queue ``frame`` for one peer or all; raises UnknownPeer or TransportClosed."""

    @abc.abstractmethod
    async def recv(self) -> tuple[str, bytes]:
        """Next (peer name, frame); raises TransportClosed once closed."""

    @abc.abstractmethod
    async def close(self) -> None:
        """Release the link; idempotent."""

    def check_frame(self, frame: bytes) -> None:
        if not 0 < len(frame) <= self.capabilities.max_frame:
            raise ValueError(f"frame of {len(frame)} bytes outside 1..{self.capabilities.max_frame}")


class InboxTransport(Transport):
    """A transport whose received frames wait in an asyncio queue (``self.inbox``) until
    ``recv``; closing puts a sentinel in it so that a pending ``recv`` wakes up."""

    _CLOSED = object()

    def __init__(self) -> None:
        self.inbox: asyncio.Queue = asyncio.Queue()
        self._closed = False

    def ensure_open(self) -> None:
        if self._closed:
            raise TransportClosed(f"{self.name} is closed")

    async def recv(self) -> tuple[str, bytes]:
        self.ensure_open()
        item = await self.inbox.get()
        if item is self._CLOSED:
            raise TransportClosed(f"{self.name} is closed")
        return item

    def mark_closed(self) -> bool:
        """Mark closed and wake receivers; False if it already was (close is idempotent)."""
        if self._closed:
            return False
        self._closed = True
        self.inbox.put_nowait(self._CLOSED)
        return True
