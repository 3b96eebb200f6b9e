"""A live fleet for Foxglove: the feed's snapshots on a Foxglove WebSocket server
(``nonholo fleet --foxglove``; needs ``pip install 'nonholo[foxglove]'``, the foxglove-sdk).

Foxglove connects to ``ws://127.0.0.1:PORT`` and shows, without configuration, ``/tf``
(``foxglove.FrameTransform``, a frame per robot) and ``/robots/NAME/pose``
(``foxglove.PoseInFrame``), plus ``/links`` (per link its errors and frame counts) and
``/states``. The Foxglove protocol has no token: the server binds loopback only.
"""
from __future__ import annotations

import threading

from nonholo.view import require
from nonholo.view.record import FRAME_TRANSFORM, LINKS, POSE_IN_FRAME, frame_transform, pose_in_frame

HOST = "127.0.0.1"
RATE_HZ = 20.0
STOP_TIMEOUT_S = 5.0
STATES = {"title": "nonholo.States", "type": "object", "properties": {"states": {"type": "object"}},
          "description": "Per robot program its state (starting, running, done or its watchdog's)"}


class FoxgloveBridge:
    """Logs the newest snapshot of ``feed`` (``LatestFeed``) to a Foxglove WebSocket server,
    at most ``RATE_HZ`` times a second, from a thread of its own; ``start()``, ``stop()``."""

    def __init__(self, feed, port: int = 8765) -> None:
        require("foxglove", "foxglove")
        self.feed, self.port = feed, port
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._server = None
        self._channels: dict = {}
        self.logged = 0

    def start(self) -> "FoxgloveBridge":
        import foxglove

        self._context = foxglove.Context()
        self._server = foxglove.start_server(name="nonholo", host=HOST, port=self.port, context=self._context)
        self.port = self._server.port
        self._thread = threading.Thread(target=self._run, name="nonholo-foxglove", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(STOP_TIMEOUT_S)
        if self._server is not None:
            self._server.stop()
            self._server = None

    def _channel(self, topic: str, schema: dict):
        import foxglove

        if topic not in self._channels:
            self._channels[topic] = foxglove.Channel(topic, schema=schema, context=self._context)
        return self._channels[topic]

    def _run(self) -> None:
        import json

        sent = -1
        while not self._stop.wait(1.0 / RATE_HZ):
            version, text = self.feed.latest()
            if version == sent or text is None:
                continue
            sent = version
            self.log(json.loads(text))

    def log(self, snapshot: dict) -> None:
        """Log one snapshot (its simulation time as the log time)."""
        ns = int(round(snapshot["t"] * 1e9))
        tf = self._channel("/tf", FRAME_TRANSFORM)
        for name, robot in snapshot["robots"].items():
            x, y, theta = robot["x"], robot["y"], robot["theta"]
            tf.log(frame_transform(ns, name, x, y, theta), log_time=ns)
            self._channel(f"/robots/{name}/pose", POSE_IN_FRAME).log(pose_in_frame(ns, x, y, theta), log_time=ns)
        stamp = {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}
        self._channel("/links", LINKS).log({"timestamp": stamp, "links": snapshot["links"]}, log_time=ns)
        self._channel("/states", STATES).log({"states": snapshot["states"]}, log_time=ns)
        self.logged += 1
