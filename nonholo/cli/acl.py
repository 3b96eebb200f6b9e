"""``nonholo acl``: FIPA-ACL codec, keys, benchmark and fuzz run of the communication layer.

Exit codes: 0 ok; 1 the input was read but is not a valid message (parse/encode error), a
failed benchmark, or a fuzz run that found failures; 2 bad usage or unreadable input.
Every error is one line on stderr, never a traceback.
"""
from __future__ import annotations

import argparse
import json
import re
import sys

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK

DEFAULT_MAX_DEPTH = 32
DEFAULT_MAX_SIZE = 64 * 1024
# The JSON form of a message is longer than its ACL text (escapes): allow this factor.
JSON_SIZE_FACTOR = 8
MAX_FUZZ_SECONDS = 7 * 24 * 3600
_ASCII_INTEGER = re.compile(r"[+-]?[0-9]{1,12}")


class _BadInput(ValueError):
    """A command-line value outside what the command accepts (exit 2)."""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "acl", help="FIPA-ACL messages: parse, encode, keygen, bench, fuzz",
        description="FIPA-ACL string codec (SC00070I), HMAC keys, a benchmark and a fuzz "
        "run of the communication layer. See docs/comm.md.")
    commands = parser.add_subparsers(dest="acl_command", metavar="ACTION", required=True)

    parse = commands.add_parser("parse", help="ACL string -> JSON",
                                description="Parse one ACL message and print it as JSON. On "
                                "error print {\"error\", \"offset\"} and exit 1. At most "
                                "--max-size bytes are read.")
    parse.add_argument("file", nargs="?", default="-", help="input file, or - for stdin")
    parse.add_argument("--max-depth", default=str(DEFAULT_MAX_DEPTH), metavar="N",
                       help=f"nesting limit, 1..200 (default {DEFAULT_MAX_DEPTH})")
    parse.add_argument("--max-size", default=str(DEFAULT_MAX_SIZE), metavar="BYTES",
                       help=f"size limit in bytes, 1..16777216 (default {DEFAULT_MAX_SIZE})")
    parse.set_defaults(handler=_parse)

    encode = commands.add_parser("encode", help="JSON -> ACL string",
                                 description="Read the JSON form of a message (as printed "
                                 "by `nonholo acl parse`) and print the ACL string.")
    encode.add_argument("file", nargs="?", default="-", help="input file, or - for stdin")
    encode.add_argument("--max-size", default=str(DEFAULT_MAX_SIZE), metavar="BYTES",
                        help=f"size limit of the ACL output in bytes, 1..16777216 (default "
                        f"{DEFAULT_MAX_SIZE}); the JSON input may be {JSON_SIZE_FACTOR} "
                        "times as long")
    encode.set_defaults(handler=_encode)

    keygen = commands.add_parser("keygen", help="create a 0600 HMAC key file",
                                 description="Write random HMAC-SHA256 keys, one line "
                                 "'<key-id>:<hex>' per id, to a new file with mode 0600.")
    keygen.add_argument("path", help="file to create (must not exist)")
    keygen.add_argument("--ids", nargs="+", default=["0"], metavar="ID",
                        help="key ids to generate, 0..65535 in ASCII digits (default: 0)")
    keygen.set_defaults(handler=_keygen)

    bench = commands.add_parser("bench", help="measure codec, envelope and transports",
                                description="Print encode/decode/sign/verify microseconds "
                                "per message and loopback round-trip and 1->7 fan-out "
                                "latency (TCP, and Zenoh if installed).")
    bench.add_argument("--json", action="store_true", help="print JSON instead of a table")
    bench.add_argument("--codec-only", action="store_true", help="skip the network part")
    bench.add_argument("--rounds", default="2000", metavar="N",
                       help="round trips, 1..1000000 (default 2000)")
    bench.add_argument("--fanout-count", default="500", metavar="N",
                       help="messages in the 100 Hz fan-out run, 1..100000 (default 500)")
    bench.set_defaults(handler=_bench)

    fuzz = commands.add_parser("fuzz", help="fuzz every decoder of foreign bytes",
                               description="Feed mutated and random inputs to the ACL "
                               "decoder, the envelope, the stream hello and the framing for "
                               "a fixed time; print inputs/s, failures and the slowest "
                               "input. Exit 1 if any input broke a property.")
    fuzz.add_argument("--seconds", default="10", metavar="S",
                      help=f"how long to run, 1..{MAX_FUZZ_SECONDS} (default 10)")
    fuzz.add_argument("--seed", default="0", metavar="N", help="random seed (default 0)")
    fuzz.add_argument("--json", action="store_true", help="print JSON instead of text")
    fuzz.set_defaults(handler=_fuzz)


def _integer(text: str, option: str, low: int, high: int) -> int:
    """``text`` as an integer in low..high written in ASCII digits (int() would also take
    '1_0', spaces and non-ASCII digits); _BadInput otherwise."""
    if not _ASCII_INTEGER.fullmatch(text) or not low <= int(text) <= high:
        raise _BadInput(f"{option} must be an integer in {low}..{high}, got {text[:40]!r}")
    return int(text)


def _read_input(path: str, command: str, limit: int) -> bytes | None:
    """At most ``limit + 1`` bytes of ``path`` (``-``: standard input), so that an endless
    or huge input is cut off at once; None after a one-line error."""
    try:
        if path == "-":
            return sys.stdin.buffer.read(limit + 1)
        with open(path, "rb") as handle:
            return handle.read(limit + 1)
    except OSError as exc:
        print(f"nonholo acl {command}: cannot read {path}: {exc.strerror}", file=sys.stderr)
        return None


def _bad_input(command: str, error: Exception) -> int:
    print(f"nonholo acl {command}: error: {error}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _parse(args: argparse.Namespace) -> int:
    from nonholo.comm.acl_decode import decode
    from nonholo.comm.acl_lexical import HARD_MAX_DEPTH, HARD_MAX_SIZE
    from nonholo.comm.errors import ACLParseError
    from nonholo.comm.json_form import message_to_json

    try:
        max_depth = _integer(args.max_depth, "--max-depth", 1, HARD_MAX_DEPTH)
        max_size = _integer(args.max_size, "--max-size", 1, HARD_MAX_SIZE)
    except _BadInput as exc:
        return _bad_input("parse", exc)
    data = _read_input(args.file, "parse", max_size)
    if data is None:
        return EXIT_BAD_INPUT
    try:
        if len(data) > max_size:
            raise ACLParseError(f"input is longer than the {max_size}-byte limit", max_size)
        message = decode(data, max_depth=max_depth, max_size=max_size)
    except ACLParseError as exc:
        print(json.dumps({"error": exc.reason, "offset": exc.offset}))
        print(f"nonholo acl parse: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    print(json.dumps(message_to_json(message), ensure_ascii=False, indent=2))
    return EXIT_OK


def _encode(args: argparse.Namespace) -> int:
    from nonholo.comm.acl_encode import encode
    from nonholo.comm.acl_lexical import HARD_MAX_SIZE
    from nonholo.comm.errors import CommError
    from nonholo.comm.json_form import message_from_json

    try:
        max_size = _integer(args.max_size, "--max-size", 1, HARD_MAX_SIZE)
    except _BadInput as exc:
        return _bad_input("encode", exc)
    limit = JSON_SIZE_FACTOR * max_size
    data = _read_input(args.file, "encode", limit)
    if data is None:
        return EXIT_BAD_INPUT
    try:
        if len(data) > limit:
            raise ValueError(f"input is longer than {limit} bytes ({JSON_SIZE_FACTOR} x "
                             "--max-size)")
        message = message_from_json(json.loads(data))
        text = encode(message, max_size=max_size)
    except (CommError, ValueError, RecursionError) as exc:
        print(f"nonholo acl encode: {str(exc)[:500]}", file=sys.stderr)
        return EXIT_FAILURE
    sys.stdout.buffer.write(text + b"\n")
    return EXIT_OK


def _keygen(args: argparse.Namespace) -> int:
    from nonholo.comm.keys import generate_key_line, parse_key_id, write_key_file

    try:
        ids = [parse_key_id(text) for text in args.ids]
    except ValueError as exc:
        return _bad_input("keygen", f"--ids: {exc}")
    if len(set(ids)) != len(ids):
        return _bad_input("keygen", "--ids lists a key id twice")
    try:
        write_key_file(args.path, [generate_key_line(key_id) for key_id in ids])
    except OSError as exc:
        return _bad_input("keygen", f"cannot create {args.path}: {exc.strerror}")
    print(f"wrote {len(ids)} key(s) to {args.path} (mode 0600)")
    return EXIT_OK


def _bench(args: argparse.Namespace) -> int:
    from nonholo.comm import bench

    try:
        rounds = _integer(args.rounds, "--rounds", 1, 1_000_000)
        fanout_count = _integer(args.fanout_count, "--fanout-count", 1, 100_000)
    except _BadInput as exc:
        return _bad_input("bench", exc)
    try:
        result = bench.run(rounds=rounds, fanout_count=fanout_count,
                           network=not args.codec_only)
    except (OSError, TimeoutError) as exc:
        print(f"nonholo acl bench: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    print(json.dumps(result, indent=2) if args.json else bench.format_report(result))
    return EXIT_OK


def _fuzz(args: argparse.Namespace) -> int:
    from nonholo.comm import fuzz

    try:
        seconds = _integer(args.seconds, "--seconds", 1, MAX_FUZZ_SECONDS)
        seed = _integer(args.seed, "--seed", 0, 2**32 - 1)
    except _BadInput as exc:
        return _bad_input("fuzz", exc)
    progress = None if args.json else (
        lambda report: print(f"... {report.seconds:.0f} s, {report.total_inputs} inputs, "
                             f"{report.total_failures} failures", file=sys.stderr))
    report = fuzz.run(seconds, seed, on_progress=progress)
    print(json.dumps(report.as_json(), indent=2) if args.json else fuzz.format_report(report))
    return EXIT_FAILURE if report.total_failures else EXIT_OK
