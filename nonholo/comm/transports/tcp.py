"""asyncio TCP star: the leader serves, followers connect. The default transport.

Both ends need link keys (``hello.LinkAuth``): a connection that cannot prove a key the
hub knows learns nothing and is closed (see ``transports.stream`` for every limit)."""
from __future__ import annotations

import asyncio
import socket

from nonholo.comm.transports.base import DEFAULT_MAX_FRAME
from nonholo.comm.transports.hello import LinkAuth
from nonholo.comm.transports.stream import DEFAULT_LIMITS, StreamClient, StreamLimits, StreamServer


async def serve_tcp(name: str, host: str = "127.0.0.1", port: int = 0,
                    max_frame: int = DEFAULT_MAX_FRAME, *, auth: LinkAuth,
                    limits: StreamLimits = DEFAULT_LIMITS,
                    sock: socket.socket | None = None) -> StreamServer:
    """Listen on ``host:port`` (port 0 picks a free one: read ``tcp_port(server)``), or
    on ``sock``, a listening socket made by someone else (``host`` and ``port`` unused)."""
    hub = StreamServer(name, max_frame, auth=auth, limits=limits)
    # The kernel's accept queue is bounded too: beyond it the kernel refuses connections.
    where = {"sock": sock} if sock is not None else {"host": host, "port": port}
    hub.server = await asyncio.start_server(hub.handle_connection, **where,
                                            backlog=limits.max_peers + limits.max_pending)
    return hub


def tcp_port(hub: StreamServer) -> int:
    assert hub.server is not None
    return hub.server.sockets[0].getsockname()[1]


async def connect_tcp(name: str, host: str, port: int, *, auth: LinkAuth, timeout: float = 5.0,
                      max_frame: int = DEFAULT_MAX_FRAME,
                      limits: StreamLimits = DEFAULT_LIMITS) -> StreamClient:
    """Connect and run the authenticated hello; HelloFailed/HelloRefused if it fails."""
    # asyncio enables TCP_NODELAY on its sockets, so small frames are not delayed.
    reader, writer = await asyncio.wait_for(asyncio.open_connection(host, port), timeout)
    return await StreamClient.handshake(name, reader, writer, max_frame, auth=auth, limits=limits)
