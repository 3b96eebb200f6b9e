"""In-process transport: asyncio queues, deterministic order, no sockets. For simulation
and tests: broadcast visits peers in name order, so runs repeat exactly. Each inbox holds
at most ``inbox_frames`` frames; beyond that the oldest is dropped and counted."""
from __future__ import annotations

from nonholo.comm.transports.base import (
    DEFAULT_INBOX_FRAMES, DEFAULT_MAX_FRAME, Capabilities, InboxTransport, UnknownPeer,
)


class InProcNetwork:
    """A hub of named endpoints living in one event loop."""

    def __init__(self, max_frame: int = DEFAULT_MAX_FRAME,
                 inbox_frames: int = DEFAULT_INBOX_FRAMES) -> None:
        self.max_frame = max_frame
        self.inbox_frames = inbox_frames
        self._endpoints: dict[str, InProcTransport] = {}

    def endpoint(self, name: str) -> "InProcTransport":
        if name in self._endpoints:
            raise ValueError(f"endpoint {name!r} already exists")
        endpoint = InProcTransport(self, name)
        self._endpoints[name] = endpoint
        return endpoint

    def deliver(self, sender: str, frame: bytes, to: str | None) -> None:
        if to is None:
            targets = [self._endpoints[n] for n in sorted(self._endpoints) if n != sender]
        elif to in self._endpoints:
            targets = [self._endpoints[to]]
        else:
            raise UnknownPeer(f"no endpoint named {to!r}")
        for target in targets:
            target.deliver(sender, frame)

    def remove(self, name: str) -> None:
        self._endpoints.pop(name, None)


class InProcTransport(InboxTransport):
    def __init__(self, network: InProcNetwork, name: str) -> None:
        self.name = name
        self.capabilities = Capabilities(reliable=True, ordered=True, broadcast=True,
                                         max_frame=network.max_frame)
        super().__init__(network.inbox_frames)
        self._network = network

    async def send(self, frame: bytes, to: str | None = None) -> None:
        self.ensure_open()
        self.check_frame(frame)
        self._network.deliver(self.name, bytes(frame), to)

    async def close(self) -> None:
        if self.mark_closed():
            self._network.remove(self.name)
