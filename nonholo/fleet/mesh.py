"""A robot's authenticated links to its parents and children over TCP (the thesis's
piconet: a robot with followers is the master its followers connect to).

``RobotLinks`` is one ``Transport`` addressed by robot name: a robot with children serves a
``StreamServer`` hub that only its children's keys open (each child's name bound to its key
id); for each parent it keeps a ``StreamClient`` and reconnects it when it drops, with
exponential backoff and jitter (spec comm.md §3.5); the program sees a parent's new boot by
the epoch of its envelopes, resubscribes and drops states of the previous boot. Frames from every link meet in one bounded inbox
(latest-value: the oldest is dropped and counted beyond it).
"""
from __future__ import annotations

import asyncio
import random
import socket
from dataclasses import dataclass

from nonholo.comm.transports.base import Capabilities, DEFAULT_MAX_FRAME, InboxTransport, TransportClosed
from nonholo.comm.transports.hello import HelloFailed, LinkAuth
from nonholo.comm.transports.stream import StreamClient
from nonholo.comm.transports.tcp import connect_tcp, serve_tcp, tcp_port
from nonholo.errors import NonholoInputError

BACKOFF_FIRST_S = 0.02
BACKOFF_MAX_S = 0.5
CONNECT_TIMEOUT_S = 2.0
INBOX_FRAMES = 1024


def split_address(text: str, what: str) -> tuple[str, int]:
    """``host:port`` (IPv6 as ``[::1]:port``) → (host, port); NonholoInputError naming ``what``."""
    host, sep, port = text.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise NonholoInputError(f"{what}: expected host:port, got {text[:80]!r}")
    return host, int(port)


@dataclass
class Backoff:
    """Delays between reconnection attempts: doubling from ``first`` up to ``most``, each
    multiplied by a random factor in [0.5, 1.5) so that restarted peers do not retry in step."""

    first: float = BACKOFF_FIRST_S
    most: float = BACKOFF_MAX_S
    attempt: int = 0

    def next(self, rng: random.Random) -> float:
        delay = min(self.most, self.first * 2 ** self.attempt) * (0.5 + rng.random())
        self.attempt = min(self.attempt + 1, 30)
        return delay

    def reset(self) -> None:
        self.attempt = 0


class RobotLinks(InboxTransport):
    """Links of robot ``name``: ``keys`` {robot: (key id, secret)} of itself and its peers;
    ``listen`` (host, port) or a listening socket when it has children (then only the
    names of ``children`` may connect, each with its own key); ``parents`` {parent: (host, port)}."""

    def __init__(self, name: str, keys: dict, children: tuple[str, ...], parents: dict,
                 listen: tuple[str, int] | socket.socket | None) -> None:
        self.name = name
        self.capabilities = Capabilities(reliable=True, ordered=True, broadcast=False, max_frame=DEFAULT_MAX_FRAME)
        super().__init__(INBOX_FRAMES)
        self._keys, self._children, self._parents, self._listen = keys, children, parents, listen
        self.hub = None
        self.clients: dict[str, StreamClient] = {}
        self.reconnects = {p: 0 for p in parents}
        self.unsent = 0          # frames for a peer not connected at that moment
        self._tasks: list[asyncio.Task] = []
        self._rng = random.Random()

    async def start(self) -> int | None:
        """Listen (if it has children) and start connecting to the parents; the port listened on."""
        port = None
        if self._children and self._listen is not None:
            kid = {c: self._keys[c][0] for c in self._children}
            auth = LinkAuth({self._keys[c][0]: self._keys[c][1] for c in self._children}, peer_key_ids=kid)
            if isinstance(self._listen, socket.socket):
                self.hub = await serve_tcp(self.name, auth=auth, sock=self._listen)
            else:
                self.hub = await serve_tcp(self.name, *self._listen, auth=auth)
            port = tcp_port(self.hub)
            self._tasks.append(asyncio.ensure_future(self._pump_hub()))
        for parent, address in self._parents.items():
            self._tasks.append(asyncio.ensure_future(self._keep_linked(parent, address)))
        return port

    async def _pump_hub(self) -> None:
        try:
            while True:
                peer, frame, arrived = await self.hub.recv_stamped()
                self.deliver(peer, frame, arrived=arrived)
        except TransportClosed:
            return

    async def _keep_linked(self, parent: str, address: tuple[str, int]) -> None:
        own_id, own_secret = self._keys[self.name]
        auth = LinkAuth({own_id: own_secret}, key_id=own_id)
        backoff = Backoff()
        while not self._closed:
            try:
                client = await connect_tcp(self.name, *address, auth=auth, timeout=CONNECT_TIMEOUT_S)
            except (OSError, HelloFailed, asyncio.TimeoutError):
                await asyncio.sleep(backoff.next(self._rng))
                continue
            if client.peer != parent:   # a hub that is not this parent (wrong address)
                await client.close()
                await asyncio.sleep(backoff.next(self._rng))
                continue
            backoff.reset()
            self.clients[parent] = client
            try:
                while True:
                    peer, frame = await client.recv()
                    self.deliver(peer, frame)
            except TransportClosed:
                pass
            finally:
                if self.clients.get(parent) is client:
                    del self.clients[parent]
                await client.close()
            self.reconnects[parent] += 1
            await asyncio.sleep(backoff.next(self._rng))

    async def send(self, frame: bytes, to: str | None = None) -> None:
        self.ensure_open()
        client = self.clients.get(to)
        try:
            if client is not None:
                await client.send(frame)
            elif self.hub is not None and to in self.hub.peers:
                await self.hub.send(frame, to=to)
            else:
                self.unsent += 1
        except TransportClosed:
            self.unsent += 1

    def add_parent(self, parent: str, address: tuple[str, int]) -> None:
        """Link (and keep linked) to a new parent, as at the start."""
        if parent not in self._parents:
            self._parents[parent] = address
            self.reconnects[parent] = 0
            self._tasks.append(asyncio.ensure_future(self._keep_linked(parent, address)))

    def stats(self) -> dict:
        return {**super().stats(), "unsent": self.unsent, "reconnects": dict(self.reconnects),
                "hub": self.hub.stats() if self.hub is not None else None}

    async def close(self) -> None:
        if not self.mark_closed():
            return
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        for client in list(self.clients.values()):
            await client.close()
        if self.hub is not None:
            await self.hub.close()
