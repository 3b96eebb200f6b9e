"""Length-prefixed frames over a byte stream (TCP or Bluetooth RFCOMM).

Each frame is a 4-byte big-endian length and the bytes. The length is checked against the
limit before the body is read. On connect both ends first send a hello frame holding their
name, which becomes the peer name used for addressing (a routing label only: authenticity
comes from the envelope).
"""
from __future__ import annotations

import asyncio
import socket
import struct

from nonholo.comm.transports.base import (
    DEFAULT_MAX_FRAME, Capabilities, FramingError, InboxTransport, Transport, TransportClosed, UnknownPeer,
)

LENGTH = struct.Struct(">I")
MAX_NAME_BYTES = 255
HELLO_TIMEOUT_S = 5.0


def frame_bytes(payload: bytes) -> bytes:
    return LENGTH.pack(len(payload)) + payload


async def read_frame(reader: asyncio.StreamReader, max_frame: int) -> bytes:
    """Next frame; FramingError on a bad length, TransportClosed at end of stream."""
    try:
        (length,) = LENGTH.unpack(await reader.readexactly(LENGTH.size))
        if not 0 < length <= max_frame:
            raise FramingError(f"frame length {length} outside 1..{max_frame}")
        return await reader.readexactly(length)
    except (asyncio.IncompleteReadError, ConnectionError) as exc:
        raise TransportClosed("stream ended") from exc


async def _exchange_hello(name: str, reader: asyncio.StreamReader,
                          writer: asyncio.StreamWriter) -> str:
    writer.write(frame_bytes(name.encode("utf-8")))
    await writer.drain()
    raw = await asyncio.wait_for(read_frame(reader, MAX_NAME_BYTES), HELLO_TIMEOUT_S)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        raise FramingError("peer name is not UTF-8") from None


def _check_name(name: str) -> None:
    if not 0 < len(name.encode("utf-8")) <= MAX_NAME_BYTES:
        raise ValueError(f"endpoint name must be 1..{MAX_NAME_BYTES} UTF-8 bytes")


def _stream_capabilities(max_frame: int) -> Capabilities:
    # A star over unicast streams: "send to all" writes one copy per peer.
    return Capabilities(reliable=True, ordered=True, broadcast=False, max_frame=max_frame)


class StreamClient(Transport):
    """One connection to a server (the follower side of the star)."""

    def __init__(self, name: str, peer: str, reader: asyncio.StreamReader,
                 writer: asyncio.StreamWriter, max_frame: int) -> None:
        self.name = name
        self.peer = peer
        self.capabilities = _stream_capabilities(max_frame)
        self._reader = reader
        self._writer = writer

    @classmethod
    async def handshake(cls, name: str, reader: asyncio.StreamReader,
                        writer: asyncio.StreamWriter,
                        max_frame: int = DEFAULT_MAX_FRAME) -> "StreamClient":
        _check_name(name)
        try:
            peer = await _exchange_hello(name, reader, writer)
        except BaseException:
            writer.close()
            raise
        return cls(name, peer, reader, writer, max_frame)

    @classmethod
    async def over_socket(cls, name: str, sock: socket.socket,
                          max_frame: int = DEFAULT_MAX_FRAME) -> "StreamClient":
        """Client over an already connected stream socket (RFCOMM, socketpair)."""
        reader, writer = await asyncio.open_connection(sock=sock)
        return await cls.handshake(name, reader, writer, max_frame)

    async def send(self, frame: bytes, to: str | None = None) -> None:
        if to is not None and to != self.peer:
            raise UnknownPeer(f"{self.name} is connected only to {self.peer!r}")
        self.check_frame(frame)
        if self._writer.is_closing():
            raise TransportClosed(f"{self.name} is closed")
        self._writer.write(frame_bytes(frame))
        try:
            await self._writer.drain()
        except ConnectionError as exc:
            raise TransportClosed("connection lost") from exc

    async def recv(self) -> tuple[str, bytes]:
        if self._writer.is_closing():
            raise TransportClosed(f"{self.name} is closed")
        return self.peer, await read_frame(self._reader, self.capabilities.max_frame)

    async def close(self) -> None:
        if not self._writer.is_closing():
            self._writer.close()
        try:
            await self._writer.wait_closed()
        except ConnectionError:
            pass


class StreamServer(InboxTransport):
    """The hub of the star (the leader, like a piconet master). Accepts connections from
    an ``asyncio.Server`` or from ``attach_socket``; frames from all peers are merged."""

    def __init__(self, name: str, max_frame: int = DEFAULT_MAX_FRAME) -> None:
        _check_name(name)
        self.name = name
        self.capabilities = _stream_capabilities(max_frame)
        self.server: asyncio.AbstractServer | None = None
        self._writers: dict[str, asyncio.StreamWriter] = {}
        self._tasks: set[asyncio.Task] = set()
        self._peers_changed = asyncio.Event()
        super().__init__()

    @property
    def peers(self) -> list[str]:
        return sorted(self._writers)

    async def wait_for_peers(self, count: int, timeout: float) -> None:
        async def enough() -> None:
            while len(self._writers) < count:
                self._peers_changed.clear()
                await self._peers_changed.wait()
        await asyncio.wait_for(enough(), timeout)

    async def attach_socket(self, sock: socket.socket) -> None:
        """Serve one already connected stream socket (used for socketpair tests)."""
        reader, writer = await asyncio.open_connection(sock=sock)
        self._spawn(self.handle_connection(reader, writer))

    def _spawn(self, coroutine) -> None:
        task = asyncio.ensure_future(coroutine)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def handle_connection(self, reader: asyncio.StreamReader,
                                writer: asyncio.StreamWriter) -> None:
        peer = None
        try:
            peer = await _exchange_hello(self.name, reader, writer)
            previous = self._writers.pop(peer, None)
            if previous is not None:  # a reconnecting peer replaces its old link
                previous.close()
            self._writers[peer] = writer
            self._peers_changed.set()
            while True:
                frame = await read_frame(reader, self.capabilities.max_frame)
                self.inbox.put_nowait((peer, frame))
        except (TransportClosed, FramingError, asyncio.TimeoutError, ConnectionError):
            pass
        finally:
            if peer is not None and self._writers.get(peer) is writer:
                del self._writers[peer]
                self._peers_changed.set()
            writer.close()

    async def send(self, frame: bytes, to: str | None = None) -> None:
        self.ensure_open()
        self.check_frame(frame)
        if to is None:
            writers = list(self._writers.values())
        elif to in self._writers:
            writers = [self._writers[to]]
        else:
            raise UnknownPeer(f"no connected peer named {to!r}")
        data = frame_bytes(frame)
        for writer in writers:
            writer.write(data)
        for writer in writers:
            try:
                await writer.drain()
            except ConnectionError:
                pass  # its reader task notices and drops the peer

    async def close(self) -> None:
        if not self.mark_closed():
            return
        if self.server is not None:
            self.server.close()
        for writer in self._writers.values():
            writer.close()
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
