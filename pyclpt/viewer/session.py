"""A live render session: a :class:`~pyclpt.rendering.progressive.ProgressiveRenderer` driven by its own
thread, which renders frame after frame, turns each into the picture the viewer shows (the plain
average, the denoised frame, an AOV or the samples per pixel; tonemapped; PNG) and hands it to whoever
listens (the server).

Everything that touches the renderer runs in that thread: camera moves, setting changes (the device
among them: a new renderer on it) and the window's size from the page are queued
(:meth:`RenderSession.submit`) and applied between frames, several camera moves at once as one.
Without a listener for ``idle_after`` seconds (a closed tab, a lost connection) the thread stops
rendering and waits; a new client wakes it. :meth:`RenderSession.close` ends it within a frame.
Needs no web server: tests and scripts can drive it directly.
"""
from __future__ import annotations

import concurrent.futures
import copy
import dataclasses
import json
import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pyopencl as cl

from pyclpt.common.image_io import check_exposure, write_image
from pyclpt.device.context import get_device, list_devices
from pyclpt.rendering.progressive import ProgressiveRenderer
from pyclpt.scene.camera_path import CameraPath, Keyframe
from pyclpt.scene.model import Camera, Scene
from pyclpt.viewer.camera import OrbitCamera, camera_path_to_json
from pyclpt.viewer.display import VIEWS, aov_to_display, encode_png, samples_to_display, tonemap_fast

log = logging.getLogger("pyclpt.viewer")

DENOISERS = ("off", "blend", "svgf")  # oidn runs on the host at about a second a frame: not live
INTEGRATORS = ("megakernel", "wavefront")
LAYOUTS = ("soa", "aos")
# The G-buffer a renderer records for the AOV views when it has no denoiser (a denoiser records all of it).
VIEW_AOVS = ("albedo", "normal", "depth", "motion")
MAX_SPP_PER_FRAME = 64
# At most this many pictures a second (a screen shows no more); a faster render skips making some.
MAX_PICTURE_RATE = 60.0
# Bounds of max depth from the page (-1: unlimited, as Mitsuba).
MAX_DEPTH_LIMIT = 1024
# Frames between two recorded keyframes when the path is played or saved.
KEYFRAME_SPACING = 30
KEYFRAME_OPS = ("add", "clear", "play", "save")
# The kernels the page's time bars show, the longest first.
MAX_KERNEL_ROWS = 8
# The smallest side of a frame that follows the window (a window dragged narrow still shows a picture).
MIN_SIDE = 8
# The largest max_size a session takes (a longer side of 8192 pixels: 8K).
MAX_SIZE_LIMIT = 8192


@dataclasses.dataclass(frozen=True)
class Frame:
    """One picture of the session: ``index`` counts the pictures made; ``png`` is what the page shows."""

    index: int
    png: bytes
    width: int
    height: int
    spp: int  # samples per pixel in the plain average shown (the denoised frame's history can be longer)
    seconds: float  # render, read-back and encoding of this picture
    status: dict  # RenderSession.status() as this picture was made: the readouts that go with it


def _is_integer(value: object, lo: int, hi: int) -> bool:
    """An integer (or a float with an integer value, as JSON numbers come) in [lo, hi]."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    return math.isfinite(value) and value == int(value) and lo <= value <= hi


def _setting_error(name: str, value: object, allowed: str) -> ValueError:
    return ValueError(f"setting {name}: {value!r} is not {allowed}")


def fit_size(width: int, height: int, view_width: float, view_height: float, max_size: int) -> tuple[int, int]:
    """The frame of ``width`` x ``height``'s aspect that fills a ``view_width`` x ``view_height`` window
    (device pixels) without cropping, its longer side at most ``max_size``, each side at least MIN_SIDE
    (where the aspect allows: the shorter side of a very long film may be less)."""
    scale = min(view_width / width, view_height / height, max_size / max(width, height))
    scale = max(scale, MIN_SIDE / min(width, height))
    scale = min(scale, max_size / max(width, height))  # the cap wins over the minimum
    return max(1, round(width * scale)), max(1, round(height * scale))


def device_id(platform: int, device: int) -> str:
    """A device's selector as ``pyclpt devices`` lists it: ``P:D``."""
    return f"{platform}:{device}"


class RenderSession:
    """The scene rendered progressively in a thread of its own (:meth:`start`), as the viewer shows it.

    ``denoiser``: off, blend or svgf (a camera move then keeps the denoiser's history, reprojected;
    without a denoiser the average restarts). ``view``: what the pictures show (color, denoised,
    albedo, normal, depth, motion, samples; default denoised with a denoiser, else color). ``max_size``:
    the frame follows the page's window (:meth:`fit`), the scene's aspect kept, its longer side at most
    this many pixels; None: the frame stays ``width`` x ``height``. ``device``: a Device, a selector
    (``pyclpt devices``) or None (the default); the page can switch to any device :meth:`devices` lists.
    ``output_dir``: where :meth:`save` and :meth:`write_lookat` write. The renderer is made (its programs
    compiled) here, so a bad device or scene raises before any server starts."""

    def __init__(self, scene: Scene, *, width: int | None = None, height: int | None = None,
                 spp_per_frame: int = 1, max_depth: int | None = None, denoiser: str | None = "svgf",
                 integrator: str = "megakernel", layout: str = "soa", device: Any = None, seed: int = 0,
                 exposure: float = 0.0, view: str | None = None, output_dir: str | Path = ".",
                 idle_after: float = 2.0, max_size: int | None = None) -> None:
        if not isinstance(scene, Scene):
            raise TypeError(f"scene must be a pyclpt.Scene (pyclpt.load makes one), got {type(scene).__name__}")
        self.scene = copy.copy(scene)  # the session sets its camera and max depth; the caller's scene keeps its own
        self.orbit = OrbitCamera(scene)
        self.settings: dict[str, Any] = {"spp_per_frame": 1, "max_depth": scene.max_depth, "denoiser": "off",
                                         "integrator": "megakernel", "layout": "soa", "exposure": 0.0,
                                         "view": "color"}
        self._set("spp_per_frame", spp_per_frame)
        if max_depth is not None:
            self._set("max_depth", max_depth)
        self._set("denoiser", denoiser or "off")
        self._set("integrator", integrator)
        self._set("layout", layout)
        self._set("exposure", exposure)
        self._set("view", view or ("denoised" if self.settings["denoiser"] != "off" else "color"))
        self.output_dir = Path(output_dir)
        self.idle_after = float(idle_after)
        self._size = (width, height) if width is not None or height is not None else (None, None)
        if max_size is not None and not _is_integer(max_size, MIN_SIDE, MAX_SIZE_LIMIT):
            raise ValueError(f"max_size must be an integer number of pixels in {MIN_SIDE}..{MAX_SIZE_LIMIT} "
                             f"(None: a fixed frame size), got {max_size!r}")
        self.max_size = None if max_size is None else int(max_size)
        self._target_size: tuple[int, int] | None = None  # the size the page's window asked for last
        self._device, self._seed = device, int(seed)
        self.error: str | None = None  # the last failure of the render thread, shown by the page
        self.frame: Frame | None = None
        self.frames = 0  # pictures made
        self.fps = 0.0  # frames (steps of spp_per_frame samples) rendered per second
        self.pictures_fps = 0.0  # pictures made per second (at most MAX_PICTURE_RATE)
        self.kernels: list[dict] = []  # device ms per frame of the slowest kernels (renderer and denoiser)
        self.version = 0  # bumped by every new picture or status change
        self.listeners: list[Callable[[RenderSession], None]] = []
        self.clients = 0
        self.rendering = False
        self._last_seen = time.monotonic()
        self._last_publish: float | None = None
        self._picture_seconds = 0.0  # the last picture's render, read-back and encoding
        self._last_rate: tuple[float, int, int] | None = None  # (time, frames rendered, pictures) at the last rate
        self._rendered = 0  # frames rendered by this session
        self._force_picture = True  # the next frame makes a picture whatever the rate cap
        self._commands: queue.SimpleQueue = queue.SimpleQueue()
        self._camera_moved = False
        self.keyframes: list[Camera] = []  # cameras recorded from the page (Camera), KEYFRAME_SPACING frames apart
        self._playback: tuple[CameraPath, float] | None = None  # the path played and its next frame time
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._changed = threading.Condition()
        self._thread: threading.Thread | None = None
        self.pr = self._make_renderer()
        self._devices = self._list_devices()
        self.settings["device"] = self._device_id(self.pr.device.device)

    # -- settings ----------------------------------------------------------------------------------
    def _set(self, name: str, value: Any) -> bool:
        """Check and store one setting; True when it changed."""
        if name == "spp_per_frame":
            if not _is_integer(value, 1, MAX_SPP_PER_FRAME):
                raise _setting_error(name, value, f"an integer in 1..{MAX_SPP_PER_FRAME}")
            value = int(value)
        elif name == "max_depth":
            if not _is_integer(value, -1, MAX_DEPTH_LIMIT):
                raise _setting_error(name, value, f"an integer in -1..{MAX_DEPTH_LIMIT} (-1: unlimited)")
            value = int(value)
        elif name in (choices := {"denoiser": DENOISERS, "integrator": INTEGRATORS, "layout": LAYOUTS,
                                   "view": VIEWS}):
            if value not in choices[name]:
                raise _setting_error(name, value, f"one of {', '.join(choices[name])}")
        elif name == "exposure":
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise _setting_error(name, value, "a number of stops")
            value = check_exposure(value)
        elif name == "device":
            ids = [d["id"] for d in self._devices]
            if value not in ids:
                raise _setting_error(name, value, f"one of the OpenCL devices {', '.join(ids)} (pyclpt devices)")
        else:
            raise ValueError(f"unknown setting {name!r} (settings: {', '.join(self.settings)})")
        changed = self.settings.get(name) != value
        self.settings[name] = value
        return changed

    def _make_renderer(self) -> ProgressiveRenderer:
        s = self.settings
        denoiser = None if s["denoiser"] == "off" else s["denoiser"]
        self.scene.camera = self.orbit.camera()
        self.scene.max_depth = s["max_depth"]
        aovs = VIEW_AOVS if denoiser is None and s["view"] in VIEW_AOVS else None
        w, h = self._size
        return ProgressiveRenderer(self.scene, seed=self._seed, integrator=s["integrator"], layout=s["layout"],
                                   width=w, height=h, device=self._device, denoiser=denoiser, aovs=aovs)

    def _list_devices(self) -> list[dict[str, str]]:
        """The OpenCL devices the page offers: id (``P:D``), name, type."""
        return [{"id": device_id(p, i), "name": f"{d.platform.name.strip()} / {d.name.strip()}",
                 "type": "GPU" if d.type & cl.device_type.GPU else "CPU" if d.type & cl.device_type.CPU else "other"}
                for p, i, d in list_devices()]

    def _device_id(self, device: Any) -> str | None:
        for p, i, d in list_devices():
            if d == device:
                return device_id(p, i)
        return None

    def devices(self) -> list[dict[str, str]]:
        """The OpenCL devices the page's device setting offers (``pyclpt devices``' list): dicts with
        ``id`` (``P:D``, the selector), ``name`` and ``type``."""
        return [dict(d) for d in self._devices]

    def _switch_device(self, previous: str | None) -> None:
        """A new renderer on the device of settings["device"]; on failure the previous one stays."""
        old_device, old_pr = self._device, self.pr
        try:
            self._device = get_device(self.settings["device"])
            self.pr = self._make_renderer()
        except BaseException:
            self._device, self.pr, self.settings["device"] = old_device, old_pr, previous
            raise
        log.info("viewer: rendering on %s", self.pr.device.name)

    def _apply(self, name: str, value: Any) -> None:
        """A setting changed from the page, in the render thread: rebuild what it needs."""
        previous = self.settings.get(name)
        if not self._set(name, value):
            return
        if name == "device":
            self._switch_device(previous)
        elif name in ("denoiser", "integrator", "layout"):
            self.pr = self._make_renderer()
        elif name == "view" and value in VIEW_AOVS and value not in self.pr.aov_names:
            self.pr = self._make_renderer()  # the G-buffer is recorded from now on
        elif name == "max_depth":
            self.scene.max_depth = self.settings["max_depth"]
            self.pr.sync()

    # -- the thread's side -------------------------------------------------------------------------
    def submit(self, fn: Callable[[], Any]) -> concurrent.futures.Future:
        """Run ``fn()`` in the render thread between two frames (at once when it is not started);
        the future holds its result or exception."""
        fut: concurrent.futures.Future = concurrent.futures.Future()
        if self._thread is None or not self._thread.is_alive():
            self._run_one(fn, fut)
        else:
            self._commands.put((fn, fut))
            self._wake.set()
        return fut

    def _run_one(self, fn: Callable[[], Any], fut: concurrent.futures.Future) -> None:
        if not fut.set_running_or_notify_cancel():
            return
        try:
            fut.set_result(fn())
        except Exception as exc:  # the caller sees it through the future
            fut.set_exception(exc)

    def _drain(self) -> bool:
        """Run the queued commands, then move the renderer's camera once; True if anything ran."""
        ran = False
        while True:
            try:
                fn, fut = self._commands.get_nowait()
            except queue.Empty:
                break
            self._run_one(fn, fut)
            ran = True
            self._force_picture = True  # what changed shows in the very next frame
        if self._camera_moved:
            self._camera_moved = False
            self.pr.set_camera(self.orbit.camera())
        return ran

    def start(self) -> RenderSession:
        """Start the render thread (a daemon: it never keeps the interpreter alive)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._loop, name="pyclpt-viewer-render", daemon=True)
            self._thread.start()
        return self

    def close(self, timeout: float = 1.0) -> None:
        """Stop the render thread: it ends after the frame in progress (waited for up to ``timeout`` s)."""
        self._stop.set()
        self._wake.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _active(self) -> bool:
        return self.frame is None or self.clients > 0 or time.monotonic() - self._last_seen < self.idle_after

    def _loop(self) -> None:
        while not self._stop.is_set():
            try:
                ran = self._drain()
                if self.error is not None and not ran:  # wait for a change from the page before trying again
                    self._idle()
                    continue
                if ran:
                    self.error = None
                if not self._active():
                    self._idle()
                    continue
                if not self.rendering:
                    self.rendering = True
                    self._bump()
                self._render()
            except Exception as exc:  # the page and the terminal say what failed; the server goes on
                message = str(exc) or type(exc).__name__
                log.error("viewer: rendering failed: %s", message)
                self.error = message
                self._bump()
        self.rendering = False

    def _idle(self) -> None:
        if self.rendering:
            self.rendering = False
            log.info("viewer: no page connected for %.1f s: rendering paused", self.idle_after)
            self._bump()
        self._wake.wait(0.25)
        self._wake.clear()

    def _render(self) -> None:
        start = time.perf_counter()
        if self._playback is not None:  # the next camera of the path played
            path, t = self._playback
            self.orbit.look(path.camera(t))
            self.pr.set_camera(self.orbit.camera())
            self._playback = (path, t + 1) if t + 1 <= path.keyframes[-1].time else None
        done = self.pr.step(self.settings["spp_per_frame"])
        if done == 0:  # the accumulation has stopped: nothing new to show
            self._idle()
            return
        self._rendered += 1
        # the step only enqueues its frames (the renderer's pacer lets a quarter second of them queue up): wait
        # for them, so that the rate cap below counts finished frames and a camera move shows in the next one
        self.pr.renderer.pacer.wait(self.pr.device.queue)
        t = time.perf_counter()
        if not self._force_picture and self._last_publish is not None \
                and t - self._last_publish < 1.0 / MAX_PICTURE_RATE:
            return  # faster than a screen shows: the next frame makes the picture
        self._force_picture = False
        pixels = self.picture()
        png = encode_png(pixels)
        now = time.perf_counter()
        self.frames += 1
        # frames and pictures per second over a quarter of a second (the first estimate from the first two)
        if self._last_rate is None or now - self._last_rate[0] > 0.25 or self.fps == 0:
            if self._last_rate is not None:
                t0, rendered, made = self._last_rate
                rate, pictures = (self._rendered - rendered) / (now - t0), (self.frames - made) / (now - t0)
                first = self.fps == 0
                self.fps = rate if first else 0.5 * self.fps + 0.5 * rate
                self.pictures_fps = pictures if first else 0.5 * self.pictures_fps + 0.5 * pictures
                self.kernels = self._kernel_times(self._rendered - rendered)
            self._last_rate = (now, self._rendered, self.frames)
        self._last_publish = now
        self._picture_seconds = now - start
        self.frame = Frame(self.frames, png, pixels.shape[1], pixels.shape[0], self.pr.frame_count, now - start,
                           self.status())
        self._bump()

    def _kernel_times(self, frames: int) -> list[dict]:
        """The device time per frame of each kernel (the renderer's and the denoiser's) over the last
        ``frames`` frames, the longest first, from their profiling events, which are then dropped (a
        session that runs for hours would otherwise keep every event)."""
        profiles = [self.pr.renderer.integrator.profile]
        if self.pr.denoiser is not None:
            profiles.append(self.pr.denoiser.profile)
        rows = [row for profile in profiles for row in profile.table()]
        for profile in profiles:
            profile.clear()
        rows.sort(key=lambda r: -r["total_ms"])
        return [{"kernel": r["kernel"], "ms": round(r["total_ms"] / max(frames, 1), 3)} for r in rows[:MAX_KERNEL_ROWS]]

    def _bump(self) -> None:
        with self._changed:
            self.version += 1
            self._changed.notify_all()
        for listener in list(self.listeners):
            listener(self)

    # -- what is shown -----------------------------------------------------------------------------
    def shown_view(self) -> str:
        """The view the pictures show: ``denoised`` falls back to ``color`` without a denoiser."""
        view = self.settings["view"]
        return "color" if view == "denoised" and self.pr.denoiser is None else view

    def picture(self):
        """The current picture, (H, W, 3) uint8, in the render thread (or before :meth:`start`)."""
        view, exposure = self.shown_view(), self.settings["exposure"]
        if view == "color":
            return tonemap_fast(self.pr.image(), exposure)
        if view == "denoised":
            return tonemap_fast(self.pr.denoised(), exposure)
        if view == "samples":
            return samples_to_display(self.sample_counts())
        return aov_to_display(view, self.pr.aovs([view])[view])

    def sample_counts(self) -> np.ndarray:
        """Samples per pixel of the plain average, (H, W) int64. The renderer is not adaptive: every
        pixel has the same count, the frames accumulated so far (a camera move without a denoiser, a
        change of resolution or of the scene restarts it)."""
        return np.full((self.pr.height, self.pr.width), self.pr.frame_count, np.int64)

    def radiance(self):
        """The image a save writes: the denoised frame with a denoiser, else the plain average."""
        if self.pr.denoiser is not None and self.pr.frame_index > 0:
            return self.pr.denoised()
        return self.pr.image()

    def status(self) -> dict[str, Any]:
        """What the page's readouts show (JSON-ready)."""
        pr = self.pr
        return {"type": "status", "frame": self.frames, "spp": pr.frame_count, "sample_index": pr.sample_index,
                "fps": round(self.fps, 2), "pictures_fps": round(self.pictures_fps, 2),
                "frame_ms": round(self._picture_seconds * 1e3, 2) if self.frames else None,
                "width": pr.width, "height": pr.height, "shown": self.shown_view(), "settings": dict(self.settings),
                "device": pr.device.name.strip(), "scene": self.scene.name, "rendering": self.rendering,
                "clients": self.clients, "resets": pr.reset_count, "reprojections": pr.reprojections,
                "keyframes": len(self.keyframes), "playing": self._playback is not None, "kernels": self.kernels,
                "max_size": self.max_size, "error": self.error}

    def wait_frame(self, after: int = 0, timeout: float = 10.0) -> Frame:
        """Block until a picture with an index above ``after`` exists, then return it (TimeoutError)."""
        deadline = time.monotonic() + timeout
        with self._changed:
            while self.frame is None or self.frame.index <= after:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"no frame after {after} within {timeout} s (error: {self.error})")
                self._changed.wait(left)
            return self.frame

    # -- what the page asks for (any thread) ---------------------------------------------------------
    def client_connected(self) -> None:
        self.clients += 1
        self.touch()

    def client_disconnected(self) -> None:
        self.clients = max(0, self.clients - 1)
        self.touch()

    def touch(self) -> None:
        """Someone looked: keep rendering for idle_after seconds at least."""
        self._last_seen = time.monotonic()
        self._wake.set()

    def move(self, op: str, **args: float) -> concurrent.futures.Future:
        """A camera move (:class:`OrbitCamera`: orbit yaw/pitch, pan dx/dy, zoom factor, fly
        forward/right/up, or reset), applied before the next frame."""
        moves = {"orbit": ("yaw", "pitch"), "pan": ("dx", "dy"), "zoom": ("factor",),
                 "fly": ("forward", "right", "up"), "reset": ()}
        if op not in moves:
            raise ValueError(f"unknown camera move {op!r} (moves: {', '.join(moves)})")
        if set(args) != set(moves[op]):
            raise ValueError(f"camera move {op} takes {', '.join(moves[op]) or 'nothing'}, got {', '.join(args)}")
        bad = {k: v for k, v in args.items() if not math.isfinite(float(v))}
        if bad:
            raise ValueError(f"camera move {op}: {', '.join(f'{k}={v}' for k, v in bad.items())} is not finite")

        def apply() -> None:
            getattr(self.orbit, op)(**args)
            self._camera_moved = True
            self._playback = None  # a move from the page takes the camera back from a path played

        self.touch()
        return self.submit(apply)

    def set(self, name: str, value: Any) -> concurrent.futures.Future:
        """Change a setting (spp_per_frame, max_depth, denoiser, integrator, layout, view, exposure, device)
        before the next frame; the future raises ValueError for a bad value, and the device's error where a
        renderer cannot be made on the device chosen (the previous one goes on)."""
        self.touch()
        return self.submit(lambda: self._apply(name, value))

    def fit(self, width: float, height: float, scale: float = 1.0) -> concurrent.futures.Future:
        """The page's picture area is ``width`` x ``height`` CSS pixels of ``scale`` device pixels each: render
        the frame that fills it (:func:`fit_size`: the scene's aspect, the longer side at most ``max_size``),
        from the next frame on (the accumulation restarts). The future holds the frame's (width, height); with
        no ``max_size`` the size stays as it is."""
        for what, v in (("width", width), ("height", height), ("scale", scale)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not 0 < v <= 1e5:
                raise ValueError(f"viewport {what} must be a positive number, got {v!r}")
        if self.max_size is not None:
            film = self.scene.film
            self._target_size = fit_size(film.width, film.height, width * scale, height * scale, self.max_size)

        def apply() -> tuple[int, int]:
            target = self._target_size  # the latest asked for: several queued resizes make one
            if target is not None and target != (self.pr.width, self.pr.height):
                self._size = target
                self.pr.set_resolution(*target)
            return self.pr.width, self.pr.height

        self.touch()
        return self.submit(apply)

    def save(self, directory: str | Path | None = None) -> concurrent.futures.Future:
        """Write the current image (:meth:`radiance`) as EXR (linear) and PNG (with the exposure) into
        ``directory`` (default ``output_dir``); the future holds the two paths."""
        def write() -> list[str]:
            folder = Path(directory) if directory is not None else self.output_dir
            folder.mkdir(parents=True, exist_ok=True)
            image = self.radiance()
            stem = folder / f"{self.scene.name}_{self.pr.sample_index:05d}"
            paths = [write_image(stem.with_suffix(".exr"), image),
                     write_image(stem.with_suffix(".png"), image, exposure=self.settings["exposure"])]
            log.info("viewer: wrote %s", ", ".join(map(str, paths)))
            return [str(p) for p in paths]

        return self.submit(write)

    def camera_path(self, spacing: int = KEYFRAME_SPACING) -> CameraPath:
        """The recorded keyframes as a Catmull-Rom :class:`~pyclpt.scene.camera_path.CameraPath`, ``spacing``
        frames apart (ValueError without a keyframe)."""
        if not self.keyframes:
            raise ValueError("no keyframes recorded: add the current camera as a keyframe first")
        keys = [Keyframe(float(i * spacing), cam) for i, cam in enumerate(self.keyframes)]
        return CameraPath(keys, interpolation="catmull-rom")

    def keyframe(self, op: str, spacing: int = KEYFRAME_SPACING) -> concurrent.futures.Future:
        """Camera keyframes: ``add`` the current camera, ``clear`` them, ``play`` them as a camera path
        (``spacing`` frames apart; a move from the page stops it), ``save`` the path as JSON
        (SCENE_path.json in ``output_dir``, :func:`~pyclpt.viewer.camera.camera_path_from_json` reads it).
        The future holds the number of keyframes (and, for save, the file's path)."""
        if op not in KEYFRAME_OPS:
            raise ValueError(f"unknown keyframe operation {op!r} ({', '.join(KEYFRAME_OPS)})")
        if not _is_integer(spacing, 1, 100000):
            raise ValueError(f"keyframe spacing must be an integer number of frames in 1..100000, got {spacing!r}")

        def run() -> dict:
            if op == "add":
                self.keyframes.append(self.orbit.camera())
            elif op == "clear":
                self.keyframes.clear()
                self._playback = None
            elif op == "play":
                if len(self.keyframes) < 2:
                    raise ValueError(f"{len(self.keyframes)} keyframe(s) recorded: a path to play needs two or more")
                self._playback = (self.camera_path(int(spacing)), 0.0)
            else:
                path = self.output_dir / f"{self.scene.name}_path.json"
                self.output_dir.mkdir(parents=True, exist_ok=True)
                path.write_text(json.dumps(camera_path_to_json(self.camera_path(int(spacing))), indent=1) + "\n")
                log.info("viewer: wrote %s", path)
                return {"count": len(self.keyframes), "path": str(path)}
            return {"count": len(self.keyframes), "path": None}

        self.touch()
        return self.submit(run)

    def write_lookat(self, directory: str | Path | None = None) -> concurrent.futures.Future:
        """Write the camera as a Mitsuba XML sensor (``<lookat>``) to SCENE_camera.xml in ``directory``
        (default ``output_dir``); the future holds (path, text)."""
        def write() -> tuple[str, str]:
            folder = Path(directory) if directory is not None else self.output_dir
            folder.mkdir(parents=True, exist_ok=True)
            text = self.orbit.lookat_xml()
            path = folder / f"{self.scene.name}_camera.xml"
            path.write_text(text)
            log.info("viewer: wrote %s", path)
            return str(path), text

        return self.submit(write)
