"""The page server: token on every request, read-only, the latest-wins live feed, a fleet's
snapshots against its result, and the view command's bad inputs (one line, exit 2)."""
import asyncio
import json
import logging
import socket
import threading
import time
import urllib.error
import urllib.request

import numpy as np
import pytest

pytest.importorskip("aiohttp", reason="the view extra (aiohttp) is not installed")
pytest.importorskip("mcap", reason="the view extra (mcap) is not installed")

import aiohttp  # noqa: E402
from view_fleets import chain  # noqa: E402

from nonholo.cli import main  # noqa: E402
from nonholo.fleet.launch import run_fleet  # noqa: E402
from nonholo.fleet.robot import ACK_EVERY, WINDOW  # noqa: E402
from nonholo.view.feed import FleetObserver, LatestFeed  # noqa: E402
from nonholo.view import server as view_server  # noqa: E402
from nonholo.view.server import RATE_HZ, ViewServer  # noqa: E402

WAIT_S = 10.0


def get(url: str, method: str = "GET"):
    request = urllib.request.Request(url, method=method)
    try:
        with urllib.request.urlopen(request, timeout=WAIT_S) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


@pytest.fixture
def replay_server():
    page = {"mode": "replay", "t": [0.0, 1.0], "robots": [], "reference": None, "links": {}, "title": "x"}
    with ViewServer(lambda: page) as server:
        yield server


def test_every_request_needs_the_token(replay_server):
    base = f"http://127.0.0.1:{replay_server.port}"
    token = replay_server.token
    assert replay_server.url == f"{base}/?token={token}"
    status, body = get(replay_server.url)
    assert status == 200 and b"view.js?token=" + token.encode() in body
    assert get(f"{base}/data?token={token}")[1].startswith(b'{"mode":"replay"')
    for path in ("/", "/data", "/view.js", "/live", "/nothing", "/../etc/passwd"):
        for query in ("", "?token=", f"?token={token[:-1]}", f"?token={token}x", "?token=" + "a" * len(token)):
            assert get(base + path + query) == (403, b"forbidden"), path + query
    assert get(replay_server.url, "POST") == (403, b"forbidden")
    assert get(f"{base}/nothing?token={token}")[0] == 404
    assert get(f"{base}/live?token={token}")[0] == 503      # a replay has no live feed
    assert replay_server.refused >= 30


def closed_by_peer(sock: socket.socket, within_s: float) -> bool:
    """True when the server closes ``sock`` within ``within_s`` (what it sent is read)."""
    sock.settimeout(within_s)
    try:
        while sock.recv(4096):
            pass
    except socket.timeout:
        return False
    except OSError:      # reset: closed too
        pass
    return True


def test_connections_are_bounded_and_those_without_the_token_expire(monkeypatch):
    """A flood of silent connections holds at most MAX_CONNECTIONS, cannot keep a page out (a
    new connection closes one not yet proven) and each is closed REQUEST_DEADLINE_S after it
    connected; a slow client trickling a request too; responses name no server software."""
    monkeypatch.setattr(view_server, "MAX_CONNECTIONS", 8)
    monkeypatch.setattr(view_server, "REQUEST_DEADLINE_S", 1.0)
    page = {"mode": "replay", "t": [0.0], "robots": [], "reference": None, "links": {}, "title": "x"}
    with ViewServer(lambda: page) as server:
        flood = [socket.create_connection(("127.0.0.1", server.port)) for _ in range(20)]
        try:
            slow = socket.create_connection(("127.0.0.1", server.port))
            slow.sendall(b"GET /?token=")
            deadline = time.monotonic() + WAIT_S
            while server.gate.evicted < 13 and time.monotonic() < deadline:
                time.sleep(0.02)
            assert len(server.gate.open) <= 8 and server.gate.evicted == 13
            with urllib.request.urlopen(server.url, timeout=WAIT_S) as response:     # a page still gets in
                assert response.status == 200 and response.headers["Server"] == "nonholo"
            started = time.monotonic()
            assert closed_by_peer(slow, 3.0) and time.monotonic() - started < 2.5
            assert all(closed_by_peer(sock, 3.0) for sock in flood)
            assert server.gate.expired >= 7 and not server.gate.unproven
        finally:
            for sock in flood + [slow]:
                sock.close()


def test_a_malformed_request_is_refused_and_the_terminal_stays_quiet(replay_server, capfd):
    """aiohttp logs a malformed request's traceback; a program without logging set up (the
    nonholo command) would print it (logging's last resort): nothing reaches the root logger."""
    records = []
    collect = logging.Handler()
    collect.emit = records.append
    logging.getLogger().addHandler(collect)
    try:
        with socket.create_connection(("127.0.0.1", replay_server.port), timeout=WAIT_S) as sock:
            sock.sendall(b"GET /?token=" + replay_server.token.encode() + b" HTTP/1.1\r\nX-Long: " + b"a" * 10_000
                         + b"\r\n\r\n")
            assert sock.recv(4096).split(b"\r\n")[0] in (b"HTTP/1.0 400 Bad Request", b"HTTP/1.1 400 Bad Request")
        assert get(replay_server.url)[0] == 200
    finally:
        logging.getLogger().removeHandler(collect)
    assert records == []
    out, err = capfd.readouterr()
    assert err == "" and out == ""


def test_live_feed_is_latest_wins():
    feed = LatestFeed({"mode": "live", "robots": [], "reference": None, "links": {}, "title": "t"})

    async def watch(url: str, seconds: float) -> list:
        got = []
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(url, timeout=aiohttp.ClientWSTimeout(ws_close=WAIT_S)) as ws:
                deadline = time.monotonic() + seconds
                while time.monotonic() < deadline:
                    try:
                        message = await ws.receive(timeout=max(0.01, deadline - time.monotonic()))
                    except asyncio.TimeoutError:
                        break
                    if message.type != aiohttp.WSMsgType.TEXT:
                        break
                    got.append(json.loads(message.data))
        return got

    stop = threading.Event()

    def publish():   # a publisher far faster than the page: 10 000 snapshots a second or more
        n = 0
        while not stop.is_set() and n < 1_000_000:
            n += 1
            feed.publish({"n": n})
            time.sleep(0.0001)

    with ViewServer(None, feed) as server:
        publisher = threading.Thread(target=publish)
        publisher.start()
        try:
            url = f"ws://127.0.0.1:{server.port}/live?token={server.token}"
            got = asyncio.run(watch(url, 1.0))
        finally:
            stop.set()
            publisher.join(WAIT_S)
    numbers = [m["n"] for m in got]
    assert 5 <= len(numbers) <= 1.0 * RATE_HZ + 3             # the page's rate, not the publisher's
    assert numbers == sorted(numbers) and numbers[-1] - numbers[0] > 10 * len(numbers)  # frames dropped
    assert feed.published > 20 * len(numbers)


def test_fleet_snapshots_keep_up_and_match_the_result(tmp_path):
    _, scenario = chain(tmp_path, duration=4.0)
    feed = LatestFeed()
    snapshots = []

    class Keeping(FleetObserver):
        def __call__(self, programs):
            super().__call__(programs)
            snapshots.append((time.monotonic(), json.loads(feed.latest()[1])))

    run_fleet(scenario, "inproc", speed=None)             # compiled and warm
    started = time.monotonic()
    run = run_fleet(scenario, "inproc", observer=Keeping(feed), speed=4.0)
    wall = time.monotonic() - started
    assert wall < 4.0 / 4.0 + 1.0                           # kept pace: 200 instants of 8 robots in ~1 s
    stamps = np.array([s[0] for s in snapshots])
    assert len(snapshots) >= 10 and np.diff(stamps).max() < 0.1   # ≥ 10 Hz throughout
    last = snapshots[-1][1]
    assert last["t"] == pytest.approx(4.0) and set(last["states"].values()) == {"done"}
    result = run.result
    checked = 0
    for _, snap in snapshots:
        for name, robot in snap["robots"].items():
            k = robot["k"]
            if k < 0:
                continue
            i = result.index(name)
            assert (robot["x"], robot["y"]) == pytest.approx((result.x[i][k], result.y[i][k]), abs=1e-12)
        for key, link in snap["links"].items():
            child = key.split("->")[1]
            k = snap["robots"][child]["k"]
            if k < 0:
                continue
            e_l, e_phi = result.output_errors(child)
            assert link["e1"] == pytest.approx(e_l[k], abs=2e-6)
            assert link["e2"] == pytest.approx(np.angle(np.exp(1j * e_phi[k])), abs=2e-6)
            # a parent runs at most WINDOW instants ahead of its follower's acknowledged progress
            assert link["in_flight"] <= WINDOW + ACK_EVERY and link["rejected"] == 0
            assert link["age_s"] == pytest.approx(0.0)
            checked += 1
    assert checked >= 7 * 5
    assert all(link["lost"] == 0 for link in run.network["links"].values())
    assert any(abs(link["e1"]) > 0.1 for _, s in snapshots for link in s["links"].values() if link["e1"] is not None)


def test_final_snapshot_of_an_l_l_follower(tmp_path):
    """The page's errors of an l-l follower (F keeps l1 to the leader, l2 to R2) are the run's."""
    import dataclasses

    from nonholo import examples
    from nonholo.sim.files import load_scenario

    scenario = load_scenario(examples.resolve("formation-eight-triangle"))
    scenario = dataclasses.replace(scenario, duration=1.0, dt=0.01, control_period=0.02, steps=None)
    feed = LatestFeed()
    run = run_fleet(scenario, "inproc", observer=FleetObserver(feed))
    last = json.loads(feed.latest()[1])
    l1, l2 = run.result.output_errors("F")
    assert abs(l1[-1]) > 1e-3 and abs(l2[-1]) > 1e-3
    assert last["links"]["leader->F"]["e1"] == pytest.approx(l1[-1], abs=2e-6)
    assert last["links"]["R2->F"]["e2"] == pytest.approx(l2[-1], abs=2e-6)
    e_l, e_phi = run.result.output_errors("R2")
    assert last["links"]["leader->R2"]["e1"] == pytest.approx(e_l[-1], abs=2e-6)
    assert last["links"]["leader->R2"]["e2"] == pytest.approx(np.angle(np.exp(1j * e_phi[-1])), abs=2e-6)


@pytest.mark.parametrize("make, message", [
    (lambda d: d / "missing.mcap", "no such file or directory"),
    (lambda d: (d / "bad.mcap").write_bytes(b"\x89MCAP0\r\n garbage") and d / "bad.mcap", "not a readable MCAP"),
    (lambda d: d, "no result.json"),
])
def test_view_bad_sources_are_one_line(tmp_path, capsys, make, message):
    assert main(["view", str(make(tmp_path)), "--for", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("nonholo view: ") and message in err


def test_view_bad_options(tmp_path, capsys):
    (tmp_path / "x.mcap").write_bytes(b"")
    for options in (["--port", "70000"], ["--host", "localhost; rm"], ["--for", "0"]):
        assert main(["view", str(tmp_path / "x.mcap"), *options]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "nonholo view: --" in err


def test_view_command_serves_a_recording(tmp_path, capsys):
    """`nonholo view FILE.mcap` prints the page's address and serves the recording there."""
    from nonholo.sim.simulator import simulate
    from nonholo.view.data import from_result
    from nonholo.view.record import write_recording

    _, scenario = chain(tmp_path, duration=1.0)
    result = simulate(scenario, progress=False)
    path = write_recording(from_result(result), tmp_path / "run.mcap")
    outcome = {}
    runner = threading.Thread(target=lambda: outcome.setdefault("code", main(["view", str(path), "--for", "2"])))
    runner.start()
    try:
        deadline, out = time.monotonic() + WAIT_S, ""
        while "page: " not in out and time.monotonic() < deadline:
            time.sleep(0.05)
            out += capsys.readouterr().out
        url = out.split("page: ", 1)[1].split()[0]
        status, body = get(url.replace("/?", "/data?"))
        page = json.loads(body)
        assert status == 200 and page["mode"] == "replay" and page["title"] == "leader-and-7"
        assert [r["name"] for r in page["robots"]] == list(result.names)
        assert page["robots"][3]["x"][-1] == pytest.approx(result.x[3][-1], abs=1e-6)
        assert get(url.split("?")[0] + "data")[0] == 403
    finally:
        runner.join(WAIT_S)
    assert outcome["code"] == 0
