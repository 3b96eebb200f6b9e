"""The formation ontology ``leader-follower-v1`` with content language ``json``.

* ``LeaderState`` - the leader's periodic state (sequence number, time stamp, pose, v, w,
  formation id), sent as ``inform`` in a FIPA-Subscribe conversation;
* ``FormationCommand`` - a new formation (follower targets as offsets in the leader frame),
  sent as ``request`` in a FIPA-Request conversation.

Content is validated on the way in and out: finite numbers within physical bounds.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any, Mapping

from nonholo.comm.errors import ContentError
from nonholo.comm.message import ACLMessage, AgentID

ONTOLOGY = "leader-follower-v1"
LANGUAGE = "json"
SUBSCRIBE_PROTOCOL = "fipa-subscribe"
REQUEST_PROTOCOL = "fipa-request"
MAX_FOLLOWERS = 7


@dataclass(frozen=True, slots=True)
class PhysicalLimits:
    """Bounds a value must respect to be believed (not the robot's saturation limits)."""

    max_abs_position_m: float = 1.0e4
    max_speed_m_s: float = 10.0
    max_turn_rate_rad_s: float = 20.0
    max_offset_m: float = 100.0


DEFAULT_LIMITS = PhysicalLimits()


@dataclass(frozen=True, slots=True)
class LeaderState:
    seq: int
    stamp: float            # sender wall-clock time, seconds since the Unix epoch
    x: float
    y: float
    theta: float
    v: float                # linear speed, m/s
    w: float                # turn rate, rad/s
    formation: str

    def validate(self, limits: PhysicalLimits = DEFAULT_LIMITS) -> "LeaderState":
        _require(type(self.seq) is int and 0 <= self.seq < 2**63, "seq must be an int >= 0")
        _require(isinstance(self.formation, str) and 0 < len(self.formation) <= 64,
                 "formation must be a 1..64 character string")
        _finite(stamp=self.stamp, x=self.x, y=self.y, theta=self.theta, v=self.v, w=self.w)
        _require(self.stamp >= 0, "stamp must be >= 0")
        _within(limits.max_abs_position_m, x=self.x, y=self.y)
        _within(limits.max_speed_m_s, v=self.v)
        _within(limits.max_turn_rate_rad_s, w=self.w)
        _within(1000 * math.pi, theta=self.theta)
        return self

    def to_content(self) -> str:
        self.validate()
        return json.dumps({"seq": self.seq, "t": self.stamp, "pose": [self.x, self.y, self.theta],
                           "v": self.v, "w": self.w, "formation": self.formation},
                          separators=(",", ":"), allow_nan=False)

    @classmethod
    def from_content(cls, content: str, limits: PhysicalLimits = DEFAULT_LIMITS) -> "LeaderState":
        data = _json_object(content, {"seq", "t", "pose", "v", "w", "formation"})
        pose = data["pose"]
        _require(isinstance(pose, list) and len(pose) == 3, "pose must be [x, y, theta]")
        return cls(data["seq"], _number(data["t"]), *map(_number, pose), _number(data["v"]),
                   _number(data["w"]), data["formation"]).validate(limits)


@dataclass(frozen=True, slots=True)
class FormationCommand:
    """Switch to ``formation``: each follower's target offset (forward, left) in metres,
    in the leader's body frame."""

    formation: str
    offsets: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def validate(self, limits: PhysicalLimits = DEFAULT_LIMITS) -> "FormationCommand":
        _require(isinstance(self.formation, str) and 0 < len(self.formation) <= 64,
                 "formation must be a 1..64 character string")
        _require(0 < len(self.offsets) <= MAX_FOLLOWERS, f"1..{MAX_FOLLOWERS} offsets required")
        for name, offset in self.offsets.items():
            _require(isinstance(name, str) and name, "follower names must be non-empty strings")
            _require(len(offset) == 2, f"offset of {name} must be [forward, left]")
            _finite(forward=offset[0], left=offset[1])
            _within(limits.max_offset_m, forward=offset[0], left=offset[1])
        return self

    def to_content(self) -> str:
        self.validate()
        return json.dumps({"action": "set-formation", "formation": self.formation,
                           "offsets": {k: list(v) for k, v in self.offsets.items()}},
                          separators=(",", ":"), allow_nan=False)

    @classmethod
    def from_content(cls, content: str,
                     limits: PhysicalLimits = DEFAULT_LIMITS) -> "FormationCommand":
        data = _json_object(content, {"action", "formation", "offsets"})
        _require(data["action"] == "set-formation", "action must be set-formation")
        offsets = data["offsets"]
        _require(isinstance(offsets, dict), "offsets must be an object")
        parsed = {}
        for name, offset in offsets.items():
            _require(isinstance(offset, list) and len(offset) == 2,
                     f"offset of {name} must be [forward, left]")
            parsed[name] = (_number(offset[0]), _number(offset[1]))
        return cls(data["formation"], parsed).validate(limits)


def state_inform(state: LeaderState, sender: AgentID, receivers: tuple[AgentID, ...],
                 conversation_id: str, in_reply_to: str | None = None) -> ACLMessage:
    return ACLMessage("inform", sender=sender, receivers=receivers, content=state.to_content(),
                      language=LANGUAGE, ontology=ONTOLOGY, protocol=SUBSCRIBE_PROTOCOL,
                      conversation_id=conversation_id, in_reply_to=in_reply_to)


def formation_request(command: FormationCommand, sender: AgentID,
                      receivers: tuple[AgentID, ...], conversation_id: str,
                      reply_with: str) -> ACLMessage:
    return ACLMessage("request", sender=sender, receivers=receivers, content=command.to_content(),
                      language=LANGUAGE, ontology=ONTOLOGY, protocol=REQUEST_PROTOCOL,
                      conversation_id=conversation_id, reply_with=reply_with)


def read_leader_state(message: ACLMessage, limits: PhysicalLimits = DEFAULT_LIMITS) -> LeaderState:
    """The state carried by an ``inform`` of this ontology; ContentError otherwise."""
    _check_envelope_fields(message, "inform")
    return LeaderState.from_content(message.content or "", limits)


def read_formation_command(message: ACLMessage,
                           limits: PhysicalLimits = DEFAULT_LIMITS) -> FormationCommand:
    _check_envelope_fields(message, "request")
    return FormationCommand.from_content(message.content or "", limits)


# -- validation helpers ----------------------------------------------------------------
def _check_envelope_fields(message: ACLMessage, performative: str) -> None:
    _require(message.performative == performative, f"expected {performative}, got "
             f"{message.performative}")
    _require(message.ontology == ONTOLOGY, f"unknown ontology {message.ontology!r}")
    _require(message.language == LANGUAGE, f"unsupported content language {message.language!r}")


def _json_object(content: str, keys: set[str]) -> dict[str, Any]:
    try:
        data = json.loads(content, parse_constant=_reject_constant)
    except (ValueError, RecursionError) as exc:
        raise ContentError(f"content is not valid JSON: {exc}") from None
    _require(isinstance(data, dict), "content must be a JSON object")
    _require(set(data) == keys, f"content must have exactly the keys {sorted(keys)}")
    return data


def _reject_constant(name: str) -> None:
    raise ContentError(f"{name} is not a finite number")


def _number(value: object) -> float:
    _require(isinstance(value, (int, float)) and not isinstance(value, bool),
             f"expected a number, got {value!r}")
    try:
        return float(value)  # type: ignore[arg-type]
    except OverflowError:
        raise ContentError(f"{value} is not a finite number") from None


def _finite(**values: float) -> None:
    for name, value in values.items():
        _require(isinstance(value, (int, float)) and not isinstance(value, bool)
                 and math.isfinite(value), f"{name} must be a finite number")


def _within(bound: float, **values: float) -> None:
    for name, value in values.items():
        _require(abs(value) <= bound, f"{name}={value} is beyond the physical bound {bound}")


def _require(condition: bool, reason: str) -> None:
    if not condition:
        raise ContentError(reason)
