"""A fleet's keys: one per robot, used to seal its envelopes (the sender id bound to its
name) and to prove its name in the stream hello. In a key file (``nonholo.comm.keys``
format, mode 0600) robot i of the scenario (0-based, in file order) has key id i + 1.

The hello and the envelope use the key under different labels (``hello`` and ``envelope``
tags), so a tag of one can never pass for the other.
"""
from __future__ import annotations

import secrets

from nonholo.comm.channel import SecureChannel
from nonholo.comm.envelope import Opener, Sealer
from nonholo.comm.errors import KeyFileError
from nonholo.comm.keys import generate_key_line, load_key_file, write_key_file
from nonholo.errors import NonholoInputError

KEY_BYTES = 32
MAX_AGE_MS = 60_000


def fleet_keys(names) -> dict[str, tuple[int, int, bytes]]:
    """Fresh keys: per robot (sender id, key id, secret) (spec comm.md §3.1)."""
    return {name: (i + 1, i + 1, secrets.token_bytes(KEY_BYTES)) for i, name in enumerate(names)}


def write_fleet_key_file(path, names) -> None:
    """A new key file (mode 0600 from the start) with a fresh key per robot."""
    write_key_file(path, [generate_key_line(i + 1, KEY_BYTES) for i in range(len(names))])


def keys_from_file(path, names, needed) -> dict[str, tuple[int, int, bytes]]:
    """The keys of the robots ``needed`` (names) from a key file; NonholoInputError naming
    the first robot whose key id is missing."""
    try:
        keys = load_key_file(path)
    except KeyFileError as exc:
        raise NonholoInputError(f"keys: {exc}") from None
    index = {name: i + 1 for i, name in enumerate(names)}
    found = {}
    for name in needed:
        if index[name] not in keys:
            raise NonholoInputError(f"{path}: no key id {index[name]} (robot {name!r}, number {index[name]} "
                                    "in the scenario)")
        found[name] = (index[name], index[name], keys[index[name]])
    return found


def robot_channel(name: str, peers, keys: dict) -> SecureChannel:
    """Seals with ``name``'s key; opens only ``peers``' frames, each bound to its name."""
    sender_id, key_id, secret = keys[name]
    opener = Opener({keys[p][1]: keys[p][2] for p in peers},
                    key_senders={keys[p][1]: frozenset({keys[p][0]}) for p in peers}, max_age_ms=MAX_AGE_MS)
    return SecureChannel(Sealer(secret, key_id=key_id, sender_id=sender_id), opener,
                         senders={keys[p][0]: p for p in peers})
