"""Bluetooth RFCOMM star (the thesis' piconet: one master, at most 7 active slaves).

RFCOMM is a byte stream like TCP, so the same length-prefixed framing
(``nonholo.comm.transports.stream``) is reused unchanged; only socket creation differs.
Needs a CPython built with BlueZ headers and a kernel with the Bluetooth family.
"""
from __future__ import annotations

import asyncio
import errno
import socket

from nonholo.comm.transports.base import DEFAULT_MAX_FRAME
from nonholo.comm.transports.stream import StreamClient, StreamServer

PICONET_ACTIVE_SLAVES = 7


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
                       max_frame: int = DEFAULT_MAX_FRAME) -> StreamServer:
    sock = _rfcomm_socket()
    sock.bind((bdaddr, channel))
    sock.listen(PICONET_ACTIVE_SLAVES)
    hub = StreamServer(name, max_frame)
    hub.server = await asyncio.start_server(hub.handle_connection, sock=sock)
    return hub


async def connect_rfcomm(name: str, bdaddr: str, channel: int, *, timeout: float = 10.0,
                         max_frame: int = DEFAULT_MAX_FRAME) -> StreamClient:
    sock = _rfcomm_socket()
    try:
        await asyncio.wait_for(asyncio.get_running_loop().sock_connect(sock, (bdaddr, channel)),
                               timeout)
    except BaseException:
        sock.close()
        raise
    return await StreamClient.over_socket(name, sock, max_frame)
