"""Telemetry of robot processes (nonholo.fleet.telemetry): a client without the fleet's key gets
nothing from the observer endpoint and the fleet is unaffected; an endpoint without the keys
never gets a status; a slow observer never slows a robot; statuses are checked field by field;
bad options are one line naming the option."""
import asyncio
import dataclasses
import socket
import threading
import time

import pytest

from nonholo.cli import main
from nonholo.comm.channel import SecureChannel
from nonholo.comm.envelope import Sealer
from nonholo.comm.errors import CommError, ContentError
from nonholo.comm.transports.hello import HelloFailed, LinkAuth
from nonholo.comm.transports.tcp import connect_tcp, serve_tcp, tcp_port
from nonholo.fleet.config import load_fleet
from nonholo.fleet.keys import fleet_keys, keys_from_file, write_fleet_key_file
from nonholo.fleet.launch import run_fleet
from nonholo.fleet.telemetry import OBSERVER, ObserverHub, ObserverThread, read_status, status_message
from nonholo.sim.simulator import simulate
from test_fleet_lockstep import assert_same_result
from view_fleets import chain_toml

NAMES = ("leader", "f1", "f2")
STATUS = {"k": 3, "t": 0.06, "pose": [1.0, 2.0, 0.5], "v": 0.4, "w": 0.0, "state": "running",
          "links": {"leader": {"e1": 0.1, "e2": None, "age_s": 0.0, "latency_s": None, "received": 4,
                               "rejected": 0}},
          "sent": {"f2": 5}}
ATTACKS = 20


def fleet_file(tmp_path, duration=2.0):
    path = tmp_path / "chain.toml"
    path.write_text(chain_toml(duration, followers=2))
    keys = tmp_path / "fleet.keys"
    write_fleet_key_file(keys, NAMES)
    scenario, config = load_fleet(path)
    return path, scenario, dataclasses.replace(config, keys=keys)


def run(path, scenario, config, observe, speed=None):
    return run_fleet(scenario, "tcp", config=config, source=path, observe=observe, wait_s=15.0, speed=speed)


async def keyless_client(port: int) -> bytes:
    """Connect without the key: send a forged hello and read all the hub sends (bounded)."""
    reader, writer = await asyncio.wait_for(asyncio.open_connection("127.0.0.1", port), 5)
    got = b""
    try:
        writer.write(b"\x00\x00\x00\x30" + b"\x01" * 48)
        await writer.drain()
        while len(got) < 1 << 16:
            chunk = await asyncio.wait_for(reader.read(4096), 6)
            if not chunk:
                break
            got += chunk
    except (ConnectionError, asyncio.TimeoutError):
        pass
    finally:
        writer.close()
    return got


async def wrong_key_client(port: int) -> str:
    auth = LinkAuth({1: b"k" * 32}, key_id=1)
    try:
        client = await connect_tcp("leader", "127.0.0.1", port, auth=auth, timeout=5)
    except HelloFailed as exc:
        return str(exc)
    await client.close()
    return "linked"


def attack(port: int, results: dict, stop: threading.Event) -> None:
    async def attacks():
        while not stop.is_set() and len(results.setdefault("bytes", [])) < ATTACKS:
            results["bytes"].append(await keyless_client(port))
            results.setdefault("hello", []).append(await wrong_key_client(port))
    asyncio.run(attacks())


def test_a_keyless_client_gets_nothing_and_the_fleet_is_unaffected(tmp_path):
    path, scenario, config = fleet_file(tmp_path)
    seen, results, stop = {}, {}, threading.Event()

    def slow_observer(name, status):     # a slow observer: the robots drop statuses, never wait
        seen.setdefault(name, []).append(status)
        time.sleep(0.02)

    endpoint = ObserverThread(keys_from_file(config.keys, NAMES, NAMES), slow_observer).start()
    attacker = threading.Thread(target=attack, args=(endpoint.port, results, stop))
    try:
        attacker.start()
        # paced at twice real time: the robots stream their statuses for 1 s of wall time, so
        # that the count below does not hang on how fast a loaded machine runs the lockstep
        fleet = run(path, scenario, config, endpoint.address, speed=2.0)
    finally:
        stop.set()
        attacker.join(30)
        endpoint.stop(drain_s=10.0)   # the slow observer's backlog: every robot's last status
    assert_same_result(simulate(scenario), fleet.result)
    assert set(seen) == set(NAMES) and all(s[-1]["state"] == "done" for s in seen.values())
    assert endpoint.hub.rejected == 0 and sum(endpoint.hub.received.values()) >= 3 * 5
    assert results["bytes"] and all(len(got) <= 4 + 41 for got in results["bytes"])   # the challenge at most
    # the challenge frame: length (4) | magic, kind, epoch (9) | nonce (32 random bytes, which may
    # hold a two-letter name by chance); no name anywhere else
    assert not any(name.encode() in got[:13] + got[45:] for got in results["bytes"] for name in NAMES)
    assert results["hello"] and "linked" not in results["hello"]


class StalledObserver:
    """A live view's observer stalled for 2 s (on the endpoint's event loop) once every robot
    has linked: the robots end while what they sent is still in flight."""
    period_s = 0.05

    def __init__(self):
        self.seen, self.stalled = {}, False

    def status(self, name, status):
        self.seen.setdefault(name, []).append(status)
        if len(self.seen) == len(NAMES) and not self.stalled:
            self.stalled = True
            time.sleep(2.0)


def test_a_fleet_run_waits_for_its_observer_to_read_every_robots_last_status(tmp_path):
    path, scenario, config = fleet_file(tmp_path, duration=1.0)
    observer = StalledObserver()
    run_fleet(scenario, "tcp", config=config, source=path, observer=observer, wait_s=15.0)
    assert set(observer.seen) == set(NAMES)
    assert all(s[-1]["state"] == "done" for s in observer.seen.values()), \
        {name: s[-1]["state"] for name, s in observer.seen.items()}


def test_an_observer_stops_at_once_without_draining_and_drains_within_its_bound():
    endpoint = ObserverThread(fleet_keys(NAMES), lambda name, status: None).start()
    started = time.monotonic()
    endpoint.stop()
    assert time.monotonic() - started < 1.0
    endpoint = ObserverThread(fleet_keys(NAMES), lambda name, status: None).start()
    started = time.monotonic()
    endpoint.stop(drain_s=5.0)          # no robot linked, nothing in flight: nothing to wait for
    assert time.monotonic() - started < 1.0


def test_an_endpoint_without_the_keys_gets_no_status(tmp_path):
    path, scenario, config = fleet_file(tmp_path)
    impostor_keys = fleet_keys(NAMES)
    auth = LinkAuth({k: s for _, k, s in impostor_keys.values()},
                    peer_key_ids={n: k for n, (_, k, _) in impostor_keys.items()})
    loop = asyncio.new_event_loop()
    hub = loop.run_until_complete(serve_tcp(OBSERVER, auth=auth))
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    try:
        fleet = run(path, scenario, config, f"127.0.0.1:{tcp_port(hub)}")
    finally:
        loop.call_soon_threadsafe(loop.stop)
        thread.join(10)
    try:
        assert hub.peers == [] and hub.stats()["inbox"] == 0
        assert_same_result(simulate(scenario), fleet.result)
    finally:
        loop.run_until_complete(hub.close())
        loop.close()


def frame_of(keys, name, status, ontology=None):
    from nonholo.fleet.telemetry import observer_keys

    sid, kid, secret = observer_keys(keys)[name]
    message = status_message(name, status)
    if ontology:
        message = dataclasses.replace(message, ontology=ontology)
    return SecureChannel(Sealer(secret, key_id=kid, sender_id=sid)).pack(message)


@pytest.mark.parametrize("change", [
    lambda s: {**s, "extra": 1},
    lambda s: {**s, "pose": [1.0, 2.0]},
    lambda s: {**s, "k": -2},
    lambda s: {**s, "v": "fast"},
    lambda s: {**s, "v": 1e300},
    lambda s: {**s, "state": "dancing"},
    lambda s: {**s, "links": {"ghost": s["links"]["leader"]}},
    lambda s: {**s, "links": {"leader": {**s["links"]["leader"], "received": -1}}},
    lambda s: {**s, "links": {"leader": {**s["links"]["leader"], "e1": True}}},
    lambda s: {**s, "sent": {"f2": 1.5}},
])
def test_statuses_are_checked(change):
    keys = fleet_keys(NAMES)
    got = []
    hub = ObserverHub(keys, lambda name, status: got.append((name, status)))
    hub.accept("f1", frame_of(keys, "f1", STATUS))
    assert got == [("f1", STATUS)]
    hub.accept("f1", frame_of(keys, "f1", change(STATUS)))
    hub.accept("f2", frame_of(keys, "f1", STATUS))                    # f1's status on f2's link
    hub.accept("f1", frame_of(keys, "f1", STATUS, ontology="other"))
    hub.accept("f1", frame_of(fleet_keys(NAMES), "f1", STATUS))       # another fleet's key
    assert len(got) == 1 and hub.rejected == 4
    with pytest.raises(ContentError):
        read_status(status_message("f1", change(STATUS)), frozenset(NAMES))
    assert issubclass(ContentError, CommError)


@pytest.mark.parametrize("arguments, option", [
    (["view", "chain.toml", "--attach", "nowhere"], "--attach"),
    (["view", "chain.toml", "--attach", "localhost:7500"], "--attach"),
    (["view", "chain.toml", "--attach", "127.0.0.1:7500"], "--keys"),
    (["view", "chain.toml", "--keys", "fleet.keys"], "--keys"),
    (["view", "chain.toml", "--attach", "127.0.0.1:7500", "--keys", "missing.keys"], "missing.keys"),
    (["fleet", "chain.toml", "--observe", "127.0.0.1:7500"], "--observe"),
    (["fleet", "chain.toml", "--observe", "127.0.0.1:7500", "--view"], "--observe"),
    (["fleet", "chain.toml", "--observe", "127.0.0.1", "--keys", "fleet.keys"], "--observe"),
    (["fleet", "chain.toml", "--observe", "127.0.0.1:1", "--keys", "f.keys", "--transport", "inproc"],
     "--observe"),
    (["robot", "chain.toml", "--name", "f1", "--keys", "fleet.keys", "--observe", "x"], "--observe"),
    (["robot", "chain.toml", "--name", "f1", "--keys", "fleet.keys", "--speed", "0"], "--speed"),
    (["fleet", "chain.toml", "--speed", "1e-300", "--transport", "inproc"], "--speed"),   # would never end
])
def test_bad_watching_options_are_one_line_exit_2(arguments, option, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "chain.toml").write_text(chain_toml(1.0, followers=2))
    write_fleet_key_file(tmp_path / "fleet.keys", NAMES)
    assert main(arguments) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and option in err and "Traceback" not in err and len(err) <= 200


def test_an_observer_port_in_use_is_one_line(tmp_path, capsys):
    (tmp_path / "chain.toml").write_text(chain_toml(1.0, followers=2))
    write_fleet_key_file(tmp_path / "fleet.keys", NAMES)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        code = main(["view", str(tmp_path / "chain.toml"), "--attach", f"127.0.0.1:{port}", "--keys",
                     str(tmp_path / "fleet.keys"), "--for", "0.1"])
    err = capsys.readouterr().err.strip()
    assert code == 1 and len(err.splitlines()) == 1 and "--attach" in err
