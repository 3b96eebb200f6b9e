"""``nonholo acl``: FIPA-ACL codec, keys and benchmark of the communication layer.

Exit codes: 0 ok; 1 the input was read but is not a valid message (parse/encode error);
2 bad usage or unreadable input file.
"""
from __future__ import annotations

import argparse
import json
import sys

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "acl", help="FIPA-ACL messages: parse, encode, keygen, bench",
        description="FIPA-ACL string codec (SC00070I), HMAC keys and a benchmark of the "
        "communication layer. See docs/comm.md.")
    commands = parser.add_subparsers(dest="acl_command", metavar="ACTION", required=True)

    parse = commands.add_parser("parse", help="ACL string -> JSON",
                                description="Parse one ACL message and print it as JSON. On "
                                "error print {\"error\", \"offset\"} and exit 1.")
    parse.add_argument("file", nargs="?", default="-", help="input file, or - for stdin")
    parse.add_argument("--max-depth", type=int, default=32, help="nesting limit (default 32)")
    parse.add_argument("--max-size", type=int, default=64 * 1024,
                       help="size limit in bytes (default 65536)")
    parse.set_defaults(handler=_parse)

    encode = commands.add_parser("encode", help="JSON -> ACL string",
                                 description="Read the JSON form of a message (as printed "
                                 "by `nonholo acl parse`) and print the ACL string.")
    encode.add_argument("file", nargs="?", default="-", help="input file, or - for stdin")
    encode.set_defaults(handler=_encode)

    keygen = commands.add_parser("keygen", help="create a 0600 HMAC key file",
                                 description="Write random HMAC-SHA256 keys, one line "
                                 "'<key-id>:<hex>' per id, to a new file with mode 0600.")
    keygen.add_argument("path", help="file to create (must not exist)")
    keygen.add_argument("--ids", type=int, nargs="+", default=[0],
                        help="key ids to generate (default: 0)")
    keygen.set_defaults(handler=_keygen)

    bench = commands.add_parser("bench", help="measure codec, envelope and transports",
                                description="Print encode/decode/sign/verify microseconds "
                                "per message and loopback round-trip and 1->7 fan-out "
                                "latency (TCP, and Zenoh if installed).")
    bench.add_argument("--json", action="store_true", help="print JSON instead of a table")
    bench.add_argument("--codec-only", action="store_true", help="skip the network part")
    bench.add_argument("--rounds", type=int, default=2000, help="round trips (default 2000)")
    bench.add_argument("--fanout-count", type=int, default=500,
                       help="messages in the 100 Hz fan-out run (default 500)")
    bench.set_defaults(handler=_bench)


def _read_input(path: str, command: str) -> bytes | None:
    """The bytes of ``path`` (``-``: standard input), or None after a one-line error."""
    if path == "-":
        return sys.stdin.buffer.read()
    try:
        with open(path, "rb") as handle:
            return handle.read()
    except OSError as exc:
        print(f"nonholo acl {command}: cannot read {path}: {exc.strerror}", file=sys.stderr)
        return None


def _parse(args: argparse.Namespace) -> int:
    from nonholo.comm.acl_decode import decode
    from nonholo.comm.errors import ACLParseError
    from nonholo.comm.json_form import message_to_json

    data = _read_input(args.file, "parse")
    if data is None:
        return EXIT_BAD_INPUT
    try:
        message = decode(data, max_depth=args.max_depth, max_size=args.max_size)
    except ACLParseError as exc:
        print(json.dumps({"error": exc.reason, "offset": exc.offset}))
        print(f"nonholo acl parse: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except ValueError as exc:  # an out-of-range --max-depth
        print(f"nonholo acl parse: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(json.dumps(message_to_json(message), ensure_ascii=False, indent=2))
    return EXIT_OK


def _encode(args: argparse.Namespace) -> int:
    from nonholo.comm.acl_encode import encode
    from nonholo.comm.errors import CommError
    from nonholo.comm.json_form import message_from_json

    data = _read_input(args.file, "encode")
    if data is None:
        return EXIT_BAD_INPUT
    try:
        message = message_from_json(json.loads(data))
        text = encode(message)
    except (CommError, ValueError, RecursionError) as exc:
        print(f"nonholo acl encode: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    sys.stdout.buffer.write(text + b"\n")
    return EXIT_OK


def _keygen(args: argparse.Namespace) -> int:
    from nonholo.comm.keys import generate_key_line, write_key_file

    try:
        write_key_file(args.path, [generate_key_line(key_id) for key_id in args.ids])
    except (OSError, ValueError) as exc:
        print(f"nonholo acl keygen: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(f"wrote {len(args.ids)} key(s) to {args.path} (mode 0600)")
    return EXIT_OK


def _bench(args: argparse.Namespace) -> int:
    from nonholo.comm import bench

    try:
        result = bench.run(rounds=args.rounds, fanout_count=args.fanout_count,
                           network=not args.codec_only)
    except (OSError, TimeoutError) as exc:
        print(f"nonholo acl bench: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    print(json.dumps(result, indent=2) if args.json else bench.format_report(result))
    return EXIT_OK
