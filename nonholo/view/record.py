"""MCAP recordings of a run (``--record FILE.mcap``) and reading them back.

Written with the ``mcap`` library (the format's reference implementation, maintained by its
authors), every message JSON with a JSON schema, so that Foxglove shows the well-known ones
without configuration:

==============================  ======================  =====================================
topic                           schema                  content
==============================  ======================  =====================================
``/tf``                         foxglove.FrameTransform each robot's frame in ``world``
``/robots/NAME/pose``           foxglove.PoseInFrame    the robot's axle pose
``/reference/pose``             foxglove.PoseInFrame    the reference point (x_d, y_d, θ_d)
``/scene``                      foxglove.SceneUpdate    reference path, trails, formation links
``/robots/NAME/command``        nonholo.Command         v (m/s), ω (rad/s)
``/robots/NAME/errors``         nonholo.Errors          a follower's link errors z_d − z (l, φ or
                                                        l1, l2), a root's position and heading error
``/links``                      nonholo.Links           per link parent→child: distance, errors
==============================  ======================  =====================================

The metadata record ``nonholo`` holds the robots (roles, parents, error names), the links and
the run's JSON summary; ``read_recording`` rebuilds the ``Replay`` from the messages.
"""
from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import numpy as np

from nonholo.errors import NonholoInputError
from nonholo.view import require
from nonholo.view.data import Replay

PROFILE = ""  # no ROS profile: plain JSON messages
METADATA = "nonholo"
FRAME = "world"
SCENE_RATE_HZ = 5.0       # scene updates (trails, links) at most this often
TRAIL_S = 20.0            # seconds of trail drawn behind each robot
TRAIL_POINTS = 50         # at most this many points per trail
MAX_MESSAGES = 5_000_000   # reading holds a few hundred bytes per message
RECORD_MAX_HZ = 100.0      # samples recorded at most this often (Foxglove plays a run in real time)
COLORS = ((0.12, 0.47, 0.71), (1.0, 0.5, 0.05), (0.17, 0.63, 0.17), (0.84, 0.15, 0.16), (0.58, 0.4, 0.74),
          (0.55, 0.34, 0.29), (0.89, 0.47, 0.76), (0.5, 0.5, 0.5), (0.74, 0.74, 0.13), (0.09, 0.75, 0.81))


# ---------------------------------------------------------------------- schemas
def _object(title: str, properties: dict, description: str = "") -> dict:
    out = {"title": title, "type": "object", "properties": properties}
    if description:
        out["description"] = description
    return out


NUMBER = {"type": "number"}
TIME = _object("time", {"sec": {"type": "integer", "minimum": 0},
                        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}})
DURATION = _object("duration", {"sec": {"type": "integer"},
                                "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}})
VECTOR3 = _object("foxglove.Vector3", {"x": NUMBER, "y": NUMBER, "z": NUMBER})
POINT3 = _object("foxglove.Point3", {"x": NUMBER, "y": NUMBER, "z": NUMBER})
QUATERNION = _object("foxglove.Quaternion", {"x": NUMBER, "y": NUMBER, "z": NUMBER, "w": NUMBER})
COLOR = _object("foxglove.Color", {"r": NUMBER, "g": NUMBER, "b": NUMBER, "a": NUMBER})
POSE = _object("foxglove.Pose", {"position": VECTOR3, "orientation": QUATERNION})
POSE_IN_FRAME = _object("foxglove.PoseInFrame", {"timestamp": TIME, "frame_id": {"type": "string"}, "pose": POSE},
                        "A timestamped pose for an object or reference frame in 3D space")
FRAME_TRANSFORM = _object("foxglove.FrameTransform", {
    "timestamp": TIME, "parent_frame_id": {"type": "string"}, "child_frame_id": {"type": "string"},
    "translation": VECTOR3, "rotation": QUATERNION}, "A transform between two reference frames in 3D space")
LINE = _object("foxglove.LinePrimitive", {
    "type": {"type": "integer", "enum": [0, 1, 2], "description": "0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST"},
    "pose": POSE, "thickness": NUMBER, "scale_invariant": {"type": "boolean"},
    "points": {"type": "array", "items": POINT3}, "color": COLOR, "colors": {"type": "array", "items": COLOR},
    "indices": {"type": "array", "items": {"type": "integer", "minimum": 0}}})
ARRAY = {"type": "array", "items": {"type": "object"}}
ENTITY = _object("foxglove.SceneEntity", {
    "timestamp": TIME, "frame_id": {"type": "string"}, "id": {"type": "string"}, "lifetime": DURATION,
    "frame_locked": {"type": "boolean"}, "metadata": ARRAY, "arrows": ARRAY, "cubes": ARRAY, "spheres": ARRAY,
    "cylinders": ARRAY, "lines": {"type": "array", "items": LINE}, "triangles": ARRAY, "texts": ARRAY,
    "models": ARRAY})
SCENE_UPDATE = _object("foxglove.SceneUpdate", {"deletions": ARRAY, "entities": {"type": "array", "items": ENTITY}},
                       "An update to the entities displayed in a 3D scene")
COMMAND = _object("nonholo.Command", {"timestamp": TIME, "v": NUMBER, "omega": NUMBER},
                  "The command a robot holds: v (m/s), omega (rad/s)")
ERRORS = _object("nonholo.Errors", {"timestamp": TIME}, "A follower's link output errors z_d - z (named after "
                 "its outputs: l and phi, or l1 and l2) or a root's position (m) and heading (rad) error")
LINKS = _object("nonholo.Links", {"timestamp": TIME, "links": {"type": "object"}},
                "Per formation link parent->child: axle distance (m) and the follower's output errors")


def _stamp(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _quaternion(theta: float) -> dict:
    return {"x": 0.0, "y": 0.0, "z": math.sin(theta / 2), "w": math.cos(theta / 2)}


def _pose(x: float, y: float, theta: float) -> dict:
    return {"position": {"x": x, "y": y, "z": 0.0}, "orientation": _quaternion(theta)}


def pose_in_frame(ns: int, x: float, y: float, theta: float) -> dict:
    """A ``foxglove.PoseInFrame`` message in the ``world`` frame."""
    return {"timestamp": _stamp(ns), "frame_id": FRAME, "pose": _pose(x, y, theta)}


def frame_transform(ns: int, name: str, x: float, y: float, theta: float) -> dict:
    """A ``foxglove.FrameTransform`` message: frame ``name`` in ``world``."""
    return {"timestamp": _stamp(ns), "parent_frame_id": FRAME, "child_frame_id": name,
            "translation": {"x": x, "y": y, "z": 0.0}, "rotation": _quaternion(theta)}


def _line(points, color, thickness: float, kind: int = 0) -> dict:
    r, g, b = color
    return {"type": kind, "pose": _pose(0.0, 0.0, 0.0), "thickness": thickness, "scale_invariant": True,
            "points": [{"x": float(x), "y": float(y), "z": 0.0} for x, y in points],
            "color": {"r": r, "g": g, "b": b, "a": 1.0}, "colors": [], "indices": []}


def _entity(ns: int, name: str, lines: list) -> dict:
    return {"timestamp": _stamp(ns), "frame_id": FRAME, "id": name, "lifetime": {"sec": 0, "nsec": 0},
            "frame_locked": False, "metadata": [], "arrows": [], "cubes": [], "spheres": [], "cylinders": [],
            "lines": lines, "triangles": [], "texts": [], "models": []}


def _dump(value) -> bytes:
    return json.dumps(value, separators=(",", ":"), allow_nan=False).encode()


# ---------------------------------------------------------------------- writing
def record_every(dt: float, every: int = 1) -> int:
    """The sample stride of a recording: every ``every``-th sample, and at most
    ``RECORD_MAX_HZ`` samples a second of simulated time."""
    return max(int(every), math.ceil(1.0 / (RECORD_MAX_HZ * dt) - 1e-9))


def write_recording(replay: Replay, path, network: dict | None = None) -> Path:
    """Write ``replay`` to the MCAP file ``path`` (see the module's table of topics)."""
    require("mcap")
    from mcap.writer import Writer

    path = Path(path)
    names = replay.names
    messages = replay.t.size * (4 * len(names) + 2)
    if messages > MAX_MESSAGES:
        raise ValueError(f"a recording of {len(names)} robots and {replay.t.size} samples would hold {messages} "
                         f"messages, more than {MAX_MESSAGES} (fewer samples: --every N)")
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start(profile=PROFILE, library="nonholo")
        schema = {s["title"]: writer.register_schema(s["title"], "jsonschema", _dump(s))
                  for s in (POSE_IN_FRAME, FRAME_TRANSFORM, SCENE_UPDATE, COMMAND, ERRORS, LINKS)}

        def channel(topic: str, schema_name: str) -> int:
            return writer.register_channel(topic, "json", schema[schema_name])

        tf = channel("/tf", "foxglove.FrameTransform")
        scene = channel("/scene", "foxglove.SceneUpdate")
        links_channel = channel("/links", "nonholo.Links")
        reference_channel = channel("/reference/pose", "foxglove.PoseInFrame") if replay.reference is not None \
            else None
        per_robot = [(channel(f"/robots/{n}/pose", "foxglove.PoseInFrame"),
                      channel(f"/robots/{n}/command", "nonholo.Command"),
                      channel(f"/robots/{n}/errors", "nonholo.Errors")) for n in names]
        writer.add_metadata(METADATA, {"robots": json.dumps(replay.robots), "links": json.dumps(replay.links or {}),
                                       "summary": json.dumps(replay.summary, allow_nan=False),
                                       "network": json.dumps(network, allow_nan=False)})
        sequence = 0
        stamps = np.round(replay.t * 1e9).astype(np.int64)
        if stamps[0] < 0:
            raise ValueError("a recording starts at t >= 0")
        scene_every = max(1, int(round(1.0 / (SCENE_RATE_HZ * max(float(np.median(np.diff(replay.t))), 1e-9)))))\
            if replay.t.size > 1 else 1
        trail_samples = max(1, int(round(TRAIL_S / (float(replay.t[-1] - replay.t[0]) / max(replay.t.size - 1, 1)))))\
            if replay.t.size > 1 else 1
        trail_stride = max(1, trail_samples // TRAIL_POINTS)
        index = {n: i for i, n in enumerate(names)}
        pairs = [(key, index[link["parent"]], index[link["child"]]) for key, link in (replay.links or {}).items()
                 if link.get("parent") in index and link.get("child") in index]

        def put(channel_id: int, ns: int, value) -> None:
            nonlocal sequence
            sequence += 1
            writer.add_message(channel_id, log_time=int(ns), data=_dump(value), publish_time=int(ns),
                               sequence=sequence)

        if replay.reference is not None:
            path_points = replay.reference[:, :2][:: max(1, replay.t.size // 2000)]
            put(scene, int(stamps[0]), {"deletions": [], "entities": [
                _entity(int(stamps[0]), "reference", [_line(path_points, (0.4, 0.4, 0.4), 1.0)])]})
        for k, ns in enumerate(stamps.tolist()):
            stamp = _stamp(ns)
            for i, name in enumerate(names):
                x, y, theta = (float(v) for v in replay.pose[k, i])
                pose_channel, command_channel, errors_channel = per_robot[i]
                put(pose_channel, ns, pose_in_frame(ns, x, y, theta))
                put(tf, ns, frame_transform(ns, name, x, y, theta))
                put(command_channel, ns, {"timestamp": stamp, "v": float(replay.command[k, i, 0]),
                                          "omega": float(replay.command[k, i, 1])})
                first, second = replay.robots[i]["outputs"]
                put(errors_channel, ns, {"timestamp": stamp, f"{first}_error": float(replay.errors[k, i, 0]),
                                         f"{second}_error": float(replay.errors[k, i, 1])})
            if reference_channel is not None:
                put(reference_channel, ns, pose_in_frame(ns, *(float(v) for v in replay.reference[k])))
            if pairs:
                put(links_channel, ns, {"timestamp": stamp, "links": {
                    key: {"distance": float(np.hypot(*(replay.pose[k, c, :2] - replay.pose[k, p, :2]))),
                          **{f"{o}_error": float(replay.errors[k, c, j])
                             for j, o in enumerate(replay.robots[c]["outputs"])}} for key, p, c in pairs}})
            if k % scene_every == 0 or k == stamps.size - 1:
                start = max(0, k - trail_samples)
                entities = [_entity(ns, f"trail/{name}", [_line(replay.pose[start:k + 1:trail_stride, i, :2],
                                                                COLORS[i % len(COLORS)], 2.0)])
                            for i, name in enumerate(names)]
                if pairs:
                    segments = [replay.pose[k, j, :2] for _, p, c in pairs for j in (p, c)]
                    entities.append(_entity(ns, "links", [_line(segments, (0.2, 0.2, 0.2), 1.5, kind=2)]))
                put(scene, ns, {"deletions": [], "entities": entities})
        writer.finish()
    return path


# ---------------------------------------------------------------------- reading
def read_recording(path) -> Replay:
    """The ``Replay`` of an MCAP file written by ``write_recording``; NonholoInputError (one
    line) for a missing, truncated or foreign file."""
    require("mcap")
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    path = Path(path)
    if not path.is_file():
        raise NonholoInputError(f"{path}: no such file")
    try:
        with open(path, "rb") as stream:
            reader = make_reader(stream)
            meta = {}
            for record in reader.iter_metadata():
                if record.name == METADATA:
                    meta = dict(record.metadata)
            if not meta:
                raise NonholoInputError(f"{path}: not a nonholo recording (no '{METADATA}' metadata record)")
            robots = json.loads(meta["robots"])
            names = [r["name"] for r in robots]
            if not names or len(set(names)) != len(names):
                raise ValueError("robots")
            fields = _fields(robots)
            series: dict[str, list] = {topic: [] for topic in fields}
            count = 0
            for _, channel, message in reader.iter_messages(log_time_order=False):
                count += 1
                if count > MAX_MESSAGES:
                    raise NonholoInputError(f"{path}: more than {MAX_MESSAGES} messages")
                extract = fields.get(channel.topic)
                if extract is not None:   # numbers only: a long recording stays small in memory
                    series[channel.topic].append((message.log_time, extract(json.loads(message.data))))
    except NonholoInputError:
        raise
    except (McapError, OSError, EOFError, ValueError, KeyError, TypeError, struct.error, AttributeError,
            IndexError, RuntimeError) as exc:   # zstd and lz4 report corrupt chunks as RuntimeError
        raise NonholoInputError(f"{path}: not a readable MCAP recording ({type(exc).__name__}: "
                                f"{' '.join(str(exc).split())[:80]})") from None
    try:
        return _replay(robots, series, meta)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise NonholoInputError(f"{path}: a nonholo recording with missing or inconsistent messages "
                                f"({type(exc).__name__}: {' '.join(str(exc).split())[:80]})") from None


def _theta(orientation: dict) -> float:
    return 2.0 * math.atan2(orientation["z"], orientation["w"])


def _pose_numbers(m: dict) -> tuple:
    p = m["pose"]
    return float(p["position"]["x"]), float(p["position"]["y"]), _theta(p["orientation"])


def _fields(robots: list) -> dict:
    """Per topic read back, how to take its numbers from a message."""
    fields = {"/reference/pose": _pose_numbers}
    for robot in robots:
        name, (first, second) = robot["name"], robot["outputs"]
        fields[f"/robots/{name}/pose"] = _pose_numbers
        fields[f"/robots/{name}/command"] = lambda m: (float(m["v"]), float(m["omega"]))
        fields[f"/robots/{name}/errors"] = lambda m, a=f"{first}_error", b=f"{second}_error": (float(m[a]),
                                                                                              float(m[b]))
    return fields


def _replay(robots: list, series: dict, meta: dict) -> Replay:
    names = [r["name"] for r in robots]
    first = sorted(series[f"/robots/{names[0]}/pose"], key=lambda m: m[0])
    stamps = [m[0] for m in first]
    if not stamps:
        raise ValueError(f"no /robots/{names[0]}/pose messages")

    def aligned(topic: str) -> np.ndarray:
        messages = sorted(series[topic], key=lambda m: m[0])
        if [m[0] for m in messages] != stamps:
            raise ValueError(f"{topic} is not on the poses' time grid")
        return np.array([m[1] for m in messages], dtype=float)

    pose = np.stack([aligned(f"/robots/{n}/pose") for n in names], axis=1)
    command = np.stack([aligned(f"/robots/{n}/command") for n in names], axis=1)
    errors = np.stack([aligned(f"/robots/{n}/errors") for n in names], axis=1)
    reference = aligned("/reference/pose") if series["/reference/pose"] else None
    summary = json.loads(meta.get("summary", "null"))
    network = json.loads(meta.get("network", "null"))
    if network and isinstance(summary, dict):
        summary["network"] = network
    links = json.loads(meta.get("links", "{}"))
    return Replay(robots, np.array(stamps, dtype=float) / 1e9, pose, command, errors, reference, summary, links)
