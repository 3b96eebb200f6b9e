"""The machine's floor for the fleet's one-way latency (``nonholo bench-fleet``): one sender
and ``receivers`` minimal processes on this machine, 8-byte monotonic stamps over TCP
(``TCP_NODELAY``) at the fleet's rate. A receiver does nothing but block in ``recv`` and
note the arrival, so the figure is what the OS scheduler and the loopback add, with no codec,
envelope, event loop or control law: the robot programs cannot do better than this on the
same machine under the same load.

Receiver: ``python -m nonholo.fleet.floor PORT COUNT`` prints its latencies (s) as JSON.
"""
from __future__ import annotations

import json
import socket
import struct
import subprocess
import sys
import time

import numpy as np

STAMP = struct.Struct("<d")
ACCEPT_S = 30.0     # longest wait for the receivers to connect (they start a Python each)
RECV_S = 10.0       # longest a receiver waits for one stamp


def receive(port: int, count: int) -> list[float]:
    """Connect to the sender, read ``count`` stamps; each one's age on arrival (s)."""
    with socket.create_connection(("127.0.0.1", port), timeout=ACCEPT_S) as link:
        link.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        link.settimeout(RECV_S)
        latencies, pending = [], b""
        while len(latencies) < count:
            data = link.recv(4096)
            arrived = time.monotonic()
            if not data:
                break
            pending += data
            whole = len(pending) // STAMP.size * STAMP.size
            latencies += [arrived - t for (t,) in STAMP.iter_unpack(pending[:whole])]
            pending = pending[whole:]
    return latencies


def floor_figures(rate: float, duration: float, receivers: int = 7) -> dict:
    """One-way latency p50/p99/max (ms) of ``receivers`` minimal processes at ``rate`` Hz
    for ``duration`` s; every receiver process is reaped whatever happens."""
    count = max(1, int(rate * duration))
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(receivers)
        listener.settimeout(ACCEPT_S)
        command = [sys.executable, "-m", "nonholo.fleet.floor", str(listener.getsockname()[1]), str(count)]
        children = []
        try:
            for _ in range(receivers):
                children.append(subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE))
            links = [listener.accept()[0] for _ in range(receivers)]
            try:
                _send_stamps(links, rate, count)
            finally:
                for link in links:
                    link.close()
            outputs = [child.communicate(timeout=ACCEPT_S)[0] for child in children]
        finally:
            for child in children:
                if child.poll() is None:
                    child.kill()
                child.wait()
    per_link = [np.asarray(json.loads(out or b"[]"), dtype=float) * 1e3 for out in outputs]
    pooled = np.concatenate(per_link)
    return {"rate_hz": rate, "receivers": receivers, "received": int(pooled.size), "sent": count * receivers,
            "latency_p50_ms": float(np.median([np.median(l) for l in per_link if l.size])),
            "latency_p99_ms": float(max(np.percentile(l, 99) for l in per_link if l.size)),
            "latency_max_ms": float(pooled.max())}


def _send_stamps(links: list, rate: float, count: int) -> None:
    for link in links:
        link.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    start = time.monotonic() + 0.2
    for k in range(count):
        delay = start + k / rate - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        stamp = STAMP.pack(time.monotonic())
        for link in links:
            link.sendall(stamp)


if __name__ == "__main__":
    print(json.dumps(receive(int(sys.argv[1]), int(sys.argv[2]))))
