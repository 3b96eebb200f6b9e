"""Length-prefixed frames over a byte stream (TCP or Bluetooth RFCOMM): a hub (the
leader, like a piconet master) and the peers connected to it.

Framing: a 4-byte big-endian length, then the bytes. The length is checked against the
limit before the body is read. A frame of length zero is a keepalive: it is never
delivered, it only tells the other end that the link is alive.

Connection life (limits in ``StreamLimits``):

1. The hub sends a challenge and the peer must prove its link key (``hello``) within
   ``hello_timeout``; until then the peer learns nothing, and the hub counts it against
   ``max_pending`` (when full, an unproven connection of the source address holding the most
   is closed to make room, at random).
2. A proven peer whose name is already connected is refused; the connected one keeps
   its link. At most ``max_peers`` proven peers.
3. Each end closes a link that brought nothing, not even a keepalive, for
   ``idle_timeout``, and sends a keepalive after ``keepalive_interval`` without sending.
4. The hub never waits for one peer: ``send`` hands each target its own bounded queue.
   A peer that reads too slowly loses its own oldest queued frames (counted in
   ``stats()``); one whose socket accepts nothing for ``write_timeout`` is dropped.
5. Frames received wait in a bounded inbox; each peer may have at most
   ``inbox_frames_per_peer`` frames and ``inbox_bytes_per_peer`` bytes in it, beyond
   which the hub stops reading that peer (TCP flow control slows it down, not the others).
"""
from __future__ import annotations

import asyncio
import random
import secrets
import socket
import struct
import time
from collections import Counter, deque
from dataclasses import dataclass

from nonholo.comm.transports.base import (
    DEFAULT_MAX_FRAME, Capabilities, FramingError, InboxTransport, Transport, TransportClosed,
    UnknownPeer,
)
from nonholo.comm.transports.hello import (
    MAX_HELLO_BYTES, HelloFailed, HubHello, LinkAuth, PeerHello, check_name,
)

LENGTH = struct.Struct(">I")
KEEPALIVE = LENGTH.pack(0)
# Socket write buffer above which a hub link's frames wait in its own queue instead.
LINK_BUFFER_BYTES = 64 * 1024
CLOSE_GRACE_S = 1.0


@dataclass(frozen=True)
class StreamLimits:
    """Time-outs and bounds of a stream link (both ends use the same defaults)."""

    hello_timeout: float = 5.0        # s for the whole hello
    idle_timeout: float = 10.0        # s without any frame before a link is closed
    keepalive_interval: float = 2.0   # s without sending before a keepalive goes out
    write_timeout: float = 10.0       # s a socket may accept nothing before the link is dropped
    max_peers: int = 32               # proven peers on a hub
    max_pending: int = 64             # connections still in the hello on a hub
    send_queue_frames: int = 128      # per peer on a hub; oldest dropped beyond
    send_queue_bytes: int = 1 << 20   # per peer on a hub; oldest dropped beyond
    inbox_frames_per_peer: int = 64   # frames of one peer waiting for recv on a hub
    inbox_bytes_per_peer: int = 1 << 20

    def __post_init__(self) -> None:
        for name in ("hello_timeout", "idle_timeout", "keepalive_interval", "write_timeout"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not 0 < value <= 86400:
                raise ValueError(f"{name} must be a number of seconds in (0, 86400]")
        if self.keepalive_interval >= self.idle_timeout:
            raise ValueError("keepalive_interval must be shorter than idle_timeout, or idle "
                             "but healthy links are closed")
        for name in ("max_peers", "max_pending", "send_queue_frames", "send_queue_bytes",
                     "inbox_frames_per_peer", "inbox_bytes_per_peer"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 1 << 30:
                raise ValueError(f"{name} must be an integer in 1..2**30")


DEFAULT_LIMITS = StreamLimits()


@dataclass(slots=True)
class LinkTally:
    """Frame counters of one link (plain attributes: they are bumped for every frame)."""

    sent: int = 0
    received: int = 0
    dropped: int = 0          # frames the hub shed from this peer's full send queue
    keepalives_sent: int = 0
    keepalives_received: int = 0


def frame_bytes(payload: bytes) -> bytes:
    return LENGTH.pack(len(payload)) + payload


async def read_frame(reader: asyncio.StreamReader, max_frame: int) -> bytes:
    """Next frame (empty for a keepalive); FramingError on a length above ``max_frame``,
    TransportClosed at the end of the stream."""
    try:
        (length,) = LENGTH.unpack(await reader.readexactly(LENGTH.size))
        if length > max_frame:
            raise FramingError(f"frame length {length} above the limit of {max_frame}")
        return await reader.readexactly(length) if length else b""
    except (asyncio.IncompleteReadError, ConnectionError) as exc:
        raise TransportClosed("stream ended") from exc


async def _read_hello(reader: asyncio.StreamReader) -> bytes:
    message = await read_frame(reader, MAX_HELLO_BYTES)
    if not message:
        raise HelloFailed("empty hello message")
    return message


def _stream_capabilities(max_frame: int) -> Capabilities:
    # A star over unicast streams: "send to all" writes one copy per peer.
    return Capabilities(reliable=True, ordered=True, broadcast=False, max_frame=max_frame)


async def _close_writer(writer: asyncio.StreamWriter) -> None:
    """Close gracefully (flushing what is buffered) for at most CLOSE_GRACE_S, then abort."""
    if not writer.is_closing():
        writer.close()
    try:
        async with asyncio.timeout(CLOSE_GRACE_S):
            await writer.wait_closed()
    except (TimeoutError, ConnectionError):
        writer.transport.abort()


class StreamClient(Transport):
    """One connection to a hub (the follower side of the star). Create it with
    ``handshake`` (or ``over_socket``), which runs the authenticated hello."""

    def __init__(self, name: str, peer: str, reader: asyncio.StreamReader,
                 writer: asyncio.StreamWriter, max_frame: int,
                 limits: StreamLimits = DEFAULT_LIMITS, hub_epoch: int | None = None) -> None:
        self.name = name
        self.peer = peer
        self.hub_epoch = hub_epoch
        self.capabilities = _stream_capabilities(max_frame)
        self.limits = limits
        self._reader = reader
        self._writer = writer
        self._closed = False
        self._idle = False               # closed by the idle time-out
        self._last_sent = time.monotonic()
        self._waiting_since: float | None = None  # a recv is waiting for a frame since
        self.tally = LinkTally()
        # One task sends keepalives and watches for an idle hub: no timer per frame.
        self._keepalive_task = asyncio.ensure_future(self._watch())

    @classmethod
    async def handshake(cls, name: str, reader: asyncio.StreamReader,
                        writer: asyncio.StreamWriter, max_frame: int = DEFAULT_MAX_FRAME, *,
                        auth: LinkAuth, limits: StreamLimits = DEFAULT_LIMITS) -> "StreamClient":
        """Prove ``auth``'s key to the hub and check the hub's proof; HelloFailed (or
        HelloRefused) otherwise, with the connection closed."""
        try:
            hello = PeerHello(auth, name)
            async with asyncio.timeout(limits.hello_timeout):
                writer.write(frame_bytes(hello.answer(await _read_hello(reader))))
                await writer.drain()
                hub = hello.check_reply(await _read_hello(reader))
        except TimeoutError:
            writer.transport.abort()
            raise HelloFailed(f"no hello from the hub within {limits.hello_timeout} s") from None
        except (TransportClosed, FramingError, ConnectionError) as exc:
            writer.transport.abort()
            if isinstance(exc, HelloFailed):
                raise
            raise HelloFailed("the hub closed the connection during the hello (a wrong key or key id "
                              "for this name, or a hub flooded with connections)") from None
        except BaseException:
            writer.transport.abort()
            raise
        return cls(name, hub, reader, writer, max_frame, limits, hello.hub_epoch)

    @classmethod
    async def over_socket(cls, name: str, sock: socket.socket,
                          max_frame: int = DEFAULT_MAX_FRAME, *, auth: LinkAuth,
                          limits: StreamLimits = DEFAULT_LIMITS) -> "StreamClient":
        """Client over an already connected stream socket (RFCOMM, socketpair)."""
        reader, writer = await asyncio.open_connection(sock=sock)
        return await cls.handshake(name, reader, writer, max_frame, auth=auth, limits=limits)

    def _check_open(self) -> None:
        if self._closed or self._writer.is_closing():
            raise TransportClosed(f"{self.name} is closed")

    def _fail(self) -> None:
        self._closed = True
        if self._keepalive_task is not asyncio.current_task():
            self._keepalive_task.cancel()
        self._writer.transport.abort()

    async def send(self, frame: bytes, to: str | None = None) -> None:
        if to is not None and to != self.peer:
            raise UnknownPeer(f"{self.name} is connected only to {self.peer!r}")
        self.check_frame(frame)
        self._check_open()
        self._writer.write(frame_bytes(frame))
        self._last_sent = time.monotonic()
        self.tally.sent += 1
        if not self._writer.transport.get_write_buffer_size():
            return  # all of it went to the socket: nothing to wait for
        try:
            async with asyncio.timeout(self.limits.write_timeout):
                await self._writer.drain()
        except TimeoutError:
            self._fail()
            raise TransportClosed(f"{self.peer} accepted nothing for "
                                  f"{self.limits.write_timeout} s") from None
        except ConnectionError as exc:
            self._fail()
            raise TransportClosed("connection lost") from exc

    async def recv(self) -> tuple[str, bytes]:
        self._check_open()
        while True:
            self._waiting_since = time.monotonic()
            try:
                frame = await read_frame(self._reader, self.capabilities.max_frame)
            except (TransportClosed, FramingError):
                self._fail()
                if self._idle:
                    raise TransportClosed(f"nothing from {self.peer} for "
                                          f"{self.limits.idle_timeout} s (idle time-out)") from None
                raise
            finally:
                self._waiting_since = None
            if frame:
                self.tally.received += 1
                return self.peer, frame
            self.tally.keepalives_received += 1

    async def _watch(self) -> None:
        """Send a keepalive after keepalive_interval without sending; close the link when
        a recv has waited idle_timeout without any frame (a keepalive counts)."""
        interval, idle = self.limits.keepalive_interval, self.limits.idle_timeout
        while not self._closed:
            now = time.monotonic()
            waiting = self._waiting_since
            if waiting is not None and now - waiting >= idle:
                self._idle = True
                self._fail()
                return
            if now - self._last_sent >= interval:
                if self._writer.is_closing():
                    return
                if self._writer.transport.get_write_buffer_size() == 0:
                    self._writer.write(KEEPALIVE)
                    self.tally.keepalives_sent += 1
                self._last_sent = now
            wake = self._last_sent + interval
            if waiting is not None:
                wake = min(wake, waiting + idle)
            await asyncio.sleep(max(0.0, wake - time.monotonic()))

    def stats(self) -> dict:
        return {"peer": self.peer, "sent": self.tally.sent, "received": self.tally.received,
                "keepalives_sent": self.tally.keepalives_sent,
                "keepalives_received": self.tally.keepalives_received}

    async def close(self) -> None:
        self._closed = True
        self._keepalive_task.cancel()
        await asyncio.gather(self._keepalive_task, return_exceptions=True)
        await _close_writer(self._writer)


class _Link:
    """One proven peer on a hub: its socket, send queue and inbox ration."""

    def __init__(self, name: str, reader: asyncio.StreamReader,
                 writer: asyncio.StreamWriter) -> None:
        self.name = name
        self.reader = reader
        self.writer = writer
        self.queue: deque[bytes] = deque()
        self.queued_bytes = 0
        self.wake = asyncio.Event()       # frames were queued
        self.inbox_room = asyncio.Event()  # a frame of this peer left the inbox
        self.inbox_frames = 0
        self.inbox_bytes = 0
        self.last_sent = time.monotonic()
        self.connected_at = self.last_sent
        self.waiting_since: float | None = None  # the hub is waiting for its next frame since
        self.tally = LinkTally()
        self.closed = False
        self.tasks: list[asyncio.Task] = []

    def taken(self, frame: bytes) -> None:  # the hub's inbox let go of one of our frames
        self.inbox_frames -= 1
        self.inbox_bytes -= len(frame)
        self.inbox_room.set()

    def stats(self) -> dict:
        tally = self.tally
        return {"sent": tally.sent, "received": tally.received,
                "dropped": tally.dropped, "queued": len(self.queue),
                "queued_bytes": self.queued_bytes, "inbox": self.inbox_frames,
                "keepalives_sent": tally.keepalives_sent,
                "keepalives_received": tally.keepalives_received,
                "connected_s": round(time.monotonic() - self.connected_at, 3)}


def _source(writer: asyncio.StreamWriter) -> str:
    """A connection's source address (its host, without the port), for eviction."""
    peer = writer.get_extra_info("peername")
    return str(peer[0]) if isinstance(peer, tuple) and peer else str(peer)


class StreamServer(InboxTransport):
    """The hub of the star. Accepts connections from an ``asyncio.Server`` (see
    ``transports.tcp.serve_tcp``) or from ``attach_socket``; frames from all peers are
    merged into one bounded inbox. ``stats()`` reports every counter."""

    def __init__(self, name: str, max_frame: int = DEFAULT_MAX_FRAME, *, auth: LinkAuth,
                 limits: StreamLimits = DEFAULT_LIMITS) -> None:
        check_name(name)
        if not isinstance(auth, LinkAuth):
            raise TypeError("auth must be a LinkAuth")
        if limits.send_queue_bytes < max_frame:
            raise ValueError("send_queue_bytes must hold at least one frame of max_frame bytes")
        self.name = name
        self.auth = auth
        self.limits = limits
        self.epoch = secrets.randbits(32)
        self.capabilities = _stream_capabilities(max_frame)
        self.server: asyncio.AbstractServer | None = None
        self._links: dict[str, _Link] = {}
        self._pending: dict[asyncio.StreamWriter, str] = {}  # connections in the hello: their source address
        self._tasks: set[asyncio.Task] = set()
        self._peers_changed = asyncio.Event()
        self._counts: Counter[str] = Counter()
        super().__init__(limits.max_peers * limits.inbox_frames_per_peer)

    @property
    def peers(self) -> list[str]:
        return sorted(self._links)

    async def wait_for_peers(self, count: int, timeout: float) -> None:
        async def enough() -> None:
            while len(self._links) < count:
                self._peers_changed.clear()
                await self._peers_changed.wait()
        await asyncio.wait_for(enough(), timeout)

    COUNTERS = ("connections", "accepted", "hello_failed", "hello_timeouts", "evicted_pending",
                "refused_name_in_use", "refused_full", "closed_idle", "closed_slow_reader",
                "closed_framing", "closed_by_peer", "dropped_frames_of_closed_links")

    def stats(self) -> dict:
        return {**super().stats(), "pending": len(self._pending),
                **{name: self._counts[name] for name in self.COUNTERS},
                "peers": {n: self._links[n].stats() for n in self.peers}}

    async def attach_socket(self, sock: socket.socket) -> None:
        """Serve one already connected stream socket (used for socketpair tests)."""
        reader, writer = await asyncio.open_connection(sock=sock)
        self._spawn(self.handle_connection(reader, writer))

    def _spawn(self, coroutine) -> asyncio.Task:
        task = asyncio.ensure_future(coroutine)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return task

    # -- one connection ------------------------------------------------------------------
    async def handle_connection(self, reader: asyncio.StreamReader,
                                writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        if task is not None:
            self._tasks.add(task)
        link = None
        try:
            self._counts["connections"] += 1
            if self._closed:
                return
            if len(self._pending) >= self.limits.max_pending:
                victim = self._pending_victim()
                del self._pending[victim]
                victim.transport.abort()
                self._counts["evicted_pending"] += 1
            self._pending[writer] = _source(writer)
            try:
                link = await self._hello(reader, writer)
            finally:
                self._pending.pop(writer, None)
            if link is not None:
                await self._read_from(link)
        except asyncio.CancelledError:
            # Only close() cancels this task. asyncio's server calls task.exception() on
            # its connection tasks, which raises (and logs) for a cancelled one.
            pass
        finally:
            if link is not None:
                self._drop(link, None)
            elif not writer.is_closing():  # a refusal is closing gracefully: let it flush
                writer.transport.abort()
            if task is not None:
                self._tasks.discard(task)

    def _pending_victim(self) -> asyncio.StreamWriter:
        """The connection still in the hello to close for a new one: one at random among
        those of the source address holding the most. A flood from one address evicts its
        own connections, never a peer's from another; from the same address (loopback) a
        peer's hello in flight is as likely to go as any of the flood's, not certain to as
        the oldest was (a flood of 16 connections per hello round trip locked peers out)."""
        counts = Counter(self._pending.values())
        most = max(counts.values())
        crowded = {source for source, count in counts.items() if count == most}
        return random.choice([w for w, source in self._pending.items() if source in crowded])

    async def _hello(self, reader: asyncio.StreamReader,
                     writer: asyncio.StreamWriter) -> _Link | None:
        hello = HubHello(self.auth, self.epoch)
        try:
            async with asyncio.timeout(self.limits.hello_timeout):
                writer.write(frame_bytes(hello.challenge))
                await writer.drain()
                peer = hello.check(await _read_hello(reader))
        except TimeoutError:
            self._counts["hello_timeouts"] += 1
            return None
        except (HelloFailed, FramingError, TransportClosed, ConnectionError):
            if writer in self._pending:  # not closed by us to make room
                self._counts["hello_failed"] += 1
            return None
        if self._closed:
            return None
        if peer.name in self._links:
            refusal = f"name {peer.name!r} is already connected"
            self._counts["refused_name_in_use"] += 1
        elif len(self._links) >= self.limits.max_peers:
            refusal = f"the hub has its {self.limits.max_peers} peers"
            self._counts["refused_full"] += 1
        else:
            refusal = None
        if refusal is not None:
            writer.write(frame_bytes(peer.refusal(refusal)))
            writer.close()  # flushes the short refusal, then closes
            return None
        writer.transport.set_write_buffer_limits(high=LINK_BUFFER_BYTES)
        writer.write(frame_bytes(peer.welcome(self.name)))
        link = _Link(peer.name, reader, writer)
        self._links[peer.name] = link
        link.tasks.append(self._spawn(self._write_to(link)))
        self._counts["accepted"] += 1
        self._peers_changed.set()
        return link

    async def _read_from(self, link: _Link) -> None:
        limits = self.limits
        while not link.closed:
            # No timer per frame: the link's writer task watches waiting_since (idle).
            link.waiting_since = time.monotonic()
            try:
                frame = await read_frame(link.reader, self.capabilities.max_frame)
            except FramingError:
                return self._drop(link, "closed_framing")
            except TransportClosed:
                return self._drop(link, "closed_by_peer")
            finally:
                link.waiting_since = None
            if not frame:
                link.tally.keepalives_received += 1
                continue
            link.tally.received += 1
            # This peer's ration of the inbox: when it is used up, stop reading it (TCP
            # flow control then slows the sender down) until recv takes its frames.
            while link.inbox_frames >= limits.inbox_frames_per_peer or (
                    link.inbox_frames and link.inbox_bytes + len(frame) > limits.inbox_bytes_per_peer):
                link.inbox_room.clear()
                await link.inbox_room.wait()
                if link.closed or self._closed:
                    return
            link.inbox_frames += 1
            link.inbox_bytes += len(frame)
            self.deliver(link.name, frame, link.taken)

    async def _write_to(self, link: _Link) -> None:
        """Move the link's queued frames to its socket when the socket has room; send
        keepalives when idle; drop the link when its socket accepts nothing, or when
        nothing came from the peer for idle_timeout while the hub was reading it."""
        limits = self.limits
        writer = link.writer
        try:
            while not link.closed:
                waiting = link.waiting_since
                if waiting is not None and time.monotonic() - waiting >= limits.idle_timeout:
                    self._drop(link, "closed_idle")
                    return
                if not link.queue:
                    link.wake.clear()
                    wait = link.last_sent + limits.keepalive_interval - time.monotonic()
                    if waiting is not None:
                        wait = min(wait, waiting + limits.idle_timeout - time.monotonic())
                    if wait > 0:
                        try:
                            async with asyncio.timeout(wait):
                                await link.wake.wait()
                        except TimeoutError:
                            pass
                    if not link.queue:
                        if time.monotonic() - link.last_sent >= limits.keepalive_interval:
                            if writer.transport.get_write_buffer_size() == 0:
                                writer.write(KEEPALIVE)
                                link.tally.keepalives_sent += 1
                            link.last_sent = time.monotonic()
                        continue
                try:
                    async with asyncio.timeout(limits.write_timeout):
                        await writer.drain()
                except TimeoutError:
                    self._drop(link, "closed_slow_reader")
                    return
                if link.closed:
                    return
                batch = list(link.queue)
                link.queue.clear()
                link.queued_bytes = 0
                writer.write(b"".join(frame_bytes(frame) for frame in batch))
                link.tally.sent += len(batch)
                link.last_sent = time.monotonic()
        except ConnectionError:
            self._drop(link, "closed_by_peer")

    def _enqueue(self, link: _Link, frame: bytes) -> None:
        if link.closed or link.writer.is_closing():
            return  # its reader notices the end of the stream and drops the link
        if not link.queue and link.writer.transport.get_write_buffer_size() < LINK_BUFFER_BYTES:
            link.writer.write(frame_bytes(frame))  # the socket has room: no queueing
            link.tally.sent += 1
            link.last_sent = time.monotonic()
            return
        link.queue.append(frame)
        link.queued_bytes += len(frame)
        limits = self.limits
        while len(link.queue) > 1 and (len(link.queue) > limits.send_queue_frames
                                       or link.queued_bytes > limits.send_queue_bytes):
            dropped = link.queue.popleft()
            link.queued_bytes -= len(dropped)
            link.tally.dropped += 1
        link.wake.set()

    def _drop(self, link: _Link, reason: str | None) -> None:
        if link.closed:
            return
        link.closed = True
        if reason is not None:
            self._counts[reason] += 1
        self._counts["dropped_frames_of_closed_links"] += link.tally.dropped
        if self._links.get(link.name) is link:
            del self._links[link.name]
            self._peers_changed.set()
        link.writer.transport.abort()
        link.inbox_room.set()
        current = asyncio.current_task()
        for task in link.tasks:
            if task is not current:
                task.cancel()

    async def send(self, frame: bytes, to: str | None = None) -> None:
        """Hand ``frame`` to each target's queue; never waits for a slow peer."""
        self.ensure_open()
        self.check_frame(frame)
        if to is None:
            links = list(self._links.values())
        elif to in self._links:
            links = [self._links[to]]
        else:
            raise UnknownPeer(f"no connected peer named {to!r}")
        frame = bytes(frame)
        for link in links:
            self._enqueue(link, frame)

    async def close(self) -> None:
        if not self.mark_closed():
            return
        if self.server is not None:
            self.server.close()
        for link in list(self._links.values()):
            self._drop(link, None)
        for writer in list(self._pending):
            writer.transport.abort()
        self._pending.clear()
        current = asyncio.current_task()
        tasks = [task for task in self._tasks if task is not current]
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
