"""HMAC keys: loaded from a file only other users cannot read (mode 0600) or from an
environment variable, never from the repository.

Format (file or variable): one key per line, ``<key-id>:<hex secret>``; ``#`` comments and
blank lines are ignored. Key ids are 0..65535; secrets must be at least 16 bytes.
"""
from __future__ import annotations

import os
import re
import secrets
import stat
from pathlib import Path
from typing import Mapping

from nonholo.comm.errors import KeyFileError

DEFAULT_KEY_ENV = "NONHOLO_ACL_KEYS"
MIN_SECRET_BYTES = 16
MAX_KEY_ID = 0xFFFF
# ASCII digits only: int() would also take "1_0" (as 10), " 1" and non-ASCII digits.
_KEY_ID = re.compile(r"[0-9]{1,5}")
_HEX_SECRET = re.compile(r"(?:[0-9A-Fa-f]{2})+")
MAX_KEY_TEXT = 1 << 20  # a key file or variable larger than 1 MiB is not a key list


def parse_key_id(text: str) -> int:
    """A key id written as 1 to 5 ASCII digits with a value in 0..65535; ValueError otherwise."""
    if not _KEY_ID.fullmatch(text) or int(text) > MAX_KEY_ID:
        raise ValueError(f"key id must be an integer 0..{MAX_KEY_ID} in ASCII digits, "
                         f"got {text[:20]!r}")
    return int(text)


def parse_keys(text: str) -> dict[int, bytes]:
    if len(text) > MAX_KEY_TEXT:
        raise KeyFileError(f"key text is longer than {MAX_KEY_TEXT} characters")
    keys: dict[int, bytes] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        key_id_text, sep, hex_secret = line.partition(":")
        hex_secret = hex_secret.strip()
        if not sep or not _HEX_SECRET.fullmatch(hex_secret):
            raise KeyFileError(f"line {number}: expected <key-id>:<hex secret>")
        try:
            key_id = parse_key_id(key_id_text.strip())
        except ValueError as exc:
            raise KeyFileError(f"line {number}: {exc}") from None
        secret = bytes.fromhex(hex_secret)
        if len(secret) < MIN_SECRET_BYTES:
            raise KeyFileError(f"line {number}: secret shorter than {MIN_SECRET_BYTES} bytes")
        if key_id in keys:
            raise KeyFileError(f"line {number}: key id {key_id} defined twice")
        keys[key_id] = secret
    if not keys:
        raise KeyFileError("no keys found")
    return keys


def load_key_file(path: str | os.PathLike[str]) -> dict[int, bytes]:
    """Keys from ``path``; refuses a file that group or others may read or write."""
    path = Path(path)
    try:
        mode = path.stat().st_mode
        if stat.S_IMODE(mode) & 0o077:
            raise KeyFileError(f"{path} has mode {stat.S_IMODE(mode):04o}; run chmod 600 on it")
        with path.open("rb") as handle:
            data = handle.read(MAX_KEY_TEXT + 1)
    except OSError as exc:
        raise KeyFileError(f"cannot read key file {path}: {exc.strerror}") from None
    if len(data) > MAX_KEY_TEXT:
        raise KeyFileError(f"{path} is larger than {MAX_KEY_TEXT} bytes; not a key file")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise KeyFileError(f"{path} is not UTF-8 text (byte {exc.start})") from None
    return parse_keys(text)


def load_key_env(variable: str = DEFAULT_KEY_ENV,
                 environ: Mapping[str, str] | None = None) -> dict[int, bytes]:
    value = (os.environ if environ is None else environ).get(variable)
    if not value:
        raise KeyFileError(f"environment variable {variable} is not set")
    return parse_keys(value.replace(";", "\n"))


def generate_key_line(key_id: int, size: int = 32) -> str:
    if isinstance(key_id, bool) or not isinstance(key_id, int) or not 0 <= key_id <= MAX_KEY_ID:
        raise ValueError(f"key id must be an integer 0..{MAX_KEY_ID}")
    return f"{key_id}:{secrets.token_hex(size)}"


def write_key_file(path: str | os.PathLike[str], lines: list[str]) -> None:
    """Create ``path`` with mode 0600 from the start (no window where others can read it)."""
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(descriptor, "w", encoding="utf-8") as handle:
        handle.write("\n".join(lines) + "\n")
