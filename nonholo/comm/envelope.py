"""Authenticated envelope around each encoded ACL message (spec section 3).

Layout (big-endian)::

    magic "FA" | version u8 | flags u8 | key_id u16 | sender_id u16 | epoch u32
    | seq u64 | t_send_ms u64 | length u32 | payload | HMAC-SHA256 tag (32 bytes)

The tag covers header and payload, i.e. the exact bytes, so the ACL text needs no
canonical form. Receivers verify the tag before anything else reads the payload, then
check freshness and replay state per sender.
"""
from __future__ import annotations

import hashlib
import hmac
import secrets
import struct
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable, Mapping

from nonholo.comm.errors import (
    ForgedMessage,
    MalformedEnvelope,
    ReplayedMessage,
    StaleMessage,
    UnknownKey,
)

MAGIC = b"FA"
VERSION = 1
HEADER = struct.Struct(">2sBBHHIQQI")
TAG_SIZE = 32
OVERHEAD = HEADER.size + TAG_SIZE
RETIRED_EPOCHS_KEPT = 16
MAX_SEQ = (1 << 64) - 1


def wall_clock_ms() -> int:
    return time.time_ns() // 1_000_000


@dataclass(frozen=True, slots=True)
class Opened:
    """A verified frame: who sent it, when, and the (still unparsed) payload."""

    key_id: int
    sender_id: int
    epoch: int
    seq: int
    t_send_ms: int
    payload: bytes


class Sealer:
    """Signs outgoing payloads for one sender. The epoch is random per process start, so
    receivers can tell a reboot (sequence restarts) from a replay."""

    def __init__(self, key: bytes, *, key_id: int, sender_id: int, epoch: int | None = None,
                 clock_ms: Callable[[], int] = wall_clock_ms) -> None:
        self._key = key
        self.key_id = key_id
        self.sender_id = sender_id
        self.epoch = secrets.randbits(32) if epoch is None else epoch
        self.seq = 0
        self._clock_ms = clock_ms

    def seal(self, payload: bytes) -> bytes:
        if self.seq >= MAX_SEQ:  # sequence space used up: start a new epoch, as a reboot would
            self.epoch = (self.epoch + 1 + secrets.randbelow(0xFFFFFFFF)) & 0xFFFFFFFF
            self.seq = 0
        self.seq += 1
        header = HEADER.pack(MAGIC, VERSION, 0, self.key_id, self.sender_id, self.epoch,
                             self.seq, self._clock_ms(), len(payload))
        body = header + payload
        return body + hmac.digest(self._key, body, hashlib.sha256)


@dataclass(slots=True)
class _SenderState:
    epoch: int
    highest: int
    seen_bits: int  # bit i set: sequence number highest - i was accepted
    retired: deque[int] = field(default_factory=lambda: deque(maxlen=RETIRED_EPOCHS_KEPT))


class Opener:
    """Verifies frames from many senders.

    ``reorder_window`` = 0 (default) accepts only strictly increasing sequence numbers,
    the latest-value rule for a state stream on an ordered link; a window of N > 0 accepts
    out-of-order frames up to N behind the newest, each once (IPsec-style bitmap), for
    datagram links. ``key_senders`` optionally restricts which sender ids may use a key.
    """

    def __init__(self, keys: Mapping[int, bytes], *, max_age_ms: int = 1000,
                 max_future_ms: int = 100, reorder_window: int = 0,
                 key_senders: Mapping[int, frozenset[int]] | None = None,
                 clock_ms: Callable[[], int] = wall_clock_ms) -> None:
        if not 0 <= reorder_window <= 1024:
            raise ValueError("reorder_window must be in 0..1024")
        self._keys = dict(keys)
        self._key_senders = dict(key_senders or {})
        self.max_age_ms = max_age_ms
        self.max_future_ms = max_future_ms
        self.reorder_window = reorder_window
        self._clock_ms = clock_ms
        self._senders: dict[int, _SenderState] = {}

    def open(self, frame: bytes) -> Opened:
        opened = self.authenticate(frame)
        self._check_fresh(opened)
        self._accept_sequence(opened)
        return opened

    def authenticate(self, frame: bytes) -> Opened:
        """Header and tag checks only: no freshness or replay state is read or changed."""
        if len(frame) < OVERHEAD:
            raise MalformedEnvelope(f"frame of {len(frame)} bytes is shorter than the envelope")
        magic, version, flags, key_id, sender_id, epoch, seq, t_send, length = \
            HEADER.unpack_from(frame)
        if magic != MAGIC or version != VERSION or flags != 0:
            raise MalformedEnvelope("bad magic, version or flags")
        if length != len(frame) - OVERHEAD:
            raise MalformedEnvelope("length field disagrees with the frame size")
        key = self._keys.get(key_id)
        allowed = self._key_senders.get(key_id)
        if key is None or (allowed is not None and sender_id not in allowed):
            raise UnknownKey(f"key id {key_id} is not accepted for sender {sender_id}")
        body = frame[:-TAG_SIZE]
        if not hmac.compare_digest(hmac.digest(key, body, hashlib.sha256), frame[-TAG_SIZE:]):
            raise ForgedMessage("HMAC tag mismatch")
        return Opened(key_id, sender_id, epoch, seq, t_send, body[HEADER.size:])

    def _check_fresh(self, opened: Opened) -> None:
        age = self._clock_ms() - opened.t_send_ms
        if age > self.max_age_ms:
            raise StaleMessage(f"message is {age} ms old (limit {self.max_age_ms} ms)")
        if -age > self.max_future_ms:
            raise StaleMessage(f"message is stamped {-age} ms in the future")

    def _accept_sequence(self, opened: Opened) -> None:
        state = self._senders.get(opened.sender_id)
        if state is None:
            self._senders[opened.sender_id] = _SenderState(opened.epoch, opened.seq, 1)
            return
        if opened.epoch != state.epoch:
            # Authentic and fresh, so a genuine reboot unless the epoch was seen before.
            if opened.epoch in state.retired:
                raise ReplayedMessage(f"epoch {opened.epoch} of sender {opened.sender_id} "
                                      "was retired")
            state.retired.append(state.epoch)
            state.epoch, state.highest, state.seen_bits = opened.epoch, opened.seq, 1
            return
        # Constant time and memory whatever the jump: the bitmap never holds more than
        # ``width`` bits, and a jump of ``width`` or more simply starts a fresh window.
        width = max(self.reorder_window, 1)
        behind = state.highest - opened.seq
        if behind < 0:
            ahead = -behind
            state.seen_bits = (1 if ahead >= width else
                               ((state.seen_bits << ahead) | 1) & ((1 << width) - 1))
            state.highest = opened.seq
            return
        if behind >= width or state.seen_bits >> behind & 1:
            raise ReplayedMessage(f"sequence {opened.seq} from sender {opened.sender_id} is a "
                                  f"replay or out of order (newest {state.highest})")
        state.seen_bits |= 1 << behind
