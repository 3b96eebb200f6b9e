"""Security envelope: forged, replayed, reordered and stale frames rejected; keys."""
from __future__ import annotations

import os

import pytest

from nonholo.comm import (
    ACLMessage, AgentID, ForgedMessage, MalformedEnvelope, Opener, ReplayedMessage, Sealer,
    SecureChannel, StaleMessage, UnknownKey,
)
from nonholo.comm.envelope import HEADER
from nonholo.comm.errors import KeyFileError
from nonholo.comm.keys import generate_key_line, load_key_env, load_key_file, parse_keys, write_key_file

KEY = bytes(range(32))
NOW = 1_700_000_000_000


class Clock:
    def __init__(self) -> None:
        self.ms = NOW

    def __call__(self) -> int:
        return self.ms


@pytest.fixture
def pair():
    clock = Clock()
    sealer = Sealer(KEY, key_id=1, sender_id=7, epoch=42, clock_ms=clock)
    opener = Opener({1: KEY}, clock_ms=clock)
    return sealer, opener, clock


def test_valid_frames_open_in_order(pair):
    sealer, opener, _ = pair
    for i in range(1, 4):
        opened = opener.open(sealer.seal(b"payload %d" % i))
        assert (opened.sender_id, opened.epoch, opened.seq) == (7, 42, i)
        assert opened.payload == b"payload %d" % i


@pytest.mark.parametrize("position", [0, 5, HEADER.size + 1, -1])
def test_forged_bit_flip_rejected(pair, position):
    sealer, opener, _ = pair
    frame = bytearray(sealer.seal(b"(inform)"))
    frame[position] ^= 0x01
    with pytest.raises((ForgedMessage, MalformedEnvelope, UnknownKey)):
        opener.open(bytes(frame))


def test_wrong_key_and_unknown_key_rejected(pair):
    _, opener, clock = pair
    with pytest.raises(ForgedMessage):
        opener.open(Sealer(b"k" * 32, key_id=1, sender_id=7, clock_ms=clock).seal(b"x"))
    with pytest.raises(UnknownKey):
        opener.open(Sealer(KEY, key_id=2, sender_id=7, clock_ms=clock).seal(b"x"))


def test_key_bound_to_sender():
    clock = Clock()
    opener = Opener({0: KEY, 1: b"f" * 32}, key_senders={0: frozenset({0}), 1: frozenset({1})},
                    clock_ms=clock)
    # Follower 1 holds key 1 only and claims to be the leader (sender 0).
    with pytest.raises(UnknownKey):
        opener.open(Sealer(b"f" * 32, key_id=1, sender_id=0, clock_ms=clock).seal(b"x"))


def test_truncated_and_padded_frames_rejected(pair):
    sealer, opener, _ = pair
    frame = sealer.seal(b"abc")
    for bad in (frame[:10], frame[:-1], frame + b"\0", b""):
        with pytest.raises(MalformedEnvelope):
            opener.open(bad)


def test_replay_rejected(pair):
    sealer, opener, _ = pair
    frame = sealer.seal(b"x")
    opener.open(frame)
    with pytest.raises(ReplayedMessage):
        opener.open(frame)


def test_reordered_rejected_by_default(pair):
    sealer, opener, _ = pair
    first, second = sealer.seal(b"1"), sealer.seal(b"2")
    opener.open(second)
    with pytest.raises(ReplayedMessage):
        opener.open(first)


def test_reorder_window_accepts_late_frames_once():
    clock = Clock()
    sealer = Sealer(KEY, key_id=1, sender_id=3, epoch=1, clock_ms=clock)
    opener = Opener({1: KEY}, reorder_window=4, clock_ms=clock)
    frames = [sealer.seal(b"%d" % i) for i in range(8)]
    opener.open(frames[5])
    opener.open(frames[3])
    with pytest.raises(ReplayedMessage):
        opener.open(frames[3])
    with pytest.raises(ReplayedMessage):
        opener.open(frames[0])  # 5 behind: outside the window of 4
    opener.open(frames[7])
    opener.open(frames[6])


def test_stale_and_future_rejected(pair):
    sealer, opener, clock = pair
    frame = sealer.seal(b"x")
    clock.ms += 1001
    with pytest.raises(StaleMessage):
        opener.open(frame)
    clock.ms -= 2000
    with pytest.raises(StaleMessage):
        opener.open(frame)


def test_reboot_new_epoch_accepted_old_epoch_retired():
    clock = Clock()
    opener = Opener({1: KEY}, clock_ms=clock)
    before = Sealer(KEY, key_id=1, sender_id=9, epoch=100, clock_ms=clock)
    old = [before.seal(b"a"), before.seal(b"b")]
    opener.open(old[0])
    after = Sealer(KEY, key_id=1, sender_id=9, epoch=200, clock_ms=clock)
    opener.open(after.seal(b"c"))  # reboot: seq restarts at 1
    with pytest.raises(ReplayedMessage):
        opener.open(old[1])        # pre-reboot frame replayed within the freshness limit


def test_senders_have_independent_windows(pair):
    sealer, opener, clock = pair
    other = Sealer(KEY, key_id=1, sender_id=8, clock_ms=clock)
    opener.open(sealer.seal(b"x"))
    opener.open(other.seal(b"x"))
    opener.open(sealer.seal(b"y"))


def test_channel_verifies_before_parsing(pair):
    sealer, opener, _ = pair
    channel = SecureChannel(sealer, opener, senders={7: "leader@fleet"})
    message = ACLMessage("inform", sender=AgentID("leader@fleet"), content="state")
    opened, decoded = channel.unpack(channel.pack(message))
    assert decoded == message and opened.sender_id == 7
    # Garbage that is not ACL but carries a bad tag fails as forged, not as a parse error.
    bad = bytearray(sealer.seal(b"((((not acl"))
    bad[-1] ^= 1
    with pytest.raises(ForgedMessage):
        channel.unpack(bytes(bad))


def test_key_file_permissions(tmp_path):
    path = tmp_path / "keys"
    write_key_file(path, [generate_key_line(0), generate_key_line(5)])
    assert os.stat(path).st_mode & 0o777 == 0o600
    assert sorted(load_key_file(path)) == [0, 5]
    os.chmod(path, 0o644)
    with pytest.raises(KeyFileError, match="chmod 600"):
        load_key_file(path)
    with pytest.raises(KeyFileError):
        load_key_file(tmp_path / "missing")


def test_key_env_and_format_errors():
    line = generate_key_line(3)
    assert list(load_key_env("K", {"K": line})) == [3]
    with pytest.raises(KeyFileError):
        load_key_env("K", {})
    for bad in ["", "x:00", "1:zz", "70000:" + "00" * 32, "1:" + "00" * 4,
                f"1:{'00' * 32}\n1:{'11' * 32}"]:
        with pytest.raises(KeyFileError):
            parse_keys(bad)
