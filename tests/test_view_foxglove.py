"""nonholo fleet --foxglove: the live feed on a Foxglove WebSocket server (foxglove-sdk), read
with a plain WebSocket client speaking the Foxglove protocol."""
import asyncio
import json
import struct
import time

import pytest

pytest.importorskip("foxglove", reason="the foxglove extra (foxglove-sdk) is not installed")
aiohttp = pytest.importorskip("aiohttp", reason="the view extra (aiohttp) is not installed")

from nonholo.view.feed import LatestFeed  # noqa: E402
from nonholo.view.foxglove_live import FoxgloveBridge  # noqa: E402

WAIT_S = 10.0


def snapshot(t: float, x: float) -> dict:
    return {"t": t, "robots": {"leader": {"x": x, "y": 2.0, "theta": 0.3}, "f1": {"x": x - 2, "y": 1.0, "theta": 0.3}},
            "links": {"leader->f1": {"e1": 0.1, "e2": -0.05}}, "states": {"leader": "running", "f1": "running"}}


def test_foxglove_clients_see_the_fleet():
    feed = LatestFeed()
    bridge = FoxgloveBridge(feed, 0).start()
    try:
        feed.publish(snapshot(1.0, 1.0))

        async def watch():
            url = f"ws://127.0.0.1:{bridge.port}"
            async with aiohttp.ClientSession() as session:
                async with session.ws_connect(url, protocols=("foxglove.sdk.v1",)) as ws:
                    channels, deadline = {}, time.monotonic() + WAIT_S
                    while "/robots/f1/pose" not in channels and time.monotonic() < deadline:
                        message = json.loads((await ws.receive(timeout=WAIT_S)).data)
                        if message["op"] == "advertise":
                            channels.update({c["topic"]: c for c in message["channels"]})
                    assert channels["/tf"]["schemaName"] == "foxglove.FrameTransform"
                    assert channels["/robots/leader/pose"]["schemaName"] == "foxglove.PoseInFrame"
                    await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": [
                        {"id": 7, "channelId": channels["/robots/leader/pose"]["id"]}]}))
                    await asyncio.sleep(0.2)
                    feed.publish(snapshot(2.5, 4.0))
                    while time.monotonic() < deadline:
                        message = await ws.receive(timeout=WAIT_S)
                        if message.type == aiohttp.WSMsgType.BINARY and message.data[0] == 1:
                            subscription, log_time = struct.unpack_from("<IQ", message.data, 1)
                            return subscription, log_time, json.loads(message.data[13:])
            raise AssertionError("no message from the Foxglove server")

        subscription, log_time, pose = asyncio.run(watch())
        assert subscription == 7 and log_time == 2_500_000_000
        assert pose["pose"]["position"]["x"] == 4.0 and pose["frame_id"] == "world"
        assert pose["timestamp"] == {"sec": 2, "nsec": 500_000_000}
    finally:
        bridge.stop()
    assert bridge.logged >= 2


def _official(value, schema: dict):
    """``value`` (a recorded JSON message) built as the foxglove-sdk's message of the same
    name, field by field: an unknown or misnamed field is a TypeError."""
    from foxglove import messages

    title = schema.get("title", "")
    if title in ("time", "duration"):
        return (messages.Timestamp if title == "time" else messages.Duration)(**value)
    if schema.get("type") == "object" and title.startswith("foxglove."):
        kind = getattr(messages, title.split(".", 1)[1])
        fields = {}
        for key, item in value.items():
            sub = schema["properties"][key]
            if key == "type" and kind is messages.LinePrimitive:
                item = [t for t in (messages.LinePrimitiveLineType.LineStrip, messages.LinePrimitiveLineType.LineLoop,
                                    messages.LinePrimitiveLineType.LineList) if t.value == item][0]
            elif sub.get("type") == "array":
                item = [_official(v, sub["items"]) for v in item]
            elif sub.get("type") == "object":
                item = _official(item, sub)
            fields[key] = item
        return kind(**fields)
    return value


def test_recorded_messages_are_foxglove_messages(tmp_path):
    """Every message on a foxglove.* channel of a recording builds the official message."""
    from mcap.reader import make_reader

    from nonholo.sim.simulator import simulate
    from nonholo.view.data import from_result
    from nonholo.view.record import write_recording
    from view_fleets import chain

    _, scenario = chain(tmp_path, duration=1.0)
    path = write_recording(from_result(simulate(scenario, progress=False), every=5), tmp_path / "run.mcap")
    seen = set()
    with open(path, "rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            if schema.name.startswith("foxglove."):
                built = _official(json.loads(message.data), json.loads(schema.data))
                assert type(built).__name__ == schema.name.split(".")[1]
                assert len(built.encode()) > 0
                seen.add(schema.name)
    assert seen == {"foxglove.PoseInFrame", "foxglove.FrameTransform", "foxglove.SceneUpdate"}
