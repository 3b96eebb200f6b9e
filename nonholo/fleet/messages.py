"""The messages of a fleet (ontology ``leader-follower-v1``, content language json):

* ``subscribe`` (follower → parent) and ``agree`` (parent → follower): a FIPA-Subscribe
  conversation per link, id ``"<follower>/<parent>"``;
* ``inform`` with a ``RobotState`` (parent → its subscribers), once per control instant:
  the parent's pose at t_k, its command (v, ω) for [t_k, t_k + T), t_k, the instant k and a
  sequence number (spec fleet.md §2);
* ``inform`` with a ``Progress`` (follower → parent, every few instants): the instant it has
  consumed, the lockstep flow control that keeps every queue bounded;
* ``cancel`` (follower → parent) ends a subscription.

Floats are written with ``repr`` (json does), which round-trips exactly.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass

from nonholo.comm.errors import ContentError
from nonholo.comm.message import ACLMessage, AgentID
from nonholo.sim.scenario import MAX_POSITION_M

ONTOLOGY = "leader-follower-v1"
LANGUAGE = "json"
PROTOCOL = "fipa-subscribe"
MAX_INSTANT = 2**53


@dataclass(frozen=True)
class RobotState:
    robot: str
    k: int
    seq: int
    t: float
    x: float
    y: float
    theta: float
    v: float
    omega: float

    def to_content(self) -> str:
        return json.dumps({"robot": self.robot, "k": self.k, "seq": self.seq, "t": self.t,
                           "pose": [self.x, self.y, self.theta], "v": self.v, "w": self.omega},
                          separators=(",", ":"), allow_nan=False)


def _number(data: dict, name: str, bound: float) -> float:
    value = data.get(name)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or abs(value) > bound:
        raise ContentError(f"{name} must be a finite number within ±{bound:g}, got {value!r}"[:120])
    return float(value)


def _count(data: dict, name: str) -> int:
    value = data.get(name)
    if type(value) is not int or not 0 <= value < MAX_INSTANT:
        raise ContentError(f"{name} must be an integer in 0..2^53, got {value!r}"[:120])
    return value


def _object(content: str | None, keys: set[str]) -> dict:
    try:
        data = json.loads(content or "", parse_constant=lambda name: None)
    except (ValueError, RecursionError):
        raise ContentError("content is not valid JSON") from None
    if not isinstance(data, dict) or set(data) != keys:
        raise ContentError(f"content must be an object with exactly the keys {sorted(keys)}")
    return data


def read_state(message: ACLMessage, v_max: float, omega_max: float) -> RobotState:
    """The ``RobotState`` of an inform, validated: finite, within position bounds and the
    sender's actuator limits (a robot never commands beyond them)."""
    data = _object(message.content, {"robot", "k", "seq", "t", "pose", "v", "w"})
    pose = data["pose"]
    if not isinstance(pose, list) or len(pose) != 3:
        raise ContentError("pose must be [x, y, theta]")
    if not isinstance(data["robot"], str) or message.sender is None or data["robot"] != message.sender.name:
        raise ContentError("robot must name the sender")
    values = dict(zip("xyz", pose))
    return RobotState(data["robot"], _count(data, "k"), _count(data, "seq"), _number(data, "t", 1e9),
                      _number(values, "x", MAX_POSITION_M), _number(values, "y", MAX_POSITION_M),
                      _number(values, "z", 1e6), _number(data, "v", v_max), _number(data, "w", omega_max))


def read_progress(message: ACLMessage) -> int:
    return _count(_object(message.content, {"done"}), "done")


def progress_content(done: int) -> str:
    return json.dumps({"done": done})


def conversation(follower: str, parent: str) -> str:
    return f"{follower}/{parent}"


def act(performative: str, sender: str, receiver: str, conversation_id: str, content: str | None = None,
        **fields) -> ACLMessage:
    return ACLMessage(performative, sender=AgentID(sender), receivers=(AgentID(receiver),), content=content,
                      language=LANGUAGE, ontology=ONTOLOGY, protocol=PROTOCOL, conversation_id=conversation_id,
                      **fields)
