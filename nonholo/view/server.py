"""The page's server: HTTP and a WebSocket with aiohttp, on loopback, behind a token.

aiohttp because it is asyncio, like the fleet runtime, and serves HTTP and WebSockets from one
maintained package with no ASGI server to pair it with. The server runs its own event loop on
a thread of its own, so a page never slows the fleet, and the fleet hands it snapshots through
the latest-wins ``LatestFeed``.

Every request needs ``?token=`` equal to the server's random token (compared in constant
time); otherwise the answer is 403 with the body ``forbidden`` and nothing else. The server
only answers GET: the page, its two assets, ``/data`` (the page's JSON: a replay, or a live
fleet's robots, links and reference) and ``/live`` (a WebSocket of the newest snapshots, at
most ``RATE_HZ`` a second, at most ``MAX_CLIENTS`` at once; a client that does not take a
message within ``SEND_TIMEOUT_S`` is dropped).

Connections are bounded whoever opens them: at most ``MAX_CONNECTIONS`` at once, and one that
has not made a request with the token within ``REQUEST_DEADLINE_S`` of connecting is closed
(slow or silent clients, floods). When all are taken, a new connection closes one of those not
yet proven, chosen at random, so that a flood cannot keep a page out; with none to close, it
is refused. A proven connection idle for ``KEEPALIVE_S`` is closed. Malformed requests get
aiohttp's 400 answer and nothing on the terminal; responses name no server software.
"""
from __future__ import annotations

import asyncio
import json
import logging
import random
import secrets
import socket
import threading
from importlib import resources

from nonholo.view import require

RATE_HZ = 20.0
MAX_CLIENTS = 16
SEND_TIMEOUT_S = 2.0
MAX_CONNECTIONS = 64
REQUEST_DEADLINE_S = 5.0
KEEPALIVE_S = 15.0
START_TIMEOUT_S = 10.0
STOP_TIMEOUT_S = 5.0
ASSETS = {"/": ("index.html", "text/html"), "/view.js": ("view.js", "text/javascript"),
          "/view.css": ("view.css", "text/css")}
HEADERS = {"Cache-Control": "no-store", "Referrer-Policy": "no-referrer", "X-Content-Type-Options": "nosniff",
           "X-Frame-Options": "DENY",
           "Content-Security-Policy": "default-src 'self'; connect-src 'self'; img-src 'self' data:; "
                                      "style-src 'self'; script-src 'self'; frame-ancestors 'none'"}


def asset(name: str) -> bytes:
    return resources.files("nonholo.view").joinpath("static", name).read_bytes()


def quiet_logger() -> logging.Logger:
    """aiohttp's request-error log for the page server: dropped (a malformed request from
    anyone must not write tracebacks to the terminal)."""
    logger = logging.getLogger("nonholo.view.http")
    logger.propagate = False
    if not logger.handlers:
        logger.addHandler(logging.NullHandler())
    return logger


class ConnectionGate:
    """Every connection to the page server, bounded (see the module docstring): wraps the
    HTTP protocol factory ``factory``; ``prove(transport)`` marks a connection that made a
    request with the token."""

    def __init__(self, factory, limit: int, deadline_s: float) -> None:
        self.factory, self.limit, self.deadline_s = factory, limit, deadline_s
        self.open: dict = {}        # transport -> its GatedConnection
        self.unproven: dict = {}    # transport -> None: not yet a request with the token
        self.refused = self.evicted = self.expired = 0

    def __call__(self) -> "GatedConnection":
        return GatedConnection(self)

    def admit(self, transport) -> bool:
        if len(self.open) >= self.limit:
            if not self.unproven:
                self.refused += 1
                return False
            self.evicted += 1
            self.close(random.choice(list(self.unproven)))
        return True

    def prove(self, transport) -> None:
        if transport in self.unproven:
            del self.unproven[transport]
            connection = self.open.get(transport)
            if connection is not None and connection.timer is not None:
                connection.timer.cancel()

    def close(self, transport) -> None:
        self.open.pop(transport, None)
        self.unproven.pop(transport, None)
        transport.abort()

    def expire(self, transport) -> None:
        if transport in self.unproven:
            self.expired += 1
            self.close(transport)


class GatedConnection(asyncio.Protocol):
    """One connection through a ``ConnectionGate``: aiohttp's protocol inside, counted, on a
    deadline until proven."""

    def __init__(self, gate: ConnectionGate) -> None:
        self.gate, self.inner, self.timer, self.transport = gate, None, None, None

    def connection_made(self, transport) -> None:
        if not self.gate.admit(transport):
            transport.abort()
            return
        self.transport = transport
        self.gate.open[transport] = self
        self.gate.unproven[transport] = None
        self.timer = asyncio.get_running_loop().call_later(self.gate.deadline_s, self.gate.expire, transport)
        self.inner = self.gate.factory()
        self.inner.connection_made(transport)

    def connection_lost(self, exc) -> None:
        if self.timer is not None:
            self.timer.cancel()
        if self.transport is not None:
            self.gate.open.pop(self.transport, None)
            self.gate.unproven.pop(self.transport, None)
        if self.inner is not None:
            self.inner.connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        if self.inner is not None:
            self.inner.data_received(data)

    def eof_received(self):
        return self.inner.eof_received() if self.inner is not None else None

    def pause_writing(self) -> None:
        if self.inner is not None:
            self.inner.pause_writing()

    def resume_writing(self) -> None:
        if self.inner is not None:
            self.inner.resume_writing()


class ViewServer:
    """Serve the page of ``page()`` (a callable returning the page's JSON) and, with a
    ``feed`` (``nonholo.view.feed.LatestFeed``), its live snapshots.

    ``start()`` binds ``host:port`` (0: a free port from the OS) and serves from a thread;
    ``url`` is the address with the token; ``stop()`` closes every connection."""

    def __init__(self, page, feed=None, host: str = "127.0.0.1", port: int = 0, token: str | None = None) -> None:
        require("aiohttp")
        self.page, self.feed, self.host, self.port = page, feed, host, port
        self.token = token or secrets.token_urlsafe(24)
        self._page_text: tuple[int, bytes] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._runner = None
        self._clients: set = set()
        self.gate: ConnectionGate | None = None
        self._started = threading.Event()
        self._error: BaseException | None = None
        self.refused = 0

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/?token={self.token}"

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> "ViewServer":
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind((self.host, self.port))
            sock.listen(64)
        except OSError:
            sock.close()
            raise
        self.port = sock.getsockname()[1]
        self._thread = threading.Thread(target=self._serve, args=(sock,), name="nonholo-view", daemon=True)
        self._thread.start()
        if not self._started.wait(START_TIMEOUT_S) or self._error is not None:
            self.stop()
            raise OSError(f"the page server did not start: {self._error or 'timeout'}")
        return self

    def stop(self) -> None:
        loop, thread, stopping = self._loop, self._thread, getattr(self, "_stopping", None)
        if loop is not None and thread is not None and thread.is_alive() and stopping is not None:
            try:
                loop.call_soon_threadsafe(stopping.set)
            except RuntimeError:   # the loop has just closed
                return
            thread.join(STOP_TIMEOUT_S)

    def __enter__(self) -> "ViewServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def _serve(self, sock: socket.socket) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._main(sock))
        except BaseException as exc:   # reported to start(); the thread must end quietly
            self._error = exc
            self._started.set()
        finally:
            loop.close()

    async def _main(self, sock: socket.socket) -> None:
        from aiohttp import web

        self._stopping = asyncio.Event()
        @web.middleware
        async def guard(request, handler):
            return await self._guard(request, handler)

        async def anonymous(request, response):
            response.headers["Server"] = "nonholo"

        app = web.Application(middlewares=[guard], client_max_size=1024)
        app.on_response_prepare.append(anonymous)
        for path in ASSETS:
            app.router.add_get(path, self._asset)
        app.router.add_get("/data", self._data)
        app.router.add_get("/live", self._live)
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False, shutdown_timeout=1.0,
                                     keepalive_timeout=KEEPALIVE_S, logger=quiet_logger())
        await self._runner.setup()
        self.gate = ConnectionGate(self._runner.server, MAX_CONNECTIONS, REQUEST_DEADLINE_S)
        server = await asyncio.get_running_loop().create_server(self.gate, sock=sock)
        self._started.set()
        try:
            await self._stopping.wait()
        finally:
            server.close()
            for ws in list(self._clients):
                await ws.close()
            await self._runner.cleanup()
            for transport in list(self.gate.open):
                self.gate.close(transport)

    # ------------------------------------------------------------------ handlers
    async def _guard(self, request, handler):
        from aiohttp import web

        given = request.query.get("token", "")
        if not secrets.compare_digest(given.encode(), self.token.encode()) or request.method not in ("GET", "HEAD"):
            self.refused += 1
            return web.Response(status=403, text="forbidden")
        if self.gate is not None and request.transport is not None:
            self.gate.prove(request.transport)
        response = await handler(request)
        if not getattr(response, "prepared", False):
            response.headers.update(HEADERS)
        return response

    async def _asset(self, request):
        from aiohttp import web

        name, kind = ASSETS[request.path]
        body = asset(name)
        if name == "index.html":   # the token (URL-safe base64) for the page's own requests
            body = body.replace(b"{{TOKEN}}", self.token.encode())
        return web.Response(body=body, content_type=kind)

    async def _data(self, request):
        from aiohttp import web

        page = self.page() if self.feed is None else self.feed.page()
        return web.Response(text=json.dumps(page, separators=(",", ":"), allow_nan=False),
                            content_type="application/json")

    async def _live(self, request):
        from aiohttp import web

        if self.feed is None or len(self._clients) >= MAX_CLIENTS:
            return web.Response(status=503, text="no live feed here" if self.feed is None else "too many pages")
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=1024)
        await ws.prepare(request)
        self._clients.add(ws)
        reader = asyncio.ensure_future(self._drain(ws))
        sent = -1
        try:
            while not ws.closed and not reader.done() and not self._stopping.is_set():
                version, text = self.feed.latest()
                if version != sent and text is not None:
                    await asyncio.wait_for(ws.send_str(text), SEND_TIMEOUT_S)
                    sent = version
                await asyncio.sleep(1.0 / RATE_HZ)
        except (asyncio.TimeoutError, ConnectionError):
            pass
        finally:
            self._clients.discard(ws)
            reader.cancel()
            await asyncio.gather(reader, return_exceptions=True)
            await ws.close()
        return ws

    @staticmethod
    async def _drain(ws) -> None:
        """Read and ignore what a page sends (the page is read-only); ends when it closes."""
        async for _ in ws:
            pass
