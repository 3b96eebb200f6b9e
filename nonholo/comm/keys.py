"""HMAC keys: loaded from a file only other users cannot read (mode 0600) or from an
environment variable, never from the repository.

Format (file or variable): one key per line, ``<key-id>:<hex secret>``; ``#`` comments and
blank lines are ignored. Key ids are 0..65535; secrets must be at least 16 bytes.
"""
from __future__ import annotations

import os
import secrets
import stat
from pathlib import Path
from typing import Mapping

from nonholo.comm.errors import KeyFileError

DEFAULT_KEY_ENV = "NONHOLO_ACL_KEYS"
MIN_SECRET_BYTES = 16


def parse_keys(text: str) -> dict[int, bytes]:
    keys: dict[int, bytes] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        key_id_text, sep, hex_secret = line.partition(":")
        try:
            key_id = int(key_id_text)
            secret = bytes.fromhex(hex_secret.strip())
        except ValueError:
            raise KeyFileError(f"line {number}: expected <key-id>:<hex secret>") from None
        if not sep or not 0 <= key_id <= 0xFFFF:
            raise KeyFileError(f"line {number}: key id must be 0..65535")
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
        return parse_keys(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise KeyFileError(f"cannot read key file {path}: {exc.strerror}") from None


def load_key_env(variable: str = DEFAULT_KEY_ENV,
                 environ: Mapping[str, str] | None = None) -> dict[int, bytes]:
    value = (os.environ if environ is None else environ).get(variable)
    if not value:
        raise KeyFileError(f"environment variable {variable} is not set")
    return parse_keys(value.replace(";", "\n"))


def generate_key_line(key_id: int, size: int = 32) -> str:
    if not 0 <= key_id <= 0xFFFF:
        raise ValueError("key id must be 0..65535")
    return f"{key_id}:{secrets.token_hex(size)}"


def write_key_file(path: str | os.PathLike[str], lines: list[str]) -> None:
    """Create ``path`` with mode 0600 from the start (no window where others can read it)."""
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(descriptor, "w", encoding="utf-8") as handle:
        handle.write("\n".join(lines) + "\n")
