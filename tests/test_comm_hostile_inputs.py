"""Hostile inputs below the transports: envelope sequence jumps, impersonation through
:sender, codec edge cases (typed errors only), JADE-readable output, strict key ids, and
the CLI's limits applied while reading. Each test is bounded in time and memory."""
from __future__ import annotations

import io
import json
import os
import sys
import time
import tracemalloc
from datetime import timedelta

import pytest
from hypothesis import given, settings

from nonholo.cli import main
from nonholo.comm import (
    ACLEncodeError, ACLMessage, ACLParseError, AgentID, Opener, RelativeTime, ReplayedMessage, Sealer,
    SecureChannel, SenderMismatch, decode, encode,
)
from nonholo.comm import acl_lexical as lex
from nonholo.comm.acl_decode import tokenize
from nonholo.comm.envelope import MAX_SEQ
from nonholo.comm.errors import KeyFileError
from nonholo.comm.keys import load_key_file, parse_key_id, parse_keys

from test_comm_properties import messages

KEY = bytes(range(32))
NOW = 1_700_000_000_000


def sealed_pair(window: int = 0):
    sealer = Sealer(KEY, key_id=1, sender_id=7, epoch=42, clock_ms=lambda: NOW)
    return sealer, Opener({1: KEY}, reorder_window=window, clock_ms=lambda: NOW)


# -- envelope -----------------------------------------------------------------------------
@pytest.mark.parametrize("jump", [2**33, 2**40, 2**63, MAX_SEQ])
@pytest.mark.parametrize("window", [0, 1024])
def test_any_sequence_jump_takes_constant_time_and_memory(jump, window):
    sealer, opener = sealed_pair(window)
    opener.open(sealer.seal(b"first"))
    late = None
    if window:
        sealer.seq = jump - 2
        late = sealer.seal(b"one behind")
    sealer.seq = jump - 1
    frame = sealer.seal(b"jump")
    tracemalloc.start()
    try:
        start = time.perf_counter()
        assert opener.open(frame).seq == jump
        elapsed = time.perf_counter() - start
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert elapsed < 0.05 and peak < 64 * 1024
    if late is not None:  # the window still works right after the jump
        assert opener.open(late).seq == jump - 1
        with pytest.raises(ReplayedMessage):
            opener.open(late)
    with pytest.raises(ReplayedMessage):
        opener.open(frame)


def test_sealer_starts_a_new_epoch_when_the_sequence_space_is_used_up():
    sealer, opener = sealed_pair()
    sealer.seq = MAX_SEQ - 1
    last = opener.open(sealer.seal(b"last of the epoch"))
    after = opener.open(sealer.seal(b"first of the next"))
    assert last.seq == MAX_SEQ and after.seq == 1 and after.epoch != last.epoch


# -- sender binding -------------------------------------------------------------------------
def test_channel_binds_the_envelope_sender_to_the_acl_sender():
    follower = SecureChannel(Sealer(b"f" * 32, key_id=1, sender_id=1, clock_ms=lambda: NOW))
    hub = SecureChannel(opener=Opener({1: b"f" * 32}, key_senders={1: frozenset({1})},
                                      clock_ms=lambda: NOW),
                        senders={0: "leader@fleet", 1: "f1@fleet"})
    honest = ACLMessage("inform", sender=AgentID("f1@fleet"), content="ok")
    assert hub.unpack(follower.pack(honest))[1] == honest
    for forged in (ACLMessage("inform", sender=AgentID("leader@fleet"), content="halt"),
                   ACLMessage("inform", sender=AgentID("F1@fleet"), content="case"),
                   ACLMessage("inform", content="no sender")):
        with pytest.raises(SenderMismatch):
            hub.unpack(follower.pack(forged))
    assert hub.rejected == {"SenderMismatch": 3}
    with pytest.raises(TypeError, match="senders"):
        SecureChannel(opener=Opener({1: KEY}))


# -- codec -----------------------------------------------------------------------------------
def test_lone_surrogate_in_text_input_is_a_parse_error_with_its_byte_offset():
    with pytest.raises(ACLParseError) as info:
        decode('(inform :content "é\ud800")')
    assert info.value.offset == len('(inform :content "é'.encode())


def test_huge_integer_is_an_encode_error():
    with pytest.raises(ACLEncodeError, match="too long"):
        encode(ACLMessage("inform", user_params={"n": 10 ** 5000}))
    assert decode(encode(ACLMessage("inform", user_params={"n": -10 ** 4000}))) \
        .user_params["n"] == -10 ** 4000


@pytest.mark.parametrize("bad", [0, -1, 10**9, True, 1.5])
def test_limits_outside_their_ceiling_are_value_errors(bad):
    with pytest.raises(ValueError):
        decode(b"(inform)", max_size=bad)
    with pytest.raises(ValueError):
        encode(ACLMessage("inform"), max_depth=bad)


def test_oversized_text_is_refused_before_it_is_encoded():
    with pytest.raises(ACLParseError, match="limit"):
        decode("x" * 70_000)


def test_words_the_grammar_allows_are_read():
    message = decode(b'(inform :reply-with :colon-word :in-reply-to a"b"c '
                     b':X-list (x :y z"w (q")) :conversation-id +12"x")')
    assert message.reply_with == ":colon-word" and message.in_reply_to == 'a"b"c'
    assert message.user_params["list"] == ("x", ":y", 'z"w', ('q"',))
    assert message.conversation_id == '+12"x"'  # starts like a Word: runs to the space
    # A number stops at a quote, as a longest-match lexer of the grammar would.
    assert decode(b'(inform :X-n (12"3"))').user_params["n"] == (12, "3")


def test_every_date_time_form_of_the_standard_is_read():
    values = decode(b"(inform :X-t (20250101T120000000A 20250101T120000000y 20250101T120000000J "
                    b"20250101T120000000z +00000001T000000000Z))").user_params["t"]
    assert [v.utcoffset() for v in values[:2]] == [timedelta(hours=1), timedelta(hours=-12)]
    assert values[2].tzinfo is None and values[3].utcoffset() == timedelta(0)
    assert values[4] == RelativeTime(False, days=1)
    with pytest.raises(ACLParseError, match="UTC"):
        decode(b"(inform :reply-by 00010101T000000000A)")  # 0000-12-31 in UTC


@pytest.mark.parametrize("text,expected", [
    ("été", '"été"'),                      # JADE reads no non-ASCII word
    ("a\x7fb", '#3"a\x7fb'),               # spec comm.md §1.3 encoder rule 3: a control character,
    ('say "hi"', '"say \\"hi\\""'),
    ("C:\\my dir\\f", '#11"C:\\my dir\\f'),  # or a backslash anywhere (\\" reads two ways),
    ("tab\there\nline", '#13"tab\there\nline'),  # goes out as a byte-length string
    ("C:\\my dir\\", '#10"C:\\my dir\\'),
    ('x\\" :X-b "y', '#11"x\\" :X-b "y'),      # never a second parameter for some reader
    ("C:\\", "C:\\"),                      # a word may hold (and end in) a backslash
    (":x", '":x"'),
    ("plain-word", "plain-word"),
])
def test_encoder_writes_forms_jade_reads(text, expected):
    data = encode(ACLMessage("inform", ontology=text))
    assert data == f"(inform\n :ontology {expected})".encode()
    assert decode(data).ontology == text


@settings(max_examples=100, deadline=None)
@given(messages)
def test_every_bare_word_written_is_printable_ascii(message):
    for kind, text, _ in tokenize(encode(message)):
        if kind == lex.ATOM and not text.startswith(":"):  # a value, not a parameter name
            assert text.isascii() and text.isprintable() and '"' not in text, text
        if kind == lex.BYTE_STRING:   # only what a string literal cannot carry unambiguously
            assert "\\" in text or any(ord(c) < 0x20 or ord(c) == 0x7f for c in text), text


# -- keys ------------------------------------------------------------------------------------
@pytest.mark.parametrize("text", ["1_0", "\u0661", " 1", "+1", "-1", "65536", "0x1", "", "1.0",
                                  "123456"])
def test_key_ids_are_strict(text):
    with pytest.raises(ValueError):
        parse_key_id(text)
    if text.strip() == text:  # a key line may be indented
        with pytest.raises(KeyFileError):
            parse_keys(f"{text}:{'ab' * 16}")


def test_key_ids_in_range_are_read():
    assert [parse_key_id(t) for t in ("0", "7", "65535", "00012")] == [0, 7, 65535, 12]


def test_non_utf8_or_huge_key_file_is_one_clear_error(tmp_path):
    path = tmp_path / "keys"
    path.write_bytes(b"1:" + b"ab" * 16 + b"\n# caf\xe9\n")
    path.chmod(0o600)
    with pytest.raises(KeyFileError, match="not UTF-8") as info:
        load_key_file(path)
    assert "\n" not in str(info.value)
    path.write_bytes(b"#" * (2 << 20))
    with pytest.raises(KeyFileError, match="larger"):
        load_key_file(path)


# -- command line ----------------------------------------------------------------------------
def run_cli(argv, monkeypatch, capsys, stdin: bytes = b""):
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(stdin)))
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="needs /dev/zero")
def test_parse_of_an_endless_input_stops_at_the_limit(monkeypatch, capsys):
    start = time.monotonic()
    code, out, err = run_cli(["acl", "parse", "/dev/zero"], monkeypatch, capsys)
    assert time.monotonic() - start < 2.0
    assert code == 1 and json.loads(out)["offset"] == 65536
    assert err.count("\n") == 1 and "limit" in err


def test_parse_reads_no_more_than_the_limit(monkeypatch, capsys):
    code, out, _ = run_cli(["acl", "parse", "--max-size", "8"], monkeypatch, capsys,
                           b"(inform)" + b" " * 10**6)
    assert code == 1 and "longer than the 8-byte limit" in json.loads(out)["error"]
    assert sys.stdin.buffer.tell() == 9


@pytest.mark.parametrize("argv", [
    ["acl", "parse", "--max-size", "-1"], ["acl", "parse", "--max-size", "0"],
    ["acl", "parse", "--max-size", "1_0"], ["acl", "parse", "--max-size", "99999999999"],
    ["acl", "parse", "--max-depth", "\u0663"], ["acl", "encode", "--max-size", "-5"],
    ["acl", "keygen", "unused", "--ids", "1_0"], ["acl", "keygen", "unused", "--ids", "1", "1"],
    ["acl", "bench", "--rounds", "0"], ["acl", "fuzz", "--seconds", "-1"],
])
def test_bad_options_are_one_line_and_exit_2(argv, monkeypatch, capsys, tmp_path):
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(argv, monkeypatch, capsys)
    assert code == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "unused").exists()


def test_encode_of_a_huge_integer_is_one_line_exit_1(monkeypatch, capsys):
    payload = json.dumps({"performative": "inform", "X-n": 1}).replace("1}", "1" * 5000 + "}")
    code, out, err = run_cli(["acl", "encode"], monkeypatch, capsys, payload.encode())
    assert code == 1 and out == "" and err.count("\n") == 1


def test_fuzz_command_reports_figures(monkeypatch, capsys):
    code, out, _ = run_cli(["acl", "fuzz", "--seconds", "1", "--json", "--seed", "5"],
                           monkeypatch, capsys)
    figures = json.loads(out)
    assert code == 0 and figures["failures"] == 0 and figures["inputs"] > 1000
    assert set(figures["targets"]) == {"acl", "envelope", "hello", "frames"}
    assert figures["slowest"]["ms"] > 0
