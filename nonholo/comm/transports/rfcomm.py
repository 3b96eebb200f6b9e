"""Bluetooth RFCOMM star (the thesis' piconet: one master, at most 7 active slaves).

RFCOMM is a byte stream like TCP, so the same length-prefixed framing, authenticated
hello and limits (``nonholo.comm.transports.stream``) are reused unchanged; only socket
creation differs.
Needs a CPython built with BlueZ headers and a kernel with the Bluetooth family.
"""
from __future__ import annotations

import asyncio
import errno
import socket

from nonholo.comm.transports.base import DEFAULT_MAX_FRAME
from nonholo.comm.transports.hello import LinkAuth
from nonholo.comm.transports.stream import StreamClient, StreamLimits, StreamServer

PICONET_ACTIVE_SLAVES = 7
# A piconet has at most 7 active slaves; the hello of a few more may be under way.
PICONET_LIMITS = StreamLimits(max_peers=PICONET_ACTIVE_SLAVES, max_pending=4)


def bluetooth_available() -> bool:
    """True if an RFCOMM socket can be created here (family compiled in and in the kernel)."""
    if not hasattr(socket, "AF_BLUETOOTH"):
        return False
    try:
        socket.socket(socket.AF_BLUETOOTH, socket.SOCK_STREAM, socket.BTPROTO_RFCOMM).close()
    except OSError as exc:
        if exc.errno in (errno.EAFNOSUPPORT, errno.EPROTONOSUPPORT, errno.EPERM):
            return False
        raise
    return True


def _rfcomm_socket() -> socket.socket:
    if not hasattr(socket, "AF_BLUETOOTH"):
        raise OSError(errno.EAFNOSUPPORT, "this Python has no socket.AF_BLUETOOTH")
    sock = socket.socket(socket.AF_BLUETOOTH, socket.SOCK_STREAM, socket.BTPROTO_RFCOMM)
    sock.setblocking(False)
    return sock


async def serve_rfcomm(name: str, bdaddr: str, channel: int,
                       max_frame: int = DEFAULT_MAX_FRAME, *, auth: LinkAuth,
                       limits: StreamLimits = PICONET_LIMITS) -> StreamServer:
    sock = _rfcomm_socket()
    sock.bind((bdaddr, channel))
    sock.listen(PICONET_ACTIVE_SLAVES)
    hub = StreamServer(name, max_frame, auth=auth, limits=limits)
    hub.server = await asyncio.start_server(hub.handle_connection, sock=sock)
    return hub


async def connect_rfcomm(name: str, bdaddr: str, channel: int, *, auth: LinkAuth,
                         timeout: float = 10.0, max_frame: int = DEFAULT_MAX_FRAME,
                         limits: StreamLimits = PICONET_LIMITS) -> StreamClient:
    sock = _rfcomm_socket()
    try:
        await asyncio.wait_for(asyncio.get_running_loop().sock_connect(sock, (bdaddr, channel)),
                               timeout)
    except BaseException:
        sock.close()
        raise
    return await StreamClient.over_socket(name, sock, max_frame, auth=auth, limits=limits)
