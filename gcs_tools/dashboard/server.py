"""aiohttp server: the page, its static files, and a Server-Sent Events stream of telemetry frames.

The page (``/``) carries what it needs to start inline (``window.BOOT``: the palette, the counter
labels and, for ``/?snapshot=1``, the retained history), so it draws while it loads, without a
request of its own: ``chromium --headless --screenshot`` of ``/?snapshot=1`` shows the data at
once. ``/snapshot.json`` is the retained history once; ``/palette.json`` the colour of each
meaning, shared with the figures (:mod:`gcs_tools.palette`).
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import json
from pathlib import Path

from aiohttp import web

from companion.errors import UserError
from gcs_tools import palette
from gcs_tools.dashboard import labels
from gcs_tools.dashboard.state import LiveState

STATIC = Path(__file__).with_name("static")
FRAME_PERIOD_S = 0.05  # 20 Hz frames to the page
CLIENT_QUEUE_LEN = 64  # frames a slow browser may lag behind before frames are dropped for it


class Dashboard:
    def __init__(self, state: LiveState, frame_period_s: float = FRAME_PERIOD_S):
        self.state = state
        self.frame_period_s = frame_period_s
        self.clients: set[asyncio.Queue[str]] = set()
        self.frames_sent = 0

    def app(self) -> web.Application:
        app = web.Application()
        app.router.add_get("/", self.index)
        app.router.add_get("/events", self.events)
        app.router.add_get("/snapshot.json", self.snapshot)
        app.router.add_get("/palette.json", self.palette)
        app.router.add_static("/static/", STATIC)
        app.cleanup_ctx.append(self._ticker)
        return app

    async def index(self, request: web.Request) -> web.Response:
        boot: dict[str, object] = {"palette": palette.as_json(), "labels": labels.as_json()}
        if "snapshot" in request.query:
            boot["snapshot"] = self.state.snapshot()
        # JSON inside <script>: "</" is escaped so no payload text can close the element
        inline = json.dumps(boot, allow_nan=False).replace("</", "<\\/")
        html = (STATIC / "index.html").read_text(encoding="utf-8").replace(
            "<!--BOOT-->", f"<script>window.BOOT = {inline};</script>")
        return web.Response(text=html, content_type="text/html", headers={"Cache-Control": "no-cache"})

    async def snapshot(self, request: web.Request) -> web.Response:
        return web.json_response(self.state.snapshot(), headers={"Cache-Control": "no-cache"})

    async def palette(self, request: web.Request) -> web.Response:
        return web.json_response(palette.as_json())

    async def events(self, request: web.Request) -> web.StreamResponse:
        resp = web.StreamResponse(headers={"Content-Type": "text/event-stream", "Cache-Control": "no-cache"})
        await resp.prepare(request)
        queue: asyncio.Queue[str] = asyncio.Queue(maxsize=CLIENT_QUEUE_LEN)
        # snapshot and registration in one step of the loop: no frame is missed or doubled
        queue.put_nowait(json.dumps(self.state.snapshot()))
        self.clients.add(queue)
        try:
            while True:
                data = await queue.get()
                await resp.write(f"data: {data}\n\n".encode())
        except (ConnectionResetError, asyncio.CancelledError):
            pass
        finally:
            self.clients.discard(queue)
        return resp

    async def _ticker(self, app: web.Application):
        task = asyncio.create_task(self._tick_forever())
        yield
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task

    async def _tick_forever(self) -> None:
        while True:
            await asyncio.sleep(self.frame_period_s)
            frame = json.dumps(self.state.take_frame())
            self.frames_sent += 1
            for q in list(self.clients):
                if q.full():  # a stalled browser loses frames, never the server
                    continue
                q.put_nowait(frame)


async def serve(dashboard: Dashboard, host: str, port: int) -> web.AppRunner:
    """Start serving; a port in use is a one-line UserError."""
    runner = web.AppRunner(dashboard.app(), handle_signals=False)
    await runner.setup()
    try:
        await web.TCPSite(runner, host, port).start()
    except OSError as exc:
        await runner.cleanup()
        if exc.errno == errno.EADDRINUSE:
            raise UserError(f"port {port} on {host} is already in use (choose another with --port)") from None
        raise UserError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    return runner
