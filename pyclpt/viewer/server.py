"""The viewer's web server (aiohttp): the page, its script, and a WebSocket that streams the session's
pictures and takes camera moves and settings back.

The server runs on an asyncio loop in a thread of its own, beside the render thread
(:class:`~pyclpt.viewer.session.RenderSession`), so neither the caller nor the page ever waits for the
other: a Python prompt or notebook stays free, and the command line's main thread only waits for Ctrl-C.

Routes:

* ``GET /``: the page (``static/index.html``, ``static/viewer.js``);
* ``GET /frame.png``: the latest picture; ``GET /status``: the readouts as JSON;
* ``GET /ws``: the WebSocket. The server first sends ``{"type": "devices", "devices": [{"id": "1:0",
  "name": ..., "type": "CPU"}, ...]}`` (the choices of the device setting), then a JSON ``status`` message and
  the picture as a binary
  PNG message, each time there is a new one (only the newest: a slow page skips pictures, it never
  queues them; the status before a picture is the one it was made with). The page sends JSON:
  ``{"type": "camera", "op": "orbit", "yaw": 5, "pitch": 0}`` (and ``pan`` dx/dy, ``zoom`` factor,
  ``fly`` forward/right/up, ``reset``), ``{"type": "set", "name": "view", "value": "normal"}``,
  ``{"type": "set", "name": "device", "value": "1:0"}``, ``{"type": "viewport", "width": 800, "height": 600,
  "scale": 2}`` (the picture area in CSS pixels and the device pixel ratio: the frame follows it where the
  session has a ``max_size``), ``{"type": "save"}``, ``{"type": "lookat"}``, ``{"type": "keyframe", "op":
  "add"}`` (``clear``, ``play``, ``save``); the answers are ``size``/``saved``/``lookat``/``keyframes``/``error``
  messages. Every tab sees the same session.
"""
from __future__ import annotations

import asyncio
import json
import logging
import threading
import webbrowser
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from pyclpt.viewer.session import RenderSession

log = logging.getLogger("pyclpt.viewer")

STATIC = Path(__file__).resolve().parent / "static"
HOST = "127.0.0.1"


class Viewer:
    """The server of a :class:`RenderSession` on ``host``:``port`` (0: a free port), in its own thread.

    :meth:`start` returns once it listens (``url``); :meth:`close` stops the server and the render thread
    within a second; :meth:`wait` blocks until then (Ctrl-C closes it). In a notebook it shows itself as
    an IFrame of the page."""

    def __init__(self, session: RenderSession, *, host: str = HOST, port: int = 0) -> None:
        self.session = session
        self.host = host
        self.port = int(port)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._closed = threading.Event()
        self._startup_error: BaseException | None = None
        self._sockets: set[web.WebSocketResponse] = set()
        self._events: set[asyncio.Event] = set()
        self._runner: web.AppRunner | None = None
        self._stopping: asyncio.Event | None = None

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    # -- life ----------------------------------------------------------------------------------------
    def start(self, timeout: float = 10.0) -> Viewer:
        """Start the server thread and the render thread; OSError when the port cannot be had."""
        self._thread = threading.Thread(target=self._serve, name="pyclpt-viewer-server", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise RuntimeError(f"the viewer's server did not start within {timeout} s")
        if self._startup_error is not None:
            raise self._startup_error
        self.session.listeners.append(self._on_change)
        self.session.start()
        return self

    def close(self, timeout: float = 1.0) -> None:
        """Stop serving (every page is told the server went away) and the render thread."""
        if self._on_change in self.session.listeners:
            self.session.listeners.remove(self._on_change)
        self.session.close(timeout / 2)
        loop, stopping = self._loop, self._stopping
        if loop is not None and stopping is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(stopping.set)
            except RuntimeError:  # the loop has just closed
                pass
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout / 2)
        self._closed.set()

    def wait(self) -> None:
        """Block until :meth:`close`; Ctrl-C closes the viewer, then raises KeyboardInterrupt."""
        try:
            while not self._closed.wait(0.2):
                pass
        except KeyboardInterrupt:
            self.close()
            raise

    def __enter__(self) -> Viewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open_browser(self) -> bool:
        """Open the page in the default browser; False where none could be started."""
        try:
            return webbrowser.open(self.url)
        except webbrowser.Error:
            return False

    def _repr_html_(self) -> str:
        w, h = self.session.pr.width, self.session.pr.height
        return (f'<iframe src="{self.url}" width="{max(w + 300, 640)}" height="{max(h + 60, 400)}" '
                f'style="border:0"></iframe>')

    def __repr__(self) -> str:
        return f"Viewer({self.url}, scene={self.session.scene.name!r})"

    # -- the server thread ---------------------------------------------------------------------------
    def _serve(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._main())
        except BaseException as exc:  # reported to start(), or logged once serving
            if not self._ready.is_set():
                self._startup_error = exc
                self._ready.set()
            else:
                log.error("viewer: the server failed: %s", exc)
        finally:
            loop.close()
            self._closed.set()

    async def _main(self) -> None:
        self._stopping = asyncio.Event()
        app = web.Application()
        app.router.add_get("/", self._index)
        app.router.add_get("/frame.png", self._frame)
        app.router.add_get("/status", self._status)
        app.router.add_get("/ws", self._websocket)
        app.router.add_static("/static/", STATIC)
        self._runner = web.AppRunner(app, access_log=None, shutdown_timeout=0.25)
        await self._runner.setup()
        try:
            site = web.TCPSite(self._runner, self.host, self.port)
            await site.start()
            self.port = self._runner.addresses[0][1]
            self._ready.set()
            await self._stopping.wait()
        finally:
            for ws in list(self._sockets):
                await ws.close(code=1001, message=b"the viewer stopped")
            await self._runner.cleanup()

    def _on_change(self, session: RenderSession) -> None:
        """In the render thread: wake every WebSocket's sender."""
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        try:
            loop.call_soon_threadsafe(self._notify)
        except RuntimeError:  # closing
            pass

    def _notify(self) -> None:
        for ev in self._events:
            ev.set()

    # -- handlers ------------------------------------------------------------------------------------
    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / "index.html")

    async def _frame(self, request: web.Request) -> web.Response:
        self.session.touch()
        frame = self.session.frame
        if frame is None:
            return web.Response(status=503, text="no frame yet", headers={"Retry-After": "1"})
        return web.Response(body=frame.png, content_type="image/png", headers={"Cache-Control": "no-store"})

    async def _status(self, request: web.Request) -> web.Response:
        self.session.touch()
        return web.json_response(self.session.status())

    async def _websocket(self, request: web.Request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(heartbeat=10.0)
        await ws.prepare(request)
        self._sockets.add(ws)
        event = asyncio.Event()
        event.set()  # the current picture at once
        self._events.add(event)
        self.session.client_connected()
        await ws.send_json({"type": "devices", "devices": self.session.devices()})
        sender = asyncio.ensure_future(self._send_frames(ws, event))
        try:
            async for msg in ws:
                if msg.type != WSMsgType.TEXT:
                    continue
                reply = await self._command(msg.data)
                if reply is not None and not ws.closed:
                    await ws.send_json(reply)
        finally:
            sender.cancel()
            self._events.discard(event)
            self._sockets.discard(ws)
            self.session.client_disconnected()
        return ws

    async def _send_frames(self, ws: web.WebSocketResponse, event: asyncio.Event) -> None:
        sent_version, sent_frame = -1, -1
        try:
            while not ws.closed:
                await event.wait()
                event.clear()
                session = self.session
                if session.version == sent_version:
                    continue
                sent_version = session.version
                frame = session.frame
                if frame is not None and frame.index != sent_frame:
                    sent_frame = frame.index
                    await ws.send_json(frame.status)  # the readouts as the picture was made
                    await ws.send_bytes(frame.png)
                else:
                    await ws.send_json(session.status())
        except (ConnectionError, RuntimeError):  # the page went away while sending
            pass

    async def _command(self, text: str) -> dict[str, Any] | None:
        """One message of the page; the answer to send back (None: nothing)."""
        try:
            msg = json.loads(text)
            if not isinstance(msg, dict):
                raise ValueError("a message must be a JSON object")
            kind = msg.get("type")
            s = self.session
            if kind == "camera":
                args = {k: float(v) for k, v in msg.items() if k not in ("type", "op")}
                s.move(str(msg.get("op")), **args)  # not awaited: the render thread takes every move queued
                return None  # so far before its next frame, as one
            if kind == "set":
                await asyncio.wrap_future(s.set(str(msg.get("name")), msg.get("value")))
                return None
            if kind == "viewport":
                w, h = await asyncio.wrap_future(s.fit(msg.get("width"), msg.get("height"), msg.get("scale", 1.0)))
                return {"type": "size", "width": w, "height": h, "follows_window": s.max_size is not None}
            if kind == "save":
                return {"type": "saved", "paths": await asyncio.wrap_future(s.save())}
            if kind == "keyframe":
                done = await asyncio.wrap_future(s.keyframe(str(msg.get("op")), msg.get("spacing", 30)))
                return {"type": "keyframes", "op": msg.get("op"), **done}
            if kind == "lookat":
                path, xml = await asyncio.wrap_future(s.write_lookat())
                return {"type": "lookat", "path": path, "xml": xml}
            if kind == "ping":
                s.touch()
                return None
            raise ValueError(f"unknown message type {kind!r} (camera, set, viewport, save, lookat, keyframe, "
                             f"ping)")
        except (ValueError, TypeError, OSError) as exc:  # a bad message or setting, a file not written
            return {"type": "error", "message": str(exc)}
        except Exception as exc:  # anything else (a rebuild that failed to compile): the page and the terminal
            log.error("viewer: %s failed: %s", text[:80], exc)
            return {"type": "error", "message": f"{type(exc).__name__}: {exc}"}


def view(scene: Any, *, port: int = 0, host: str = HOST, open_browser: bool = True, block: bool = False,
         width: int | None = None, height: int | None = None, spp_per_frame: int = 1, max_depth: int | None = None,
         denoiser: str | None = "svgf", integrator: str = "megakernel", layout: str = "soa", device: Any = None,
         seed: int = 0, exposure: float = 0.0, view: str | None = None, output_dir: str | Path = ".",
         idle_after: float = 2.0, max_size: int | None = None) -> Viewer:
    """Render ``scene`` (a Scene, a built-in scene's name or a scene file) live in the browser: starts a
    :class:`Viewer` on ``host``:``port`` (0: a free port), opens the page unless ``open_browser`` is False,
    and returns it (``viewer.url``; ``viewer.close()``). ``block``: wait until Ctrl-C (a script), instead of
    returning at once (a notebook, where the viewer shows itself as an IFrame). The other arguments are
    :class:`RenderSession`'s. Without ``width`` and ``height`` the frame follows the page's window, with the
    scene's aspect and a longer side of at most ``max_size`` pixels (default 640); with either, it stays at
    that size (the other side from the scene's aspect)."""
    from pyclpt.scene.library import load
    from pyclpt.scene.model import Scene

    if not isinstance(scene, Scene):
        scene = load(scene)
    follow = width is None and height is None
    max_size = DEFAULT_MAX_SIDE if max_size is None else max_size
    width, height = frame_size(scene, width, height, max_size)
    session = RenderSession(scene, width=width, height=height, spp_per_frame=spp_per_frame, max_depth=max_depth,
                            denoiser=denoiser, integrator=integrator, layout=layout, device=device, seed=seed,
                            exposure=exposure, view=view, output_dir=output_dir, idle_after=idle_after,
                            max_size=max_size if follow else None)
    viewer = Viewer(session, host=host, port=port).start()
    if open_browser and not viewer.open_browser():
        log.warning("viewer: no browser could be opened; open %s", viewer.url)
    if block:
        viewer.wait()
    return viewer


# The longest side of the default frame (and of a frame that follows the window, --max-size): the scene's film
# scaled down to it, its aspect kept.
DEFAULT_MAX_SIDE = 640


def default_size(width: int, height: int, max_side: int = DEFAULT_MAX_SIDE) -> tuple[int, int]:
    """The scene's film size scaled down (never up) so that its longer side is at most ``max_side``."""
    scale = min(1.0, max_side / max(width, height))
    return max(1, round(width * scale)), max(1, round(height * scale))


def frame_size(scene: Any, width: int | None, height: int | None,
               max_side: int = DEFAULT_MAX_SIDE) -> tuple[int, int]:
    """The viewer's frame size: ``width`` x ``height`` as given; one of them given, the other from the
    scene's aspect; neither, :func:`default_size` of the scene's film (longer side at most ``max_side``)."""
    w, h = default_size(scene.film.width, scene.film.height, max_side)
    if width is not None and height is not None:
        return width, height
    if width is not None:
        return width, max(1, round(width * h / w))
    if height is not None:
        return max(1, round(height * w / h)), height
    return w, h
