"""A leader and N follower processes on 127.0.0.1, for the tests and the benchmark.

The leader runs in the calling process; each follower is ``python -m
nonholo.comm.loopback follower ...``. Followers subscribe (FIPA-Subscribe), the leader
agrees, streams ``count`` authenticated ``inform`` states at ``rate_hz``, and each
follower reports as one JSON line: received, lost, rejected, one-way latencies.
Every wait is bounded, so a broken run fails instead of hanging.

Keys: per-sender HMAC keys (key id = sender id; leader 0, followers 1..N) passed through
the ``NONHOLO_ACL_KEYS`` environment variable of the child processes. Follower i proves
key i in the TCP hello and signs its envelopes with it; the echo process uses key 1.
"""
from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
import time

from nonholo.comm.channel import SecureChannel
from nonholo.comm.envelope import Opener, Sealer
from nonholo.comm.errors import CommError
from nonholo.comm.keys import DEFAULT_KEY_ENV, generate_key_line, load_key_env
from nonholo.comm.message import ACLMessage, AgentID
from nonholo.comm.ontology import (
    SUBSCRIBE_PROTOCOL, LeaderState, read_leader_state, state_inform,
)
from nonholo.comm.protocols import Conversation
from nonholo.comm.transports.base import Transport

LEADER = AgentID("leader@fleet")
# The state stream is addressed to the group, as spec section 1.6 advises: naming all 7
# followers in every 100 Hz message would double its size and decoding time.
FOLLOWERS = AgentID("followers@fleet")
CONVERSATION = "formation-7"
STARTUP_TIMEOUT_S = 20.0


ECHO = "echo"


def agent_name(sender_id: int) -> str:
    """The agent of each key/sender id: 0 is the leader, i > 0 follower i."""
    return LEADER.name if sender_id == 0 else f"f{sender_id}@fleet"


def _channel(keys: dict[int, bytes], my_id: int) -> SecureChannel:
    # Each key only authenticates its own sender id, so a follower cannot forge the leader,
    # and each sender id may only speak as its own agent (:sender bound to the envelope).
    return SecureChannel(Sealer(keys[my_id], key_id=my_id, sender_id=my_id),
                         Opener(keys, key_senders={k: frozenset({k}) for k in keys}),
                         senders={k: agent_name(k) for k in keys})


def _link_auth(keys: dict[int, bytes], key_id: int, leader: bool):
    """The TCP hello keys: each follower proves its own key; the echo process uses key 1."""
    from nonholo.comm.transports.hello import LinkAuth
    if leader:
        peers = {agent_name(k): k for k in keys if k != 0}
        return LinkAuth(keys, peer_key_ids={**peers, ECHO: 1})
    return LinkAuth(keys, key_id=key_id)


async def _open_transport(kind: str, name: str, port: int, leader: bool,
                          keys: dict[int, bytes], key_id: int) -> Transport:
    if kind == "tcp":
        from nonholo.comm.transports.tcp import connect_tcp, serve_tcp
        auth = _link_auth(keys, key_id, leader)
        return await (serve_tcp(name, "127.0.0.1", port, auth=auth) if leader
                      else connect_tcp(name, "127.0.0.1", port, auth=auth))
    if kind == "zenoh":
        from nonholo.comm.transports.zenoh import ZenohTransport, peer_config
        endpoint = f"tcp/127.0.0.1:{port}"
        config = (peer_config([endpoint], []) if leader
                  else peer_config(["tcp/127.0.0.1:0"], [endpoint]))
        return ZenohTransport(name, "loopback", config)
    raise ValueError(f"unknown transport {kind!r}")


# -- follower (child process) -----------------------------------------------------------
async def run_follower(kind: str, port: int, index: int, count: int, timeout: float) -> dict:
    keys = load_key_env()
    me = AgentID(agent_name(index))
    channel = _channel(keys, index)
    transport = await _open_transport(kind, me.name, port, False, keys, index)
    conversation = Conversation(SUBSCRIBE_PROTOCOL, CONVERSATION)
    subscribe = ACLMessage("subscribe", sender=me, receivers=(LEADER,),
                           content="((iota ?s (leader-state ?s)))", language="fipa-sl0",
                           protocol=SUBSCRIBE_PROTOCOL, conversation_id=CONVERSATION,
                           reply_with=f"sub-{index}")
    conversation.advance(subscribe, "initiator")
    await transport.send(channel.pack(subscribe), to=LEADER.name)
    latencies_us: list[float] = []   # leader stamp -> frame arrival
    handled_us: list[float] = []     # leader stamp -> verified, decoded and validated
    seqs: list[int] = []
    rejected = 0
    deadline = time.monotonic() + timeout
    try:
        while len(seqs) < count:
            _, frame = await asyncio.wait_for(transport.recv(), max(0.0, deadline - time.monotonic()))
            arrival = time.time()
            try:
                _, message = channel.unpack(frame)
                conversation.advance(message, "participant")
                if message.performative == "inform":
                    state = read_leader_state(message)
                    latencies_us.append((arrival - state.stamp) * 1e6)
                    handled_us.append((time.time() - state.stamp) * 1e6)
                    seqs.append(state.seq)
            except CommError:
                rejected += 1
    except asyncio.TimeoutError:
        pass
    finally:
        await transport.close()
    in_order = all(b > a for a, b in zip(seqs, seqs[1:]))
    return {"name": me.name, "received": len(seqs), "lost": count - len(seqs),
            "in_order": in_order, "rejected": rejected, "latencies_us": latencies_us,
            "handled_us": handled_us}


async def run_echo(kind: str, port: int, rounds: int, timeout: float) -> dict:
    """Send every frame straight back (raw frames, no envelope: measures the link)."""
    transport = await _open_transport(kind, ECHO, port, False, load_key_env(), 1)
    await transport.send(b"ready", to=LEADER.name)
    echoed = 0
    try:
        while echoed < rounds:
            peer, frame = await asyncio.wait_for(transport.recv(), timeout)
            await transport.send(frame, to=peer)
            echoed += 1
    except asyncio.TimeoutError:
        pass
    finally:
        await transport.close()
    return {"name": "echo", "echoed": echoed, "lost": rounds - echoed}


async def run_round_trips(kind: str = "tcp", rounds: int = 2000, warmup: int = 200,
                          payload_size: int = 400, timeout: float = 30.0) -> list[float]:
    """Round-trip times in microseconds between this process and an echo process."""
    keys, env = _fresh_keys(1)
    port = _free_port() if kind == "zenoh" else 0
    transport = await _open_transport(kind, LEADER.name, port, True, keys, 0)
    if kind == "tcp":
        from nonholo.comm.transports.tcp import tcp_port
        port = tcp_port(transport)  # type: ignore[arg-type]
    child = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "nonholo.comm.loopback", "echo", "--transport", kind,
        "--port", str(port), "--index", "0", "--count", str(rounds + warmup),
        "--timeout", str(timeout), stdout=subprocess.PIPE, env=env)
    payload = bytes(payload_size)
    times: list[float] = []
    try:
        peer, _ = await asyncio.wait_for(transport.recv(), STARTUP_TIMEOUT_S)
        for i in range(rounds + warmup):
            start = time.perf_counter()
            await transport.send(payload, to=peer)
            await asyncio.wait_for(transport.recv(), timeout)
            if i >= warmup:
                times.append((time.perf_counter() - start) * 1e6)
        await asyncio.wait_for(child.communicate(), timeout)
    finally:
        if child.returncode is None:
            child.kill()
            await child.wait()
        await transport.close()
    return times


# -- leader (calling process) -----------------------------------------------------------
async def run_fleet(kind: str = "tcp", followers: int = 7, count: int = 200,
                    rate_hz: float = 100.0, port: int = 0, timeout: float = 30.0) -> dict:
    """Run the whole exchange; returns per-follower reports and pooled latency figures."""
    keys, env = _fresh_keys(followers)
    if kind == "zenoh" and port == 0:
        port = _free_port()
    transport = await _open_transport(kind, LEADER.name, port, True, keys, 0)
    if kind == "tcp":
        from nonholo.comm.transports.tcp import tcp_port
        port = tcp_port(transport)  # type: ignore[arg-type]
    children = [await asyncio.create_subprocess_exec(
        sys.executable, "-m", "nonholo.comm.loopback", "follower", "--transport", kind,
        "--port", str(port), "--index", str(i), "--count", str(count), "--timeout", str(timeout),
        stdout=subprocess.PIPE, env=env) for i in range(1, followers + 1)]
    try:
        channel = _channel(keys, 0)
        await _accept_subscriptions(transport, channel, followers)
        await _stream_states(transport, channel, count, rate_hz)
        outputs = await asyncio.wait_for(
            asyncio.gather(*(child.communicate() for child in children)), timeout)
    finally:
        for child in children:
            if child.returncode is None:
                child.kill()
                await child.wait()
        await transport.close()
    reports = [json.loads(out.decode().strip().splitlines()[-1]) for out, _ in outputs]
    return {"transport": kind, "followers": followers, "count": count, "rate_hz": rate_hz,
            "reports": reports}


async def _accept_subscriptions(transport: Transport, channel: SecureChannel,
                                followers: int) -> list[AgentID]:
    subscribers: dict[str, AgentID] = {}
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    while len(subscribers) < followers:
        peer, frame = await asyncio.wait_for(transport.recv(), max(0.0, deadline - time.monotonic()))
        _, message = channel.unpack(frame)
        conversation = Conversation(SUBSCRIBE_PROTOCOL, CONVERSATION)
        conversation.advance(message, "initiator")
        assert message.sender is not None
        agree = ACLMessage("agree", sender=LEADER, receivers=(message.sender,),
                           protocol=SUBSCRIBE_PROTOCOL, conversation_id=CONVERSATION,
                           in_reply_to=message.reply_with)
        await transport.send(channel.pack(agree), to=peer)
        subscribers[peer] = message.sender
    return [subscribers[name] for name in sorted(subscribers)]


async def _stream_states(transport: Transport, channel: SecureChannel, count: int,
                         rate_hz: float) -> None:
    period = 1.0 / rate_hz
    start = time.monotonic()
    for seq in range(1, count + 1):
        await asyncio.sleep(max(0.0, start + seq * period - time.monotonic()))
        state = LeaderState(seq, time.time(), 0.01 * seq, 0.0, 0.0, 0.35, -0.12, CONVERSATION)
        message = state_inform(state, LEADER, (FOLLOWERS,), CONVERSATION)
        await transport.send(channel.pack(message))


def _fresh_keys(followers: int) -> tuple[dict[int, bytes], dict[str, str]]:
    """New random keys 0..followers, and an environment that hands them to children."""
    keys = {i: bytes.fromhex(generate_key_line(i).split(":")[1]) for i in range(followers + 1)}
    env = dict(os.environ, **{DEFAULT_KEY_ENV: ";".join(f"{k}:{v.hex()}" for k, v in keys.items())})
    return keys, env


def _free_port() -> int:
    import socket
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def pooled_latency(result: dict, key: str = "latencies_us") -> dict[str, float]:
    values = sorted(v for r in result["reports"] for v in r[key])
    if not values:
        return {"p50_us": float("nan"), "p99_us": float("nan"), "max_us": float("nan")}
    return {"p50_us": values[len(values) // 2], "p99_us": values[min(len(values) - 1,
            int(len(values) * 0.99))], "max_us": values[-1]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Loopback follower process (used by tests "
                                     "and `nonholo acl bench`).")
    parser.add_argument("role", choices=["follower", "echo"])
    parser.add_argument("--transport", choices=["tcp", "zenoh"], default="tcp")
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--index", type=int, required=True)
    parser.add_argument("--count", type=int, required=True)
    parser.add_argument("--timeout", type=float, default=30.0)
    args = parser.parse_args(argv)
    if args.role == "echo":
        report = asyncio.run(run_echo(args.transport, args.port, args.count, args.timeout))
    else:
        report = asyncio.run(run_follower(args.transport, args.port, args.index, args.count,
                                          args.timeout))
    print(json.dumps(report))
    return 0 if report["lost"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
