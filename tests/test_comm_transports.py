"""Transports: in-process, TCP on 127.0.0.1, stream framing over socketpair (as RFCOMM
uses it), and the leader + 7 follower processes with zero loss. Every wait is bounded."""
from __future__ import annotations

import asyncio
import importlib.util
import socket

import pytest

from nonholo.comm.loopback import pooled_latency, run_fleet
from nonholo.comm.transports import TransportClosed, UnknownPeer
from nonholo.comm.transports.inproc import InProcNetwork
from nonholo.comm.transports.rfcomm import bluetooth_available
from nonholo.comm.transports.hello import LinkAuth
from nonholo.comm.transports.stream import LENGTH, StreamClient, StreamServer
from nonholo.comm.transports.tcp import connect_tcp, serve_tcp, tcp_port

TIMEOUT = 10.0
KEYS = {i: bytes([i + 1]) * 32 for i in range(4)}
HUB = LinkAuth(KEYS)  # any key opens any name: these tests are not about names


def peer(key_id: int = 1) -> LinkAuth:
    return LinkAuth(KEYS, key_id=key_id)


def run(coroutine):
    return asyncio.run(asyncio.wait_for(coroutine, TIMEOUT))


def test_inproc_unicast_broadcast_deterministic():
    async def scenario():
        network = InProcNetwork()
        leader, a, b = (network.endpoint(n) for n in ("leader", "a", "b"))
        await leader.send(b"all")
        await leader.send(b"only-b", to="b")
        await a.send(b"from-a", to="leader")
        assert await a.recv() == ("leader", b"all")
        assert [await b.recv(), await b.recv()] == [("leader", b"all"), ("leader", b"only-b")]
        assert await leader.recv() == ("a", b"from-a")
        with pytest.raises(UnknownPeer):
            await leader.send(b"x", to="nobody")
        with pytest.raises(ValueError):
            await leader.send(b"")
        await a.close()
        with pytest.raises(TransportClosed):
            await a.recv()
        assert leader.capabilities.reliable and leader.capabilities.broadcast
    run(scenario())


def test_tcp_star_send_to_one_and_all():
    async def scenario():
        server = await serve_tcp("leader", "127.0.0.1", 0, auth=HUB)
        port = tcp_port(server)
        clients = [await connect_tcp(f"f{i}", "127.0.0.1", port, auth=peer(i)) for i in range(3)]
        await server.wait_for_peers(3, TIMEOUT)
        assert server.peers == ["f0", "f1", "f2"] and clients[0].peer == "leader"
        await server.send(b"broadcast")
        await server.send(b"direct", to="f1")
        for client in clients:
            assert await client.recv() == ("leader", b"broadcast")
        assert await clients[1].recv() == ("leader", b"direct")
        await clients[2].send(b"up")
        assert await server.recv() == ("f2", b"up")
        with pytest.raises(UnknownPeer):
            await server.send(b"x", to="f9")
        for client in clients:
            await client.close()
        await server.close()
        with pytest.raises(TransportClosed):
            await server.recv()
    run(scenario())


def test_tcp_oversized_frame_closes_the_stream():
    async def scenario():
        server = await serve_tcp("leader", "127.0.0.1", 0, max_frame=1024, auth=HUB)
        client = await connect_tcp("f1", "127.0.0.1", tcp_port(server), auth=peer())
        await server.wait_for_peers(1, TIMEOUT)
        client._writer.write(LENGTH.pack(10**6))  # claims 1 MB: refused before reading
        await client._writer.drain()
        with pytest.raises(TransportClosed):
            await client.recv()  # the server hung up
        await client.close()
        await server.close()
    run(scenario())


def test_stream_framing_over_socketpair():
    """RFCOMM reuses this framing unchanged; socketpair has the same stream semantics."""
    async def scenario():
        hub_side, robot_side = socket.socketpair()
        hub = StreamServer("master", auth=HUB)
        await hub.attach_socket(hub_side)
        robot = await StreamClient.over_socket("slave-1", robot_side, auth=peer())
        await hub.wait_for_peers(1, TIMEOUT)
        payloads = [b"a", bytes(range(256)) * 200, b"\x00" * 3]
        for payload in payloads:
            await hub.send(payload, to="slave-1")
        for payload in payloads:
            assert await robot.recv() == ("master", payload)
        await robot.send(b"ack")
        assert await hub.recv() == ("slave-1", b"ack")
        await robot.close()
        await hub.close()
    run(scenario())


@pytest.mark.skipif(not bluetooth_available(), reason="no Bluetooth (AF_BLUETOOTH/RFCOMM) here")
def test_rfcomm_live():  # pragma: no cover - needs an adapter and a paired peer
    pytest.skip("set up a live RFCOMM peer to run this test")


def _assert_zero_loss(result, count):
    for report in result["reports"]:
        assert report["received"] == count, report["name"]
        assert report["lost"] == 0 and report["rejected"] == 0 and report["in_order"]
    assert len(result["reports"]) == 7
    assert pooled_latency(result)["p50_us"] > 0


def test_leader_and_seven_follower_processes_tcp():
    result = asyncio.run(asyncio.wait_for(run_fleet("tcp", followers=7, count=100, rate_hz=100.0,
                                                    timeout=25.0), 40.0))
    _assert_zero_loss(result, 100)


@pytest.mark.skipif(importlib.util.find_spec("zenoh") is None, reason="eclipse-zenoh not installed")
def test_leader_and_seven_follower_processes_zenoh():
    result = asyncio.run(asyncio.wait_for(run_fleet("zenoh", followers=7, count=100,
                                                    rate_hz=100.0, timeout=25.0), 40.0))
    _assert_zero_loss(result, 100)
