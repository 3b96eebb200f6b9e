"""Zenoh transport (optional extra ``nonholo[zenoh]``).

Peer mode, multicast scouting off, explicit endpoints: nothing leaves the configured
interfaces. Key space per fleet: ``nonholo/<fleet>/all`` (broadcast, one publication
reaches every follower) and ``nonholo/<fleet>/to/<name>`` (directed messages). The sender
name travels as the sample attachment.
"""
from __future__ import annotations

import asyncio
import threading
import time

import zenoh

from nonholo.comm.transports.base import (
    DEFAULT_INBOX_FRAMES, DEFAULT_MAX_FRAME, Capabilities, InboxTransport,
)



def peer_config(listen: list[str], connect: list[str]) -> zenoh.Config:
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", _json_list(listen))
    config.insert_json5("connect/endpoints", _json_list(connect))
    return config


def _json_list(items: list[str]) -> str:
    return "[" + ",".join(f'"{item}"' for item in items) + "]"


class ZenohTransport(InboxTransport):
    def __init__(self, name: str, fleet: str, config: zenoh.Config,
                 max_frame: int = DEFAULT_MAX_FRAME,
                 inbox_frames: int = DEFAULT_INBOX_FRAMES) -> None:
        self.name = name
        self.capabilities = Capabilities(reliable=True, ordered=True, broadcast=True,
                                         max_frame=max_frame)
        self._prefix = f"nonholo/{fleet}"
        self._loop = asyncio.get_running_loop()
        self._hop_lock = threading.Lock()
        self._in_flight = 0
        self._hop_dropped = 0  # oversized, or over the bound before reaching the loop
        super().__init__(inbox_frames)
        self._session = zenoh.open(config)
        self._subscribers = [
            self._session.declare_subscriber(f"{self._prefix}/all", self._on_sample),
            self._session.declare_subscriber(f"{self._prefix}/to/{name}", self._on_sample),
        ]
        # BLOCK (not the default DROP) so commands and states are never silently dropped;
        # express skips the batching delay.
        self._publishers: dict[str, zenoh.Publisher] = {}

    def _publisher(self, key: str) -> "zenoh.Publisher":
        if key not in self._publishers:
            self._publishers[key] = self._session.declare_publisher(
                key, congestion_control=zenoh.CongestionControl.BLOCK, express=True)
        return self._publishers[key]

    def _on_sample(self, sample: "zenoh.Sample") -> None:  # runs on a Zenoh thread
        arrived = time.monotonic()
        sender = sample.attachment.to_bytes().decode("utf-8", "replace") if sample.attachment else "?"
        if sender == self.name:
            return
        payload = sample.payload.to_bytes()
        with self._hop_lock:
            # Frames on their way to the event loop are bounded like the inbox itself:
            # a flood that outpaces the loop is dropped here, counted, not queued.
            if not 0 < len(payload) <= self.capabilities.max_frame \
                    or self._in_flight >= self.inbox.maxsize:
                self._hop_dropped += 1
                return
            self._in_flight += 1
        self._loop.call_soon_threadsafe(self._arrived, sender, payload, arrived)

    def _arrived(self, sender: str, payload: bytes, arrived: float) -> None:  # on the event loop
        with self._hop_lock:
            self._in_flight -= 1
        self.deliver(sender, payload, arrived=arrived)

    def stats(self) -> dict:
        with self._hop_lock:
            hop_dropped = self._hop_dropped
        return {**super().stats(), "arrival_dropped": hop_dropped}

    async def send(self, frame: bytes, to: str | None = None) -> None:
        self.ensure_open()
        self.check_frame(frame)
        key = f"{self._prefix}/all" if to is None else f"{self._prefix}/to/{to}"
        self._publisher(key).put(frame, attachment=self.name.encode("utf-8"))

    async def close(self) -> None:
        if not self.mark_closed():
            return
        for entity in [*self._publishers.values(), *self._subscribers]:
            entity.undeclare()
        self._session.close()
