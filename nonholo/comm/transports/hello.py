"""The authenticated hello of the stream transports (TCP, Bluetooth RFCOMM).

Before any name or traffic crosses a stream, the connecting peer proves that it holds a
link key the hub knows, then the hub proves it holds the same key::

    hub  -> peer  CHALLENGE  "NHH1" 01 | hub epoch u32 | hub nonce (32 bytes)
    peer -> hub   HELLO      "NHH1" 02 | key id u16 | peer nonce (32) | name length u8 | name
                             | tag = HMAC-SHA256(key, "peer" | CHALLENGE | HELLO before the tag)
    hub  -> peer  WELCOME    "NHH1" 03 | name length u8 | hub name | tag
              or  REFUSED    "NHH1" 04 | reason length u8 | reason | tag
                             tag = HMAC-SHA256(key, "hub" | CHALLENGE | HELLO | reply before the tag)

* A client without the key receives only the challenge (random bytes and the hub's
  epoch): no hub name, no peer list, no traffic. A failed proof is answered by closing.
* The peer's tag covers the hub's fresh nonce, so a recorded HELLO fails on every later
  connection (no replay); the hub's tag covers the peer's nonce and the whole exchange.
* The two tags carry different labels, so one side's tag never passes as the other's.
* Both names and the hub epoch are inside the tags. The epoch is random per hub start
  (like the envelope's), so a peer can tell a restarted hub.

The key is the pairwise link key of the peer: ``LinkAuth.peer_key_ids`` on the hub says
which key id each peer name must use (with per-sender keys, the peer's own key id), so
one follower's key cannot open a link under another follower's name.
"""
from __future__ import annotations

import hashlib
import hmac
import secrets
import struct
from dataclasses import dataclass, field
from typing import Mapping

from nonholo.comm.keys import MAX_KEY_ID, MIN_SECRET_BYTES

MAGIC = b"NHH1"
CHALLENGE, HELLO, WELCOME, REFUSED = 1, 2, 3, 4
NONCE_SIZE = 32
TAG_SIZE = 32
MAX_NAME_BYTES = 255
_HEAD = struct.Struct(">4sB")
_CHALLENGE = struct.Struct(">4sBI32s")
_HELLO_HEAD = struct.Struct(">4sBH32sB")
_PEER_LABEL = b"nonholo hello peer\x00"
_HUB_LABEL = b"nonholo hello hub\x00"
# Largest hello message: the HELLO with a 255-byte name (the replies are shorter).
MAX_HELLO_BYTES = _HELLO_HEAD.size + MAX_NAME_BYTES + TAG_SIZE


class HelloFailed(ConnectionError):
    """The stream hello did not complete: wrong or unknown key, a forged, replayed or
    malformed hello message, a timeout, or the other end closed."""


class HelloRefused(HelloFailed):
    """The hub verified the key but refused the link (name already connected, hub full);
    ``reason`` says which."""

    def __init__(self, reason: str) -> None:
        super().__init__(f"the hub refused the link: {reason}")
        self.reason = reason


@dataclass(frozen=True)
class LinkAuth:
    """Link keys for the stream hello.

    ``keys``: key id -> secret (at least 16 bytes), e.g. from ``nonholo.comm.keys``.
    ``key_id``: the key this end presents when it connects (required on a peer).
    ``peer_key_ids``: on a hub, the only key id each peer name may use; a name not listed
    is refused. None lets any key in ``keys`` open a link under any name (a fleet-wide
    key: then any key holder can take any free name).
    """

    keys: Mapping[int, bytes] = field(repr=False)
    key_id: int | None = None
    peer_key_ids: Mapping[str, int] | None = None
    _frozen_keys: dict[int, bytes] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        keys = dict(self.keys)
        if not keys:
            raise ValueError("LinkAuth needs at least one key")
        for key_id, secret in keys.items():
            if isinstance(key_id, bool) or not isinstance(key_id, int) \
                    or not 0 <= key_id <= MAX_KEY_ID:
                raise ValueError(f"key id {key_id!r} outside 0..{MAX_KEY_ID}")
            if not isinstance(secret, (bytes, bytearray)) or len(secret) < MIN_SECRET_BYTES:
                raise ValueError(f"key {key_id}: secret must be at least {MIN_SECRET_BYTES} bytes")
        if self.key_id is not None and self.key_id not in keys:
            raise ValueError(f"key id {self.key_id} is not among the keys")
        if self.peer_key_ids is not None:
            for name, key_id in self.peer_key_ids.items():
                if key_id not in keys:
                    raise ValueError(f"peer {name!r}: key id {key_id} is not among the keys")
            object.__setattr__(self, "peer_key_ids", dict(self.peer_key_ids))
        object.__setattr__(self, "_frozen_keys", {k: bytes(v) for k, v in keys.items()})

    def presented_key(self) -> tuple[int, bytes]:
        if self.key_id is None:
            raise ValueError("a connecting peer needs LinkAuth(key_id=...)")
        return self.key_id, self._frozen_keys[self.key_id]

    def key_for(self, name: str, key_id: int) -> bytes | None:
        """The secret ``name`` may prove itself with under ``key_id``, or None."""
        if self.peer_key_ids is not None and self.peer_key_ids.get(name) != key_id:
            return None
        return self._frozen_keys.get(key_id)


def check_name(name: str) -> bytes:
    """The UTF-8 bytes of an endpoint name; ValueError unless 1..255 bytes of valid text."""
    try:
        raw = name.encode("utf-8")
    except (UnicodeEncodeError, AttributeError):
        raise ValueError("endpoint name must be text") from None
    if not 0 < len(raw) <= MAX_NAME_BYTES:
        raise ValueError(f"endpoint name must be 1..{MAX_NAME_BYTES} UTF-8 bytes")
    return raw


def _tag(key: bytes, label: bytes, *parts: bytes) -> bytes:
    return hmac.digest(key, label + b"".join(parts), hashlib.sha256)


def _short_text(kind: int, text: bytes) -> bytes:
    return _HEAD.pack(MAGIC, kind) + bytes([len(text)]) + text


def _read_short_text(message: bytes, kind: int) -> tuple[bytes, bytes]:
    """(text, tag) of a WELCOME or REFUSED; HelloFailed if malformed."""
    head = _HEAD.size
    if len(message) < head + 1 + TAG_SIZE or message[:head] != _HEAD.pack(MAGIC, kind):
        raise HelloFailed("malformed hello reply")
    length = message[head]
    if len(message) != head + 1 + length + TAG_SIZE:
        raise HelloFailed("malformed hello reply")
    return message[head + 1:head + 1 + length], message[-TAG_SIZE:]


class HubHello:
    """The hub's side of one hello: ``challenge`` to send, then ``check(hello)``."""

    def __init__(self, auth: LinkAuth, epoch: int) -> None:
        self._auth = auth
        self.challenge = _CHALLENGE.pack(MAGIC, CHALLENGE, epoch, secrets.token_bytes(NONCE_SIZE))

    def check(self, hello: bytes) -> "VerifiedPeer":
        """The peer's verified name; HelloFailed for anything else (the reason is for the
        hub's own log and counters: the peer is only disconnected)."""
        size = _HELLO_HEAD.size
        if len(hello) < size + 1 + TAG_SIZE:
            raise HelloFailed("hello too short")
        magic, kind, key_id, _nonce, length = _HELLO_HEAD.unpack_from(hello)
        if magic != MAGIC or kind != HELLO or length == 0 \
                or len(hello) != size + length + TAG_SIZE:
            raise HelloFailed("malformed hello")
        raw_name = hello[size:size + length]
        try:
            name = raw_name.decode("utf-8")
        except UnicodeDecodeError:
            raise HelloFailed("peer name is not UTF-8") from None
        key = self._auth.key_for(name, key_id)
        # Compute a tag even for an unknown key id, so timing does not tell which ids exist.
        expected = _tag(key or b"\x00" * MIN_SECRET_BYTES, _PEER_LABEL, self.challenge,
                        hello[:-TAG_SIZE])
        if not hmac.compare_digest(expected, hello[-TAG_SIZE:]) or key is None:
            raise HelloFailed("hello tag does not verify (wrong key, key id or name, or a replay)")
        return VerifiedPeer(name, key_id, key, self.challenge + hello)


@dataclass(frozen=True)
class VerifiedPeer:
    """A peer that proved its key; ``welcome``/``refusal`` build the hub's signed reply."""

    name: str
    key_id: int
    _key: bytes = field(repr=False)
    _transcript: bytes = field(repr=False)

    def welcome(self, hub_name: str) -> bytes:
        return self._signed(_short_text(WELCOME, check_name(hub_name)))

    def refusal(self, reason: str) -> bytes:
        return self._signed(_short_text(REFUSED, reason.encode("utf-8")[:MAX_NAME_BYTES]))

    def _signed(self, body: bytes) -> bytes:
        return body + _tag(self._key, _HUB_LABEL, self._transcript, body)


class PeerHello:
    """The connecting side of one hello: ``answer(challenge)``, then ``check_reply``."""

    def __init__(self, auth: LinkAuth, name: str) -> None:
        self._key_id, self._key = auth.presented_key()
        self._name = check_name(name)
        self._transcript = b""
        self.hub_epoch: int | None = None

    def answer(self, challenge: bytes) -> bytes:
        if len(challenge) != _CHALLENGE.size:
            raise HelloFailed("malformed hello challenge")
        magic, kind, epoch, _nonce = _CHALLENGE.unpack(challenge)
        if magic != MAGIC or kind != CHALLENGE:
            raise HelloFailed("malformed hello challenge (is this a nonholo hub?)")
        self.hub_epoch = epoch
        body = _HELLO_HEAD.pack(MAGIC, HELLO, self._key_id, secrets.token_bytes(NONCE_SIZE),
                                len(self._name)) + self._name
        hello = body + _tag(self._key, _PEER_LABEL, challenge, body)
        self._transcript = challenge + hello
        return hello

    def check_reply(self, reply: bytes) -> str:
        """The hub's name from a verified WELCOME; HelloRefused for a verified refusal,
        HelloFailed for anything else."""
        kind = reply[len(MAGIC)] if len(reply) > len(MAGIC) else -1
        if kind not in (WELCOME, REFUSED):
            raise HelloFailed("malformed hello reply")
        text, tag = _read_short_text(reply, kind)
        expected = _tag(self._key, _HUB_LABEL, self._transcript, reply[:-TAG_SIZE])
        if not hmac.compare_digest(expected, tag):
            raise HelloFailed("the hub's reply does not verify (it does not hold this key)")
        if kind == REFUSED:
            raise HelloRefused(text.decode("utf-8", "replace"))
        try:
            decoded = text.decode("utf-8")
        except UnicodeDecodeError:
            raise HelloFailed("hub name is not UTF-8") from None
        if not decoded:
            raise HelloFailed("empty hub name")
        return decoded
