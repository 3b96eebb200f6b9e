"""Formation ontology content validation and the FIPA-Subscribe/Request state machines."""
from __future__ import annotations

import math

import pytest

from nonholo.comm import ACLMessage, AgentID, ContentError, ProtocolError, decode, encode
from nonholo.comm.ontology import (
    FormationCommand, LeaderState, formation_request, read_formation_command, read_leader_state,
    state_inform,
)
from nonholo.comm.protocols import Conversation

LEADER, F1 = AgentID("leader@fleet"), AgentID("f1@fleet")
STATE = LeaderState(4711, 1735732800.123, 1.25, -0.4, 0.7854, 0.35, -0.12, "formation-7")


def test_state_round_trip_through_acl():
    message = decode(encode(state_inform(STATE, LEADER, (F1,), "formation-7")))
    assert read_leader_state(message) == STATE


@pytest.mark.parametrize("field,value", [("v", math.nan), ("w", math.inf), ("x", 1e9),
                                         ("v", 50.0), ("seq", -1), ("formation", "")])
def test_invalid_state_rejected(field, value):
    fields = {f: getattr(STATE, f) for f in LeaderState.__dataclass_fields__}
    fields[field] = value
    with pytest.raises(ContentError):
        LeaderState(**fields).validate()


@pytest.mark.parametrize("content", [
    "not json", "[]", '{"seq":1}', '{"seq":1,"t":0,"pose":[0,0],"v":0,"w":0,"formation":"f"}',
    '{"seq":1,"t":0,"pose":[0,0,NaN],"v":0,"w":0,"formation":"f"}',
    '{"seq":1,"t":0,"pose":[0,0,0],"v":"fast","w":0,"formation":"f"}',
    '{"seq":1,"t":0,"pose":[0,0,0],"v":1e400,"w":0,"formation":"f"}',
    '{"seq":1,"t":0,"pose":[0,0,0],"v":0,"w":0,"formation":"f","extra":1}', "[" * 100000,
])
def test_invalid_state_content_rejected(content):
    with pytest.raises(ContentError):
        LeaderState.from_content(content)


def test_wrong_ontology_or_performative_rejected():
    message = state_inform(STATE, LEADER, (F1,), "c")
    with pytest.raises(ContentError):
        read_leader_state(ACLMessage("inform", content=message.content, language="json",
                                     ontology="other"))
    with pytest.raises(ContentError):
        read_formation_command(message)


def test_formation_command_round_trip_and_bounds():
    command = FormationCommand("wedge", {"f1@fleet": (-1.0, 0.5), "f2@fleet": (-1.0, -0.5)})
    message = decode(encode(formation_request(command, LEADER, (F1,), "cmd-1", "r1")))
    assert read_formation_command(message) == command
    for bad in (FormationCommand("wedge", {}), FormationCommand("w", {"f": (1e6, 0.0)}),
                FormationCommand("w", {"f": (math.nan, 0.0)})):
        with pytest.raises(ContentError):
            bad.validate()


def _msg(performative, protocol="fipa-subscribe", conversation="c"):
    return ACLMessage(performative, protocol=protocol, conversation_id=conversation)


def test_subscribe_protocol_happy_path_and_cancel():
    conversation = Conversation("fipa-subscribe", "c")
    for performative, speaker, state in [("subscribe", "initiator", "requested"),
                                         ("agree", "participant", "subscribed"),
                                         ("inform", "participant", "subscribed"),
                                         ("inform", "participant", "subscribed"),
                                         ("cancel", "initiator", "cancelled"),
                                         ("inform", "participant", "cancelled")]:
        assert conversation.advance(_msg(performative), speaker) == state


@pytest.mark.parametrize("steps", [
    [("inform", "participant")],                                  # stream before subscribe
    [("subscribe", "initiator"), ("inform", "participant")],      # inform before agree
    [("subscribe", "initiator"), ("agree", "initiator")],         # wrong speaker
    [("subscribe", "initiator"), ("refuse", "participant"), ("inform", "participant")],
])
def test_subscribe_protocol_violations(steps):
    conversation = Conversation("fipa-subscribe", "c")
    *ok, (performative, speaker) = steps
    for p, s in ok:
        conversation.advance(_msg(p), s)
    state = conversation.state
    with pytest.raises(ProtocolError):
        conversation.advance(_msg(performative), speaker)
    assert conversation.state == state


def test_request_protocol():
    conversation = Conversation("fipa-request", "c")
    conversation.advance(_msg("request", "fipa-request"), "initiator")
    conversation.advance(_msg("agree", "fipa-request"), "participant")
    assert conversation.advance(_msg("inform", "fipa-request"), "participant") == "done"
    assert conversation.finished
    with pytest.raises(ProtocolError):
        Conversation("fipa-request", "c").advance(_msg("request", "fipa-request", "other"),
                                                  "initiator")
    with pytest.raises(ProtocolError):
        Conversation("fipa-request", "c").advance(_msg("request", "fipa-subscribe"), "initiator")
