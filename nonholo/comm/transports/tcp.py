"""asyncio TCP star: the leader serves, followers connect. The default transport."""
from __future__ import annotations

import asyncio

from nonholo.comm.transports.base import DEFAULT_MAX_FRAME
from nonholo.comm.transports.stream import StreamClient, StreamServer


async def serve_tcp(name: str, host: str = "127.0.0.1", port: int = 0,
                    max_frame: int = DEFAULT_MAX_FRAME) -> StreamServer:
    """Listen on ``host:port`` (port 0 picks a free one: read ``tcp_port(server)``)."""
    hub = StreamServer(name, max_frame)
    hub.server = await asyncio.start_server(hub.handle_connection, host, port)
    return hub


def tcp_port(hub: StreamServer) -> int:
    assert hub.server is not None
    return hub.server.sockets[0].getsockname()[1]


async def connect_tcp(name: str, host: str, port: int, *, timeout: float = 5.0,
                      max_frame: int = DEFAULT_MAX_FRAME) -> StreamClient:
    # asyncio enables TCP_NODELAY on its sockets, so small frames are not delayed.
    reader, writer = await asyncio.wait_for(asyncio.open_connection(host, port), timeout)
    return await StreamClient.handshake(name, reader, writer, max_frame)
