"""``nonholo view SOURCE``: replay a recording or an --out directory in the browser."""
from __future__ import annotations

import argparse
import ipaddress
import sys
import time

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK

MAX_PORT = 65535


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "view", help="replay a recording (.mcap) or an --out directory in the browser",
        description="Serve a page that replays a run: robots' poses and trails, the reference path, formation "
                    "links with their errors, with a time slider, play/pause, zoom and follow-a-robot. SOURCE is "
                    "an MCAP file written with --record, or the --out directory of `nonholo run` (result.json "
                    "and trajectories.csv). The page is read-only, on 127.0.0.1 by default, and needs the random "
                    "token printed in its address. Ctrl-C stops it.",
        epilog="Exit codes: 0 ok, 1 the server could not start, 2 bad input.")
    parser.add_argument("source", help="a .mcap recording, or a directory written by nonholo run --out")
    add_server_arguments(parser)
    parser.set_defaults(handler=handle)


def add_server_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--port", type=int, default=0, metavar="N",
                        help="port to serve the page on (default: a free port chosen by the system)")
    parser.add_argument("--host", default="127.0.0.1", metavar="ADDRESS",
                        help="address to bind (default 127.0.0.1, loopback only; the token is still required)")
    parser.add_argument("--for", dest="serve_for", type=float, metavar="S",
                        help="stop serving after S seconds (default: until Ctrl-C)")


def check_server_arguments(args: argparse.Namespace) -> None:
    from nonholo.errors import NonholoInputError

    if not 0 <= args.port <= MAX_PORT:
        raise NonholoInputError(f"--port must be 0..{MAX_PORT}, got {args.port}")
    try:
        ipaddress.ip_address(args.host)
    except ValueError:
        raise NonholoInputError(f"--host must be an IP address such as 127.0.0.1, got {args.host!r}"[:200]) from None
    if args.serve_for is not None and not args.serve_for > 0:
        raise NonholoInputError(f"--for must be a positive number of seconds, got {args.serve_for}")


def start_server(page, feed, args: argparse.Namespace, prog: str, stream=None):
    """Start the page server and print its address (on ``stream``, default stdout); OSError
    with a one-line message when it cannot serve there."""
    from nonholo.view.server import ViewServer

    try:
        server = ViewServer(page, feed, host=args.host, port=args.port).start()
    except OSError as exc:
        raise OSError(f"cannot serve on {args.host}:{args.port}: {exc.strerror or exc}") from None
    if not ipaddress.ip_address(args.host).is_loopback:
        print(f"{prog}: serving beyond loopback on {args.host}: anyone who has the address can watch",
              file=sys.stderr)
    print(f"page: {server.url}", file=stream or sys.stdout, flush=True)
    return server


def serve_until_stopped(server, seconds: float | None) -> None:
    """Block until Ctrl-C or ``seconds``; ``server.stop()`` is called either way."""
    deadline = None if seconds is None else time.monotonic() + seconds
    try:
        while deadline is None or time.monotonic() < deadline:
            time.sleep(0.2 if deadline is None else max(0.0, min(0.2, deadline - time.monotonic())))
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()


def handle(args: argparse.Namespace) -> int:
    from pathlib import Path

    from nonholo.errors import NonholoInputError
    from nonholo.view import require

    source = Path(args.source)
    try:
        check_server_arguments(args)
        require("aiohttp")
        if source.is_dir():
            from nonholo.view.data import from_outdir

            replay = from_outdir(source)
        elif source.is_file():
            from nonholo.view.record import read_recording

            replay = read_recording(source)
        else:
            raise NonholoInputError(f"{source}: no such file or directory (expected a .mcap recording or the "
                                    f"--out directory of nonholo run)")
    except NonholoInputError as exc:
        print(f"nonholo view: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    page = replay.page()
    try:
        server = start_server(lambda: page, None, args, "nonholo view")
    except OSError as exc:
        print(f"nonholo view: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    print(f"replaying {source}: {len(replay.names)} robots, {replay.t[-1]:.6g} s (Ctrl-C stops)", file=sys.stderr)
    serve_until_stopped(server, args.serve_for)
    return EXIT_OK


def add_fleet_view_arguments(parser: argparse.ArgumentParser) -> None:
    """``--record``, ``--view``, ``--speed`` and the server's options, for ``nonholo fleet``."""
    parser.add_argument("--record", metavar="FILE.mcap", help="write an MCAP recording of the run (see nonholo run)")
    parser.add_argument("--view", action="store_true",
                        help="serve a live page of the fleet while it runs (its address, with a token, is printed "
                             "on stderr at start); after the run the page replays it until Ctrl-C or --for S")
    parser.add_argument("--foxglove", type=int, nargs="?", const=8765, metavar="PORT",
                        help="also serve the fleet live to Foxglove on ws://127.0.0.1:PORT (default 8765; "
                             "loopback only: that protocol has no token); needs nonholo[foxglove]")
    parser.add_argument("--speed", type=float, metavar="X",
                        help="pace logical time at X times wall time (default: 1 with --view or --foxglove, "
                             "else unpaced)")
    add_server_arguments(parser)


class FleetViewing:
    """The live page and the recording of a ``nonholo fleet`` run: ``start()`` before the
    run (checks the options, starts the server), ``observer`` and ``speed`` for the
    launcher, ``finish(run, summary)`` after it (the recording, the page's replay),
    ``serve()`` at the end (until Ctrl-C or --for), ``stop()`` on any failure."""

    def __init__(self, args: argparse.Namespace, prog: str) -> None:
        self.args, self.prog = args, prog
        self.observer = self.server = self.bridge = None
        watched = args.view or args.foxglove is not None
        self.speed = args.speed if args.speed is not None else (1.0 if watched else None)

    def start(self) -> None:
        from nonholo.errors import NonholoInputError
        from nonholo.view import require

        args = self.args
        if args.speed is not None and not (0 < args.speed < float("inf")):
            raise NonholoInputError(f"--speed must be a positive number, got {args.speed}")
        if args.record:
            require("mcap")
        if not args.view and args.foxglove is None:
            return
        from nonholo.errors import SimulationError
        from nonholo.view.feed import FleetObserver, LatestFeed

        check_server_arguments(args)
        if args.foxglove is not None and not 0 <= args.foxglove <= MAX_PORT:
            raise NonholoInputError(f"--foxglove must be a port 0..{MAX_PORT}, got {args.foxglove}")
        require("aiohttp") if args.view else require("foxglove", "foxglove")
        self.observer = FleetObserver(LatestFeed())
        try:
            if args.view:
                self.server = start_server(None, self.observer.feed, args, self.prog, sys.stderr)
            if args.foxglove is not None:
                from nonholo.view.foxglove_live import FoxgloveBridge

                self.bridge = FoxgloveBridge(self.observer.feed, args.foxglove).start()
                print(f"foxglove: ws://127.0.0.1:{self.bridge.port}", file=sys.stderr, flush=True)
        except (OSError, RuntimeError) as exc:    # foxglove reports a busy port as RuntimeError
            self.stop()
            raise SimulationError(f"cannot serve: {' '.join(str(exc).split())[:160]}") from None

    def finish(self, run, summary: dict) -> None:
        if not (self.args.record or self.observer):
            return
        from nonholo.view.data import from_result
        from nonholo.view.record import record_every

        # the page decimates to its own frame budget: one replay at the recording's stride serves both
        replay = from_result(run.result, record_every(run.result.scenario.dt), summary)
        for key, link in (replay.links or {}).items():
            link.update(summary.get("network", {}).get("links", {}).get(key, {}))
        if self.args.record:
            from nonholo.view.record import write_recording

            write_recording(replay, self.args.record, network=summary.get("network"))
            print(f"wrote {self.args.record}", file=sys.stderr)
        if self.observer is not None:
            self.observer.feed.finish(replay.page())

    def serve(self) -> None:
        if self.server is not None or self.bridge is not None:
            what = "the page replays it" if self.server is not None else "Foxglove keeps its last state"
            print(f"the run is over; {what} (Ctrl-C stops)", file=sys.stderr)
            serve_until_stopped(self, self.args.serve_for)

    def stop(self) -> None:
        for part in (self.server, self.bridge):
            if part is not None:
                part.stop()
