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
"""
from __future__ import annotations

import asyncio
import json
import secrets
import socket
import threading
from importlib import resources

from nonholo.view import require

RATE_HZ = 20.0
MAX_CLIENTS = 16
SEND_TIMEOUT_S = 2.0
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

        app = web.Application(middlewares=[guard], client_max_size=1024)
        for path in ASSETS:
            app.router.add_get(path, self._asset)
        app.router.add_get("/data", self._data)
        app.router.add_get("/live", self._live)
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False, shutdown_timeout=1.0)
        await self._runner.setup()
        await web.SockSite(self._runner, sock).start()
        self._started.set()
        try:
            await self._stopping.wait()
        finally:
            for ws in list(self._clients):
                await ws.close()
            await self._runner.cleanup()

    # ------------------------------------------------------------------ handlers
    async def _guard(self, request, handler):
        from aiohttp import web

        given = request.query.get("token", "")
        if not secrets.compare_digest(given.encode(), self.token.encode()) or request.method not in ("GET", "HEAD"):
            self.refused += 1
            return web.Response(status=403, text="forbidden")
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
