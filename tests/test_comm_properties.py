"""Hypothesis: decode(encode(m)) == m over generated messages, and a time-bounded fuzz
of the decoder (only ACLParseError may escape, never another exception or a hang)."""
from __future__ import annotations

from datetime import datetime, timezone

from hypothesis import HealthCheck, given, settings, strategies as st

from nonholo.comm import ACLMessage, ACLParseError, AgentID, PERFORMATIVES, RelativeTime, decode, encode
from nonholo.comm.json_form import message_from_json, message_to_json

text = st.text(max_size=30)
names = st.text(alphabet=st.characters(blacklist_characters='()" ', blacklist_categories=("Cc", "Cs", "Zs", "Zl", "Zp")),
                min_size=1, max_size=8)
datetimes = st.one_of(
    st.datetimes(min_value=datetime(1000, 1, 1), max_value=datetime(9999, 1, 1),
                 timezones=st.just(timezone.utc)).map(lambda d: d.replace(microsecond=d.microsecond // 1000 * 1000)),
    st.builds(RelativeTime, st.booleans(), st.integers(0, 9999), st.integers(0, 99),
              st.integers(0, 99), st.integers(0, 99), st.integers(0, 99), st.integers(0, 99),
              st.integers(0, 999)),
)
atoms = st.one_of(text, st.integers(-10**30, 10**30),
                  st.floats(allow_nan=False, allow_infinity=False), datetimes)
expressions = st.recursive(atoms, lambda inner: st.lists(inner, max_size=4).map(tuple), max_leaves=12)


def unique_ci(keys):
    return len({k.lower() for k in keys}) == len(keys)


user_params = st.dictionaries(names, expressions, max_size=3).filter(unique_ci)
aids = st.recursive(
    st.builds(AgentID, st.text(min_size=1, max_size=15), st.lists(text, max_size=2).map(tuple),
              st.just(()), user_params),
    lambda inner: st.builds(AgentID, st.text(min_size=1, max_size=15), st.just(()),
                            st.lists(inner, max_size=2).map(tuple), st.just({})),
    max_leaves=4)
optional = lambda strategy: st.none() | strategy  # noqa: E731
messages = st.builds(
    ACLMessage,
    performative=st.sampled_from(sorted(PERFORMATIVES)),
    sender=optional(aids), receivers=optional(st.lists(aids, max_size=3)),
    reply_to=optional(st.lists(aids, max_size=2)), content=optional(st.text(max_size=200)),
    language=optional(expressions), encoding=optional(expressions), ontology=optional(expressions),
    protocol=optional(st.sampled_from(["fipa-request", "fipa-subscribe", "x"])),
    conversation_id=optional(expressions), reply_with=optional(expressions),
    in_reply_to=optional(expressions), reply_by=optional(datetimes), user_params=user_params,
)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(messages)
def test_round_trip(message):
    assert decode(encode(message)) == message


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(messages)
def test_json_form_round_trip(message):
    assert message_from_json(message_to_json(message)) == message


FRAGMENTS = [b"(", b")", b" ", b'"', b'\\"', b"\\", b"#", b"#3\"", b"#99\"", b":content",
             b":sender", b":X-a", b"inform", b"agent-identifier", b":name", b"set", b"sequence",
             b"1", b"-.5e3", b"20250101T120005000Z", b"\xc3", b"\xff", b"\x00", b"@", b"\n"]


def _decode_or_reject(data: bytes) -> None:
    try:
        decode(data, max_size=4096)
    except ACLParseError as error:
        assert 0 <= error.offset <= max(len(data), 4096)


@settings(max_examples=400, deadline=None)
@given(st.lists(st.sampled_from(FRAGMENTS), max_size=40).map(b"".join))
def test_fuzz_structured_fragments(data):
    _decode_or_reject(data)


@settings(max_examples=200, deadline=None)
@given(messages, st.integers(0, 10**6), st.binary(max_size=3))
def test_fuzz_mutated_valid_messages(message, where, patch):
    data = encode(message)
    cut = where % (len(data) + 1)
    _decode_or_reject(data[:cut] + patch + data[cut + len(patch):])


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=200))
def test_fuzz_random_bytes(data):
    _decode_or_reject(data)
