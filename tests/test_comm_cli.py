"""``nonholo acl``: parse/encode/keygen/bench through the CLI entry point."""
from __future__ import annotations

import io
import json
import os
import sys

import pytest

from nonholo.cli import main


def run_cli(argv, stdin: bytes = b"", monkeypatch=None, capsys=None):
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(stdin)))
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


INFORM = b'(inform :sender (agent-identifier :name a@p) :content "hi" :X-seq 3)'


def test_parse_prints_json(monkeypatch, capsys):
    code, out, _ = run_cli(["acl", "parse", "-"], INFORM, monkeypatch, capsys)
    assert code == 0
    assert json.loads(out) == {"performative": "inform", "sender": {"name": "a@p"},
                               "content": "hi", "X-seq": 3}


def test_parse_error_has_offset_and_exit_1(monkeypatch, capsys):
    code, out, err = run_cli(["acl", "parse"], b"(infrom)", monkeypatch, capsys)
    assert code == 1
    assert json.loads(out)["offset"] == 1 and "byte 1" in err


def test_parse_missing_file_is_bad_input(monkeypatch, capsys, tmp_path):
    code, _, _ = run_cli(["acl", "parse", str(tmp_path / "nope")], b"", monkeypatch, capsys)
    assert code == 2


def test_encode_round_trip(monkeypatch, capsys):
    _, parsed, _ = run_cli(["acl", "parse"], INFORM, monkeypatch, capsys)
    code, acl, _ = run_cli(["acl", "encode", "-"], parsed.encode(), monkeypatch, capsys)
    assert code == 0 and acl.startswith("(inform\n")
    _, again, _ = run_cli(["acl", "parse"], acl.encode(), monkeypatch, capsys)
    assert json.loads(again) == json.loads(parsed)


@pytest.mark.parametrize("bad", [b"not json", b'{"performative": "nope"}', b"[]",
                                 b'{"performative": "inform", "color": 1}'])
def test_encode_bad_json_exit_1(monkeypatch, capsys, bad):
    code, _, err = run_cli(["acl", "encode"], bad, monkeypatch, capsys)
    assert code == 1 and err


def test_keygen_creates_0600_file(monkeypatch, capsys, tmp_path):
    path = tmp_path / "fleet.keys"
    code, _, _ = run_cli(["acl", "keygen", str(path), "--ids", "0", "1"], b"", monkeypatch, capsys)
    assert code == 0 and os.stat(path).st_mode & 0o777 == 0o600
    code, _, _ = run_cli(["acl", "keygen", str(path)], b"", monkeypatch, capsys)
    assert code == 2  # refuses to overwrite


def test_bench_codec_only_json(monkeypatch, capsys):
    code, out, _ = run_cli(["acl", "bench", "--codec-only", "--json"], b"", monkeypatch, capsys)
    figures = json.loads(out)["codec"]["inform-group"]
    assert code == 0 and {"encode_us", "decode_us", "sign_us", "verify_us"} <= set(figures)


def test_help_exits_0(capsys):
    with pytest.raises(SystemExit) as info:
        main(["acl", "--help"])
    assert info.value.code == 0
