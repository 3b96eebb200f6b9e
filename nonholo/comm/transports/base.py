"""The transport interface shared by every link."""
from __future__ import annotations

import abc
import asyncio
import time
from dataclasses import dataclass
from typing import Callable

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
    """A stream carried a frame length above the limit; the stream is closed because
    resynchronising inside a byte stream is unsafe."""


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

    async def recv_stamped(self) -> tuple[str, bytes, float]:
        """Next (peer name, frame, arrival): ``arrival`` is when the frame was read from
        the network, on ``time.monotonic()`` (here: when ``recv`` returned it)."""
        peer, frame = await self.recv()
        return peer, frame, time.monotonic()

    @abc.abstractmethod
    async def close(self) -> None:
        """Release the link; idempotent."""

    def stats(self) -> dict:
        """Counters of this transport (frames, drops, closes); the keys depend on the kind."""
        return {}

    def check_frame(self, frame: bytes) -> None:
        if not 0 < len(frame) <= self.capabilities.max_frame:
            raise ValueError(f"frame of {len(frame)} bytes outside 1..{self.capabilities.max_frame}")


# Default bound of an inbox, in frames (a few seconds of a 100 Hz stream from 7 peers).
DEFAULT_INBOX_FRAMES = 4096


class InboxTransport(Transport):
    """A transport whose received frames wait in a bounded asyncio queue (``self.inbox``)
    until ``recv``, each stamped with its arrival (``time.monotonic()`` when it was
    delivered, or the earlier moment the transport read it). ``deliver`` adds a frame; when the inbox is full the oldest frame is
    dropped and counted in ``inbox_dropped`` (latest-value semantics: an old state is
    worth less than a new one). Closing wakes a pending ``recv``."""

    _CLOSED = object()

    def __init__(self, inbox_frames: int = DEFAULT_INBOX_FRAMES) -> None:
        if isinstance(inbox_frames, bool) or not isinstance(inbox_frames, int) \
                or inbox_frames < 1:
            raise ValueError("inbox_frames must be a positive integer")
        self.inbox: asyncio.Queue = asyncio.Queue(inbox_frames)
        self.inbox_dropped = 0
        self._closed = False

    def ensure_open(self) -> None:
        if self._closed:
            raise TransportClosed(f"{self.name} is closed")

    def deliver(self, peer: str, frame: bytes,
                on_taken: Callable[[bytes], None] | None = None, arrived: float | None = None) -> None:
        """Queue a received frame; ``on_taken(frame)`` runs when it leaves the inbox (taken
        by ``recv`` or dropped), for transports that ration the inbox per peer; ``arrived``:
        when it was read (default now, on ``time.monotonic()``)."""
        if self._closed:
            return
        while self.inbox.full():
            _, dropped, dropped_taken, _ = self.inbox.get_nowait()
            self.inbox_dropped += 1
            if dropped_taken is not None:
                dropped_taken(dropped)
        self.inbox.put_nowait((peer, frame, on_taken, time.monotonic() if arrived is None else arrived))

    def stats(self) -> dict:
        return {"inbox": self.inbox.qsize(), "inbox_dropped": self.inbox_dropped}

    async def recv(self) -> tuple[str, bytes]:
        peer, frame, _ = await self.recv_stamped()
        return peer, frame

    async def recv_stamped(self) -> tuple[str, bytes, float]:
        self.ensure_open()
        item = await self.inbox.get()
        if item is self._CLOSED:
            raise TransportClosed(f"{self.name} is closed")
        peer, frame, on_taken, arrived = item
        if on_taken is not None:
            on_taken(frame)
        return peer, frame, arrived

    def mark_closed(self) -> bool:
        """Mark closed and wake receivers; False if it already was (close is idempotent)."""
        if self._closed:
            return False
        self._closed = True
        if not self.inbox.full():  # a full inbox has no waiting receiver to wake
            self.inbox.put_nowait(self._CLOSED)
        return True
