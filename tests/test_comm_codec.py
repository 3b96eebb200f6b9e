"""FIPA-ACL codec: the spec's examples, its rejection list, edge cases, round trips."""
from __future__ import annotations

from datetime import datetime, timedelta, timezone

import pytest

from nonholo.comm import (
    ACLEncodeError, ACLMessage, ACLParseError, AgentID, PERFORMATIVES, RelativeTime, decode,
    encode, encode_text,
)

SPEC_EXAMPLES = [
    rb'''(inform
  :sender (agent-identifier :name leader@fleet :addresses (sequence tcp://127.0.0.1:7447))
  :receiver (set (agent-identifier :name f1@fleet) (agent-identifier :name f2@fleet))
  :content "{\"seq\":4711,\"t\":1735732800.123,\"pose\":[1.25,-0.40,0.7854],\"v\":0.35,\"w\":-0.12}"
  :language json :ontology leader-follower-v1 :protocol fipa-subscribe
  :conversation-id formation-7 :X-seq 4711)''',
    rb'''(SUBSCRIBE :Sender (agent-identifier :name f3@fleet)
  :receiver (set (agent-identifier :name leader@fleet))
  :content "((iota ?s (leader-state ?s)))" :language fipa-sl0 :ontology leader-follower-v1
  :protocol fipa-subscribe :conversation-id formation-7 :reply-with sub-f3-1
  :reply-by 20250101T120005000Z)''',
    rb'''(agree :sender (agent-identifier :name leader@fleet) :receiver (set (agent-identifier :name f3@fleet))
  :content "((action (agent-identifier :name leader@fleet) (stream leader-state :period-ms 20)) true)"
  :language fipa-sl0 :protocol fipa-subscribe :conversation-id formation-7 :in-reply-to sub-f3-1)''',
    rb'''(not-understood :sender (agent-identifier :name f2@fleet)
  :receiver (set (agent-identifier :name leader@fleet))
  :content #22"bad frame: \"(inform\" :conversation-id formation-7)''',
]


@pytest.mark.parametrize("text", SPEC_EXAMPLES)
def test_spec_examples_parse_and_round_trip(text):
    message = decode(text)
    assert decode(encode(message)) == message


def test_spec_example_values():
    inform = decode(SPEC_EXAMPLES[0])
    assert inform.performative == "inform"
    assert inform.sender == AgentID("leader@fleet", addresses=("tcp://127.0.0.1:7447",))
    assert [r.name for r in inform.receivers] == ["f1@fleet", "f2@fleet"]
    assert inform.content.startswith('{"seq":4711,"t":1735732800.123,')
    assert inform.user_params == {"seq": 4711}
    assert (inform.language, inform.protocol, inform.conversation_id) == (
        "json", "fipa-subscribe", "formation-7")
    subscribe = decode(SPEC_EXAMPLES[1])
    assert subscribe.performative == "subscribe" and subscribe.sender.name == "f3@fleet"
    assert subscribe.reply_by == datetime(2025, 1, 1, 12, 0, 5, tzinfo=timezone.utc)
    assert decode(SPEC_EXAMPLES[2]).in_reply_to == "sub-f3-1"
    not_understood = decode(SPEC_EXAMPLES[3])
    assert not_understood.content == 'bad frame: \\"(inform\\"'
    assert not_understood.conversation_id == "formation-7"


# The spec's list of inputs to reject, plus the other strictness cases of the issue.
REJECTED = {
    "missing closing parenthesis": b'(inform :content "x"',
    "misspelled performative": b"(infrom :content \"x\")",
    "unterminated string": b'(inform :content "abc)',
    "short byte-length string": b'(inform :content #99"abc)',
    "set where an AID is required": b"(inform :sender (set))",
    "bare-word content": b"(inform :content abc)",
    "unknown parameter": b"(inform :foo bar)",
    "100 nested parentheses": b"(" * 100,
    "100 nested expressions": b"(inform :X-a " + b"(" * 100 + b")" * 101,
    "duplicate content": b'(inform :content "a" :content "b")',
    "duplicate user parameter, other case": b"(inform :X-a 1 :x-A 2)",
    "trailing garbage": b"(inform) (inform)",
    "empty input": b"",
    "unbalanced close": b"(inform))",
    "missing value": b"(inform :language)",
    "keyword as value": b"(inform :language :ontology x)",
    "aid without name": b"(inform :sender (agent-identifier))",
    "unknown aid slot": b"(inform :sender (agent-identifier :name a :colour red))",
    "duplicate aid slot": b"(inform :sender (agent-identifier :name a :name b))",
    "receiver without set": b"(inform :receiver (agent-identifier :name a))",
    "reply-by not a date": b"(inform :reply-by tomorrow)",
    "impossible date": b"(inform :reply-by 20251301T000000000Z)",
    "protocol as string": b'(inform :protocol "fipa request")',
    "word starting with digit": b"(inform :language 9lives)",
    "word starting with @": b"(inform :language @x)",
    "number overflow": b"(inform :X-n 1e999)",
    "invalid utf-8": b'(inform :content "\xff")',
    "control byte": b"(inform\x01)",
    "bad byte-length header": b'(inform :content #x"a)',
    "backslash before final quote": b'(inform :content "C:\\")',
    "performative not a word": b'("inform")',
}


@pytest.mark.parametrize("data", REJECTED.values(), ids=REJECTED.keys())
def test_rejected_inputs_raise_typed_error_with_offset(data):
    with pytest.raises(ACLParseError) as info:
        decode(data)
    assert isinstance(info.value, ValueError)
    assert 0 <= info.value.offset <= len(data)


def test_error_offsets_point_at_the_fault():
    cases = {b"(infrom)": 1, b'(inform :content "a" :content "b")': 21,
             b'(inform :content #99"abc)': 17, b"(inform) x": 9, b"(inform :foo 1)": 8}
    for data, offset in cases.items():
        with pytest.raises(ACLParseError) as info:
            decode(data)
        assert info.value.offset == offset, data


def test_limits():
    deep = b"(inform :X-a " + b"(" * 30 + b")" * 30 + b")"
    assert decode(deep).user_params["a"] is not None
    with pytest.raises(ACLParseError, match="nesting"):
        decode(deep, max_depth=16)
    big = b'(inform :content "' + b"x" * 70000 + b'")'
    with pytest.raises(ACLParseError, match="limit"):
        decode(big)
    assert len(decode(big, max_size=100_000).content) == 70000


def test_every_performative_any_case():
    for name in PERFORMATIVES:
        assert decode(f"({name.upper()})".encode()).performative == name
    assert len(PERFORMATIVES) == 22


def test_keywords_case_insensitive_values_case_preserved():
    message = decode(b"(INFORM :SENDER (AGENT-IDENTIFIER :NAME Leader@Fleet :Addresses "
                     b"(SEQUENCE http://X)) :Receiver (SET) :X-Seq Abc)")
    assert message.sender == AgentID("Leader@Fleet", addresses=("http://X",))
    assert message.receivers == ()
    assert message.user_params == {"Seq": "Abc"}


def test_lexical_forms():
    message = decode(b'(inform :X-a (-.5 1e-3 +2 -7 3.25E+2 .x +y "q\\"uote" "back\\slash" '
                     b'#2"\xc3\xa9 20250101T120005000Z 20250101T120005000 '
                     b'-00000001T020000000 ()) :X-b "line\nbreak")')
    values = message.user_params["a"]
    assert values[:7] == (-0.5, 0.001, 2, -7, 325.0, ".x", "+y")
    assert values[7:10] == ('q"uote', "back\\slash", "\u00e9")
    assert values[10] == datetime(2025, 1, 1, 12, 0, 5, tzinfo=timezone.utc)
    assert values[11] == datetime(2025, 1, 1, 12, 0, 5)  # no designator: local time
    assert values[12] == RelativeTime(True, days=1, hours=2)
    assert values[13] == ()
    assert message.user_params["b"] == "line\nbreak"


def test_byte_length_counts_bytes_not_characters():
    # "é" is 2 bytes: #2 takes exactly it; #1 would split it.
    assert decode('(inform :content #2"é)'.encode()).content == "é"
    with pytest.raises(ACLParseError):
        decode('(inform :content #1"é)'.encode())


def test_aid_resolvers_and_user_slots_round_trip():
    resolver = AgentID("df@platform", addresses=("http://df:7778/acc",))
    aid = AgentID("robot 1", addresses=("tcp://127.0.0.1:1", "1.2.3.4"), resolvers=(resolver,),
                  user_params={"role": "follower", "slot": 3})
    message = ACLMessage("propose", sender=aid, receivers=[aid], reply_to=[resolver],
                         content="")
    assert decode(encode(message)) == message


def test_encoder_follows_conventions():
    reply_by = datetime(2025, 1, 1, 13, 0, 5, 123456, tzinfo=timezone(timedelta(hours=1)))
    message = ACLMessage("request", sender=AgentID("a@p"), receivers=[AgentID("b@p")],
                         content='C:\\dir "x"', language="fipa-sl", reply_by=reply_by,
                         conversation_id=("formation", 7), user_params={"note": "two words"})
    text = encode_text(message)
    assert text.startswith("(request\n :sender (agent-identifier :name a@p)\n :receiver (set ")
    assert ':content #10"C:\\dir "x"' in text          # a backslash: a byte-length string (spec §1.3)
    assert ":reply-by 20250101T120005123Z" in text      # UTC, Z, milliseconds
    assert ':X-note "two words"' in text and ":conversation-id (formation 7)" in text
    assert encode_text(ACLMessage("inform", content="  padded  ")).count("  padded  ") == 1


@pytest.mark.parametrize("value", ["123", "-x", "#x", "@x", ":x", "", "1e5", "a(b", "a b",
                                   "20250101T120005000Z", "+1", ".5", 'a"b'])
def test_strings_that_are_not_words_are_quoted(value):
    message = ACLMessage("inform", ontology=value, user_params={"v": (value,)})
    decoded = decode(encode(message))
    assert decoded.ontology == value and decoded.user_params["v"] == (value,)


@pytest.mark.parametrize("message", [
    ACLMessage("inform", user_params={"x": float("nan")}),
    ACLMessage("inform", user_params={"x": True}),
    ACLMessage("inform", user_params={"a b": 1}),
    ACLMessage("inform", user_params={"a": 1, "A": 2}),
    ACLMessage("inform", protocol="two words"),
    ACLMessage("inform", content="\ud800"),
    ACLMessage("inform", user_params={"x": object()}),
])
def test_unencodable_messages_raise_typed_error(message):
    with pytest.raises(ACLEncodeError):
        encode(message)


def test_encoder_refuses_what_the_decoder_would_refuse():
    deep: object = "x"
    for _ in range(40):
        deep = (deep,)
    with pytest.raises(ACLEncodeError):
        encode(ACLMessage("inform", user_params={"d": deep}))
    with pytest.raises(ACLEncodeError):
        encode(ACLMessage("inform", content="x" * 70000))


def test_model_validation():
    with pytest.raises(ValueError):
        ACLMessage("query")  # PADE's non-standard name
    with pytest.raises(ValueError):
        AgentID("")


@pytest.mark.parametrize("token", ["@x", "12", "-x", "#x", "1.5", "20250101T120005000Z", "+1", ".5",
                                   "+20240101T000000000"])
def test_agent_names_and_addresses_are_words_or_strings(token):
    """spec comm.md §1.2: ``:name`` is a Word (a String accepted too) and an address is
    lexically a Word or String: a bare number, date or a token starting with @, # or - is
    neither; quoted, the same text is a name."""
    for message in (f"(inform :sender (agent-identifier :name {token}))",
                    f"(inform :sender (agent-identifier :name a :addresses (sequence {token})))"):
        with pytest.raises(ACLParseError, match="word or a string|word or string"):
            decode(message.encode())
    quoted = decode(f'(inform :sender (agent-identifier :name "{token}" :addresses (sequence "{token}")))'.encode())
    assert quoted.sender.name == token and quoted.sender.addresses == (token,)
    assert decode(encode(quoted)) == quoted


def test_a_message_read_at_the_size_limit_is_written_again():
    """A compact message just under 64 KiB decodes; written back one parameter per line it
    would pass the limit, so it goes out on one line (spec §1.3: newlines are optional)."""
    params = " ".join(f":X-p{i} {i}" for i in range(4700))
    data = f"(inform {params})".encode()
    assert 60_000 < len(data) <= 65_536
    message = decode(data)
    again = encode(message)
    assert len(again) <= 65_536 and b"\n" not in again and decode(again) == message
    assert b"\n :X-p0 0" in encode(ACLMessage("inform", user_params={"p0": 0}))   # short ones: one per line
