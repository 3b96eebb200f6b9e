"""Connection attacks against the stream hub (TCP on 127.0.0.1, ports from the OS).

Each test runs against a hub with short time-outs, bounds every wait, and closes every
socket and task in ``finally`` even when it fails; each takes a few seconds at most."""
from __future__ import annotations

import asyncio
import dataclasses
import socket
import time

import pytest

from nonholo.comm.transports import TransportClosed
from nonholo.comm.transports.hello import (
    HelloFailed, HelloRefused, HubHello, LinkAuth, PeerHello,
)
from nonholo.comm.transports.stream import (
    KEEPALIVE, LENGTH, StreamClient, StreamLimits, frame_bytes, read_frame,
)
from nonholo.comm.transports.tcp import connect_tcp, serve_tcp, tcp_port

TEST_TIMEOUT = 8.0
KEYS = {0: b"L" * 32, 1: b"a" * 32, 2: b"b" * 32, 3: b"c" * 32}
HUB_AUTH = LinkAuth(KEYS, peer_key_ids={"f1": 1, "f2": 2, "f3": 3})
FAST = StreamLimits(hello_timeout=0.5, idle_timeout=0.6, keepalive_interval=0.15,
                    write_timeout=0.5, max_peers=4, max_pending=4, send_queue_frames=16,
                    send_queue_bytes=1 << 20, inbox_frames_per_peer=8,
                    inbox_bytes_per_peer=64 * 1024)


def auth(key_id: int) -> LinkAuth:
    return LinkAuth(KEYS, key_id=key_id)


class Scene:
    """A hub plus every client and raw socket a test opens, all closed at the end."""

    def __init__(self, limits: StreamLimits = FAST) -> None:
        self.limits = limits
        self.hub = None
        self.port = 0
        self.closers: list = []

    async def __aenter__(self) -> "Scene":
        self.hub = await serve_tcp("leader", "127.0.0.1", 0, auth=HUB_AUTH, limits=self.limits)
        self.port = tcp_port(self.hub)
        return self

    async def __aexit__(self, *exc) -> None:
        for close in reversed(self.closers):
            try:
                await asyncio.wait_for(close(), 2.0)
            except Exception:
                pass
        await asyncio.wait_for(self.hub.close(), 3.0)

    async def client(self, name: str, key_id: int, **kwargs) -> StreamClient:
        client = await connect_tcp(name, "127.0.0.1", self.port, auth=auth(key_id),
                                   limits=kwargs.pop("limits", self.limits), **kwargs)
        self.closers.append(client.close)
        return client

    async def raw(self, rcvbuf: int | None = None, source: str | None = None):
        sock = socket.socket()
        if rcvbuf is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        if source is not None:   # another loopback address as the connection's source
            sock.bind((source, 0))
        sock.setblocking(False)
        try:
            await asyncio.get_running_loop().sock_connect(sock, ("127.0.0.1", self.port))
            reader, writer = await asyncio.open_connection(sock=sock)
        except BaseException:
            sock.close()
            raise
        self.closers.append(lambda: _abort(writer))
        return reader, writer

    async def raw_peer(self, name: str, key_id: int, rcvbuf: int | None = None):
        """A peer that proves its key by hand, then does only what the test makes it do."""
        reader, writer = await self.raw(rcvbuf)
        hello = PeerHello(auth(key_id), name)
        writer.write(frame_bytes(hello.answer(await read_frame(reader, 1024))))
        assert hello.check_reply(await read_frame(reader, 1024)) == "leader"
        return reader, writer


async def _abort(writer: asyncio.StreamWriter) -> None:
    writer.transport.abort()


async def read_until_closed(reader: asyncio.StreamReader, limit: float) -> bytes:
    """Everything the other end sends until it closes (bounded in time and size)."""
    data = b""
    async with asyncio.timeout(limit):
        while len(data) < 1 << 20:
            try:
                chunk = await reader.read(65536)
            except ConnectionError:
                return data
            if not chunk:
                return data
            data += chunk
    return data


async def eventually(condition, limit: float = 2.0) -> None:
    deadline = time.monotonic() + limit
    while not condition():
        assert time.monotonic() < deadline, "condition not reached in time"
        await asyncio.sleep(0.01)


def run(coroutine):
    return asyncio.run(asyncio.wait_for(coroutine, TEST_TIMEOUT))


# -- the hello ----------------------------------------------------------------------------
def test_keyless_client_learns_nothing_and_cannot_take_a_name():
    async def scenario():
        async with Scene() as scene:
            f1 = await scene.client("f1", 1)
            await scene.hub.wait_for_peers(1, 2.0)
            # The old hello: just a name. The hub answers with nothing but its challenge.
            reader, writer = await scene.raw()
            writer.write(frame_bytes(b"f1"))
            received = await read_until_closed(reader, 2.0)
            assert len(received) == LENGTH.size + 41 and b"leader" not in received
            # A well-formed hello for f1 under a key the attacker made up.
            reader, writer = await scene.raw()
            fake = PeerHello(LinkAuth({1: b"x" * 32}, key_id=1), "f1")
            writer.write(frame_bytes(fake.answer(await read_frame(reader, 1024))))
            assert await read_until_closed(reader, 2.0) == b""
            # f1 keeps its link and its traffic.
            assert scene.hub.peers == ["f1"]
            await scene.hub.send(b"state", to="f1")
            assert await asyncio.wait_for(f1.recv(), 2.0) == ("leader", b"state")
            assert scene.hub.stats()["hello_failed"] == 2
    run(scenario())


def test_one_followers_key_cannot_open_another_followers_name():
    async def scenario():
        async with Scene() as scene:
            with pytest.raises(HelloFailed):
                await scene.client("f2", 1)  # f1's key under f2's name
            with pytest.raises(HelloFailed):
                await scene.client("intruder", 1)  # a name the hub does not list
            assert scene.hub.peers == [] and scene.hub.stats()["hello_failed"] == 2
    run(scenario())


def test_replayed_hello_is_refused():
    async def scenario():
        async with Scene() as scene:
            reader, writer = await scene.raw()
            hello = PeerHello(auth(1), "f1")
            recorded = hello.answer(await read_frame(reader, 1024))
            writer.write(frame_bytes(recorded))
            hello.check_reply(await read_frame(reader, 1024))
            writer.transport.abort()
            await eventually(lambda: scene.hub.peers == [])
            # Same bytes on a new connection: the hub's nonce changed, the tag fails.
            reader, writer = await scene.raw()
            await read_frame(reader, 1024)
            writer.write(frame_bytes(recorded))
            assert await read_until_closed(reader, 2.0) == b""
            assert scene.hub.peers == [] and scene.hub.stats()["hello_failed"] == 1
    run(scenario())


@pytest.mark.parametrize("raw", [
    frame_bytes(b""),                          # a keepalive instead of a hello
    frame_bytes(b"NHH1"),                      # truncated
    frame_bytes(b"\x00" * 300),                # zeros
    frame_bytes(b"NHH1\x02" + b"\x00" * 40),   # a hello header with no name or tag
    LENGTH.pack(600),                          # longer than any hello
    LENGTH.pack(200) + b"NHH1",                # a frame that never completes
], ids=["keepalive", "truncated", "zeros", "headless", "oversized", "incomplete"])
def test_malformed_hellos_are_closed(raw):
    async def scenario():
        async with Scene() as scene:
            reader, writer = await scene.raw()
            await read_frame(reader, 1024)
            writer.write(raw)
            assert await read_until_closed(reader, 2.0) == b""
            stats = scene.hub.stats()
            assert stats.get("hello_failed", 0) + stats.get("hello_timeouts", 0) == 1
            assert scene.hub.peers == []
    run(scenario())


def test_peer_rejects_a_hub_without_the_key():
    async def scenario():
        async def fake_hub(reader, writer):
            try:
                writer.write(frame_bytes(HubHello(LinkAuth({1: b"z" * 32}), epoch=1).challenge))
                await read_frame(reader, 1024)
                # It cannot sign a WELCOME with the peer's key: it sends a made-up tag.
                writer.write(frame_bytes(b"NHH1\x03\x06leader" + b"\x00" * 32))
                await writer.drain()
                await read_until_closed(reader, 2.0)
            finally:
                writer.transport.abort()
        server = await asyncio.start_server(fake_hub, "127.0.0.1", 0)
        try:
            port = server.sockets[0].getsockname()[1]
            with pytest.raises(HelloFailed, match="does not verify"):
                await connect_tcp("f1", "127.0.0.1", port, auth=auth(1), limits=FAST)
        finally:
            server.close()
            await asyncio.sleep(0.05)  # the fake hub sees the peer close and ends
    run(scenario())


# -- names and caps -----------------------------------------------------------------------
def test_a_connected_name_is_refused_to_the_newcomer():
    async def scenario():
        async with Scene() as scene:
            f1 = await scene.client("f1", 1)
            with pytest.raises(HelloRefused, match="already connected"):
                await scene.client("f1", 1)  # even with the right key
            assert scene.hub.peers == ["f1"]
            await scene.hub.send(b"still yours")
            assert await asyncio.wait_for(f1.recv(), 2.0) == ("leader", b"still yours")
            assert scene.hub.stats()["refused_name_in_use"] == 1
    run(scenario())


def test_peer_cap():
    async def scenario():
        limits = dataclasses.replace(FAST, max_peers=2)
        async with Scene(limits) as scene:
            await scene.client("f1", 1)
            await scene.client("f2", 2)
            with pytest.raises(HelloRefused, match="2 peers"):
                await scene.client("f3", 3)
            assert scene.hub.peers == ["f1", "f2"]
    run(scenario())


def test_flood_of_silent_connections_is_capped_and_a_good_peer_still_gets_in():
    async def scenario():
        async with Scene() as scene:
            f1 = await scene.client("f1", 1)
            flood = [await scene.raw() for _ in range(40)]
            await eventually(lambda: scene.hub.stats()["connections"] >= 41)
            stats = scene.hub.stats()
            assert stats["pending"] <= FAST.max_pending
            assert stats["evicted_pending"] >= 40 - FAST.max_pending
            start = time.monotonic()
            await scene.client("f2", 2)  # makes room by closing a silent one
            assert time.monotonic() - start < 0.4
            await scene.hub.send(b"tick")
            assert await asyncio.wait_for(f1.recv(), 2.0) == ("leader", b"tick")
            # The rest time out: nothing of the flood is left after the hello time-out.
            await eventually(lambda: scene.hub.stats()["pending"] == 0, FAST.hello_timeout + 1.0)
            assert scene.hub.peers == ["f1", "f2"]
            del flood
    run(scenario())


def test_a_flood_from_one_address_evicts_only_its_own_connections():
    """A peer's hello in flight from another address is never the one closed for the flood's
    new connections (the hub evicts among the connections of the address holding the most)."""
    async def scenario():
        async with Scene(dataclasses.replace(FAST, hello_timeout=2.0)) as scene:
            reader, peer = await scene.raw()                     # 127.0.0.1: a slow hello, say
            await read_frame(reader, 1024)                       # the hub's challenge
            flood = [await scene.raw(source="127.0.0.2") for _ in range(3 * FAST.max_pending)]
            await eventually(lambda: scene.hub.stats()["connections"] >= 1 + 3 * FAST.max_pending)
            stats = scene.hub.stats()
            assert stats["pending"] <= FAST.max_pending
            assert stats["evicted_pending"] == 1 + 3 * FAST.max_pending - FAST.max_pending
            with pytest.raises(asyncio.TimeoutError):              # the peer's connection: open, silent
                await asyncio.wait_for(reader.read(1), 0.3)
            del flood, peer
    run(scenario())


# -- idle and half-open links -------------------------------------------------------------
def test_proven_but_silent_peer_is_closed_after_the_idle_time():
    async def scenario():
        async with Scene() as scene:
            reader, _ = await scene.raw_peer("f1", 1)
            await scene.hub.wait_for_peers(1, 1.0)
            start = time.monotonic()
            received = await read_until_closed(reader, 3.0)  # keepalives, then the end
            assert FAST.idle_timeout * 0.9 <= time.monotonic() - start < FAST.idle_timeout + 1.0
            assert received and set(received) == {0}  # only keepalive frames came
            assert scene.hub.peers == [] and scene.hub.stats()["closed_idle"] == 1
    run(scenario())


def test_keepalives_keep_an_idle_but_healthy_link():
    async def scenario():
        async with Scene() as scene:
            f1 = await scene.client("f1", 1)
            pending = asyncio.ensure_future(f1.recv())
            await asyncio.sleep(3 * FAST.idle_timeout)
            assert not pending.done() and scene.hub.peers == ["f1"]
            await scene.hub.send(b"late")
            assert await asyncio.wait_for(pending, 2.0) == ("leader", b"late")
            peer_stats = scene.hub.stats()["peers"]["f1"]
            assert peer_stats["keepalives_received"] >= 3 and peer_stats["keepalives_sent"] >= 3
    run(scenario())


def test_client_notices_a_silent_hub():
    async def scenario():
        hub_auth = LinkAuth(KEYS, peer_key_ids={"f1": 1})

        async def silent_hub(reader, writer):  # proves its key, then never sends again
            try:
                hello = HubHello(hub_auth, epoch=7)
                writer.write(frame_bytes(hello.challenge))
                peer = hello.check(await read_frame(reader, 1024))
                writer.write(frame_bytes(peer.welcome("leader")))
                await read_until_closed(reader, 3.0)  # reads, never writes
            finally:
                writer.transport.abort()
        server = await asyncio.start_server(silent_hub, "127.0.0.1", 0)
        client = None
        try:
            port = server.sockets[0].getsockname()[1]
            client = await connect_tcp("f1", "127.0.0.1", port, auth=auth(1), limits=FAST)
            assert client.hub_epoch == 7
            start = time.monotonic()
            with pytest.raises(TransportClosed, match="idle"):
                await client.recv()
            assert time.monotonic() - start < FAST.idle_timeout + 0.5
        finally:
            if client is not None:
                await client.close()
            server.close()
            await asyncio.sleep(0.05)  # the silent hub sees the peer close and ends
    run(scenario())


# -- floods and slow readers ----------------------------------------------------------------
def test_inbox_flood_is_bounded_and_others_still_get_in():
    async def scenario():
        async with Scene() as scene:
            _, flooder = await scene.raw_peer("f1", 1)
            f2 = await scene.client("f2", 2)
            burst = frame_bytes(b"F" * 1000) * 2000  # 2 MB, never taken by the hub's app
            flooder.write(burst)
            await eventually(lambda: scene.hub.stats()["peers"]["f1"]["inbox"] == 8)
            await asyncio.sleep(0.2)
            stats = scene.hub.stats()
            assert stats["peers"]["f1"]["inbox"] == FAST.inbox_frames_per_peer
            assert stats["inbox"] == FAST.inbox_frames_per_peer  # nothing else queued
            await f2.send(b"from f2")
            await eventually(lambda: scene.hub.stats()["peers"]["f2"]["inbox"] == 1)
            seen = [await asyncio.wait_for(scene.hub.recv(), 1.0) for _ in range(9)]
            assert seen[-1] == ("f2", b"from f2")  # behind f1's ration, not behind its flood
            assert scene.hub.stats()["peers"]["f1"]["inbox"] <= FAST.inbox_frames_per_peer
    run(scenario())


def test_never_reading_peer_loses_its_own_frames_and_is_dropped_others_keep_receiving():
    async def scenario():
        async with Scene() as scene:
            # f1 reads nothing after the hello but sends keepalives: alive, never reading.
            _, stuck = await scene.raw_peer("f1", 1, rcvbuf=4096)
            f2 = await scene.client("f2", 2)
            got: list[bytes] = []

            async def reader():
                while True:
                    got.append((await f2.recv())[1])

            async def keep_alive():
                while True:
                    stuck.write(KEEPALIVE)
                    await asyncio.sleep(0.1)
            reading = asyncio.ensure_future(reader())
            beating = asyncio.ensure_future(keep_alive())
            try:
                payload = b"S" * 30000
                slowest = 0.0
                sent = 0
                start = time.monotonic()
                while time.monotonic() - start < 1.5:
                    t0 = time.perf_counter()
                    await scene.hub.send(payload + sent.to_bytes(4, "big"))
                    slowest = max(slowest, time.perf_counter() - t0)
                    sent += 1
                    await asyncio.sleep(0.003)
                await eventually(lambda: len(got) == sent, 2.0)
            finally:
                reading.cancel()
                beating.cancel()
            assert slowest < 0.05  # a broadcast never waits for the stuck peer
            assert [int.from_bytes(g[-4:], "big") for g in got] == list(range(sent))
            stats = scene.hub.stats()
            assert stats["closed_slow_reader"] == 1 and scene.hub.peers == ["f2"]
            assert stats["dropped_frames_of_closed_links"] > 0
            assert stats["peers"]["f2"]["dropped"] == 0
    run(scenario())


def test_send_queue_is_bounded_in_frames_and_bytes():
    async def scenario():
        async with Scene() as scene:
            await scene.raw_peer("f1", 1, rcvbuf=4096)
            for i in range(3000):
                await scene.hub.send(b"Q" * 2000)
            peer = scene.hub.stats()["peers"]["f1"]
            assert peer["queued"] <= FAST.send_queue_frames
            assert peer["queued_bytes"] <= FAST.send_queue_bytes
            assert peer["dropped"] > 0 and peer["sent"] + peer["dropped"] + peer["queued"] == 3000
    run(scenario())


def test_oversized_frame_after_the_hello_closes_the_link():
    async def scenario():
        async with Scene() as scene:
            reader, writer = await scene.raw_peer("f1", 1)
            writer.write(LENGTH.pack(10**9))
            await read_until_closed(reader, 2.0)
            assert scene.hub.stats()["closed_framing"] == 1 and scene.hub.peers == []
    run(scenario())


def test_limits_are_validated():
    with pytest.raises(ValueError, match="keepalive"):
        StreamLimits(idle_timeout=1.0, keepalive_interval=1.0)
    with pytest.raises(ValueError):
        StreamLimits(max_pending=0)
    with pytest.raises(ValueError):
        StreamLimits(hello_timeout=float("nan"))
    with pytest.raises(ValueError):
        LinkAuth({1: b"short"})
    with pytest.raises(ValueError):
        LinkAuth(KEYS, key_id=9)
