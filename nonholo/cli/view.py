"""``nonholo view SOURCE``: replay a recording or an --out directory in the browser, or
(``--attach``) show a fleet of robot processes live."""
from __future__ import annotations

import argparse
import ipaddress
import sys
import time

from nonholo.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK

MAX_PORT = 65535


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "view", help="replay a recording (.mcap) or an --out directory, or watch a running fleet (--attach)",
        description="Serve a page that replays a run: robots' poses and trails, the reference path, formation "
                    "links with their errors, with a time slider, play/pause, zoom and follow-a-robot. SOURCE is "
                    "an MCAP file written with --record, or the --out directory of `nonholo run` (result.json "
                    "and trajectories.csv). With --attach HOST:PORT, SOURCE is the fleet's scenario and the page "
                    "shows live the robots that stream their status there (`nonholo fleet SCENARIO --observe "
                    "HOST:PORT --keys FILE`, or `nonholo robot ... --observe HOST:PORT`), authenticated with the "
                    "fleet's key file. The page is read-only, on 127.0.0.1 by default, and needs the random "
                    "token printed in its address. Ctrl-C stops it.",
        epilog="Exit codes: 0 ok, 1 the server could not start, 2 bad input. Example: nonholo fleet "
               "formation-chain --control-period 0.02 --observe 127.0.0.1:7500 --keys fleet.keys, then "
               "nonholo view formation-chain --control-period 0.02 --attach 127.0.0.1:7500 --keys fleet.keys "
               "(to start the viewer first, make the key file first: nonholo acl keygen fleet.keys --ids 1 2 3 4 5 6 7 8, "
               "key id i+1 for the i-th robot)")
    parser.add_argument("source", help="a .mcap recording, or a directory written by nonholo run --out; with "
                                       "--attach, the fleet's scenario (.toml or a bundled example)")
    parser.add_argument("--attach", metavar="HOST:PORT",
                        help="receive the status of a running fleet's robots on HOST:PORT (port 0: a free one, "
                             "printed) and show them live")
    parser.add_argument("--keys", metavar="FILE",
                        help="with --attach: the fleet's key file (default the scenario's [network] keys)")
    from nonholo.cli.robot import add_simulation_overrides

    add_simulation_overrides(parser)
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

    if args.attach is not None:
        return handle_attach(args)
    source = Path(args.source)
    try:
        flags = {"--keys": args.keys, "--duration": args.duration, "--dt": args.dt,
                 "--control-period": args.control_period}
        given = [flag for flag, value in flags.items() if value is not None]
        if given:
            raise NonholoInputError(f"{given[0]}: only with --attach (it describes a running fleet)")
        check_server_arguments(args)
        require("aiohttp")
        if source.is_dir():
            from nonholo.view.data import from_outdir

            replay = from_outdir(source)
        elif source.is_file():
            from nonholo.view.record import read_recording

            if source.suffix.lower() == ".toml":
                raise NonholoInputError(f"{source}: a scenario, not a recording: replay a .mcap file or an --out "
                                        "directory, or watch a running fleet of it with --attach HOST:PORT --keys FILE")

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


def attach_inputs(args: argparse.Namespace) -> tuple:
    """(scenario, the fleet's keys by robot, (host, port)) for --attach; NonholoInputError
    naming the option otherwise."""
    from nonholo import examples
    from nonholo.cli.robot import simulation_overrides
    from nonholo.errors import NonholoInputError
    from nonholo.fleet.config import load_fleet
    from nonholo.fleet.keys import keys_from_file
    from nonholo.fleet.mesh import split_address

    host, port = split_address(args.attach, "--attach")
    try:
        ipaddress.ip_address(host)
    except ValueError:
        raise NonholoInputError(f"--attach: HOST must be an IP address such as 127.0.0.1, got {host!r}"[:200]) \
            from None
    scenario, config = load_fleet(examples.resolve(args.source), simulation_overrides(args))
    keys = args.keys or config.keys
    if keys is None:
        raise NonholoInputError("--keys: attaching needs the fleet's key file (the one its robots use; or set "
                                "[network] keys)")
    return scenario, keys_from_file(keys, scenario.names, scenario.names), (host, port)


def handle_attach(args: argparse.Namespace) -> int:
    """``nonholo view SCENARIO --attach HOST:PORT``: the live page of robots streaming there."""
    from nonholo.errors import NonholoInputError
    from nonholo.fleet.setup import robot_setups
    from nonholo.fleet.telemetry import ObserverThread
    from nonholo.view import require
    from nonholo.view.feed import FleetObserver, LatestFeed

    try:
        check_server_arguments(args)
        require("aiohttp")
        scenario, keys, (host, port) = attach_inputs(args)
        observer = FleetObserver(LatestFeed())
        observer.prepare(scenario, robot_setups(scenario))
    except NonholoInputError as exc:
        print(f"nonholo view: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        endpoint = ObserverThread(keys, observer.status, host, port).start()
    except OSError as exc:
        print(f"nonholo view: --attach: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    try:
        server = start_server(None, observer.feed, args, "nonholo view")
    except OSError as exc:
        endpoint.stop()
        print(f"nonholo view: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    print(f"attached on {endpoint.address}: robots with --observe {endpoint.address} show up (Ctrl-C stops)",
          file=sys.stderr, flush=True)
    try:
        serve_until_stopped(server, args.serve_for)
    finally:
        endpoint.stop()
    return EXIT_OK


def add_fleet_view_arguments(parser: argparse.ArgumentParser) -> None:
    """``--record``, ``--view``, ``--speed`` and the server's options, for ``nonholo fleet``."""
    parser.add_argument("--record", metavar="FILE.mcap", help="write an MCAP recording of the run (see nonholo run)")
    parser.add_argument("--view", action="store_true",
                        help="serve a live page of the fleet while it runs (its address, with a token, is printed "
                             "on stderr at start; robot processes stream their status to it); after the run the "
                             "page replays it until Ctrl-C or --for S")
    parser.add_argument("--observe", metavar="HOST:PORT",
                        help="robot processes stream their status to HOST:PORT, where `nonholo view SCENARIO "
                             "--attach HOST:PORT --keys FILE` shows them (needs --keys or [network] keys)")
    parser.add_argument("--keys", metavar="FILE",
                        help="the fleet's key file (mode 0600; key id i+1 is robot i), created with a fresh key "
                             "per robot if it does not exist (default [network] keys, else fresh keys per run)")
    parser.add_argument("--foxglove", type=int, nargs="?", const=8765, metavar="PORT",
                        help="also serve the fleet live to Foxglove on ws://127.0.0.1:PORT (default 8765; "
                             "loopback only: that protocol has no token); needs nonholo[foxglove]")
    parser.add_argument("--speed", type=float, metavar="X",
                        help="pace logical time at X times wall time (default: 1 with --view, --observe or "
                             "--foxglove, else unpaced; a realtime run keeps the wall clock)")
    add_server_arguments(parser)


class FleetViewing:
    """The live page and the recording of a ``nonholo fleet`` run: ``network(config,
    names)`` applies --keys and checks --observe, ``start()`` before the run (checks the
    options, starts the server), ``observer``, ``observe`` and ``speed`` for the launcher,
    ``finish(run, summary)`` after it (the recording, the page's replay), ``serve()`` at the
    end (until Ctrl-C or --for), ``stop()`` on any failure."""

    def __init__(self, args: argparse.Namespace, prog: str) -> None:
        self.args, self.prog = args, prog
        self.observer = self.server = self.bridge = None
        self.observe = args.observe
        watched = args.view or args.foxglove is not None or args.observe is not None
        self.speed = args.speed if args.speed is not None else (1.0 if watched else None)

    def network(self, config, names):
        """``config`` ([network]) with --keys (a missing file is made with fresh keys)."""
        import dataclasses
        from pathlib import Path

        from nonholo.errors import NonholoInputError
        from nonholo.fleet.keys import write_fleet_key_file
        from nonholo.cli.robot import check_watching
        from nonholo.fleet.launch import check_observe

        args = self.args
        check_watching(args)   # --observe's address, --speed
        if args.observe is not None and args.view:
            raise NonholoInputError("--observe: with --view the fleet's own page observes it; give one of them")
        check_observe(args.observe, args.transport or config.transport)   # before any key file is made
        if args.keys:
            path = Path(args.keys)
            if not path.exists():
                try:
                    write_fleet_key_file(path, names)
                except OSError as exc:
                    raise NonholoInputError(f"--keys: cannot create {path}: {exc.strerror or exc}") from None
                print(f"{self.prog}: wrote {path} (a fresh key per robot)", file=sys.stderr)
            config = dataclasses.replace(config, keys=path)
        if args.observe is not None and config.keys is None:
            raise NonholoInputError("--observe: a viewer attaching needs the fleet's key file: give --keys FILE "
                                    "(created if missing)")
        return config

    def start(self) -> None:
        from nonholo.errors import NonholoInputError
        from nonholo.view import require

        args = self.args
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
