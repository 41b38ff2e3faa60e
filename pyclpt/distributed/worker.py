"""What runs on a worker: a task's sample range rendered with a renderer the worker keeps.

Each worker process loads a scene once and keeps its :class:`~pyclpt.rendering.renderer.Renderer`
(scene buffers, BVH, compiled programs) in a small cache keyed by the scene (file path, the
modification times and sizes of every file it reads: Scene.files, ``-D`` parameters, or a shipped
scene's token) and the renderer settings, so the many tasks of one render pay for the scene once.
The device is the worker's own choice, as pyclpt makes it on one machine (``PYCLPT_DEVICE`` in the
worker's environment, else the default device).

A scene a worker cannot open, or a worker without an OpenCL device, fails the task with a
:class:`WorkerError` naming the worker and the file; the client re-raises it and cancels the job.
"""
from __future__ import annotations

import logging
import os
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pyclpt.device.context import DeviceError
from pyclpt.distributed.merge import PartialSum
from pyclpt.distributed.tasks import RenderTask, SceneSource
from pyclpt.film.crop import Crop
from pyclpt.rendering.renderer import Renderer
from pyclpt.scene.library import builtin_dir, load

log = logging.getLogger("pyclpt.distributed")

CACHE_SIZE = 2  # scenes a worker keeps renderers of (least recently used first out)
TILE_CACHE_SIZE = 4  # renderers of tiles a worker keeps (sharing their scene's buffers)
_cache: OrderedDict[tuple, Renderer] = OrderedDict()
_tiles: OrderedDict[tuple, Renderer] = OrderedDict()
_lock = threading.Lock()  # a worker with several threads renders one task at a time on its device


class WorkerError(RuntimeError):
    """A worker could not run its task (scene not found or unreadable, no OpenCL device); the message
    names the worker and the scene file."""


def worker_name() -> str:
    """This worker's address (``tcp://host:port``), or the host and process id outside a worker."""
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return f"{os.uname().nodename} pid {os.getpid()}"


# the files the last load of a scene file read (Scene.files: includes, meshes, textures), by (path, defines)
_read_files: dict[tuple, tuple[str, ...]] = {}


def _stat(path: str | os.PathLike) -> tuple[int, int]:
    try:
        st = os.stat(path)
    except OSError:
        return (-1, -1)  # gone: a load will say so
    return st.st_mtime_ns, st.st_size


def _file_stamp(source: SceneSource) -> tuple:
    """The modification times (ns) and sizes of the scene file and of every file its last load read
    (includes, meshes, textures: Scene.files), so a scene is loaded again when any of them changed;
    () for a shipped scene. A changed file list comes with a changed scene file or include."""
    if source.path is None:
        return ()
    files = _read_files.get((source.path, source.defines))
    if files is None:
        files = tuple(str(p) for p in (Path(source.path), builtin_dir() / f"{source.path}.json") if p.is_file())[:1]
    return tuple((f, *_stat(f)) for f in files)


def _cached(cache: OrderedDict[tuple, Renderer], key: tuple, size: int, make: Callable[[], Renderer]) -> Renderer:
    r = cache.get(key)
    if r is not None:
        cache.move_to_end(key)
        return r
    r = cache[key] = make()
    while len(cache) > size:
        cache.popitem(last=False)
    return r


def renderer_for(source: SceneSource, settings: tuple[tuple[str, Any], ...], crop: Crop | None = None) -> Renderer:
    """This worker's renderer of ``source`` with ``settings`` (loaded and built on first use); ``crop``:
    of that tile of the image. The first renderer of a scene (of whatever window: a tiled render never
    makes a film of the whole image) keeps its buffers; the other windows' renderers share them."""
    key = (source.path, source.defines, source.token, _file_stamp(source), settings)
    if key not in _cache:  # kept under the stamp of every file the load read (known once it is loaded)
        r = _load(source, settings, crop)
        key = (source.path, source.defines, source.token, _file_stamp(source), settings)
        _cache.pop(key, None)
        _cached(_cache, key, CACHE_SIZE, lambda: r)
    r = _cached(_cache, key, CACHE_SIZE, lambda: _load(source, settings, crop))
    if r.crop == crop:
        return r
    return _cached(_tiles, (key, crop), TILE_CACHE_SIZE, lambda: r.cropped(crop))


def _load(source: SceneSource, settings: tuple[tuple[str, Any], ...], crop: Crop | None) -> Renderer:
    try:
        scene = load(source.path, **dict(source.defines)) if source.path is not None else source.scene
        if source.path is not None:
            _read_files[(source.path, source.defines)] = tuple(str(p) for p in scene.files)
    except Exception as exc:
        raise WorkerError(f"worker {worker_name()}: cannot open scene {source.name}: "
                          f"{type(exc).__name__}: {exc}") from None
    try:
        r = Renderer(scene, crop=crop, **dict(settings))
    except DeviceError as exc:
        raise WorkerError(f"worker {worker_name()}: no usable OpenCL device for scene {source.name}: {exc}") from None
    return r


def image_size(source: SceneSource, settings: tuple[tuple[str, Any], ...]) -> tuple[int, int]:
    """The width and height of the image ``source`` renders with ``settings`` (its scene is kept for the
    tiles that follow, in a renderer of one pixel)."""
    with _lock:
        r = renderer_for(source, settings, Crop(0, 0, 1, 1))
        return r.width, r.height


def run_task(task: RenderTask, source: SceneSource | None = None) -> PartialSum:
    """Render ``task`` on this worker: its samples' sum (or, per-sample, each sample's frame).
    ``source``: the scene, when it was sent to the workers once rather than with every task."""
    source = task.source if source is None else source
    with _lock:
        r = renderer_for(source, task.settings, task.crop)
        scene_camera = r.scene.camera
        if task.camera is not None:  # a frame of a sequence: its view (refresh_camera checks its kind)
            r.scene.camera = task.camera
            r.scene_buffers.refresh_camera(previous=task.previous)
        try:
            t0 = time.perf_counter()
            total = frames = gbuffer = weights = frame_weights = None
            if task.gbuffer:  # a frame of a denoised sequence: its own samples and G-buffer, the denoiser's input
                r.render(task.count, task.seed, first_sample=task.first_sample)
                frames, gbuffer = r.film.read_own_frame(0)[None], r.film.aov.read()
            elif task.per_sample:  # each sample's sums (a splatting film's: weighted radiance and weights)
                sums = [r.render_sums(1, task.seed, first_sample=task.first_sample + k) for k in range(task.count)]
                frames = np.stack([t.astype(np.float32) for t, _ in sums])  # one float32 frame: exact
                if sums[0][1] is not None:
                    frame_weights = np.stack([w.astype(np.float32) for _, w in sums])
            else:
                total, weights = r.render_sums(task.count, task.seed, first_sample=task.first_sample)
            seconds = time.perf_counter() - t0
            dropped = r.stats.dropped_samples
        finally:
            if task.camera is not None:
                r.scene.camera = scene_camera
                r.scene_buffers.refresh_camera(previous=None)
    return PartialSum(task.first_sample, task.count, total, frame=task.frame, dropped=dropped,
                      worker=worker_name(), seconds=seconds, frames=frames, crop=task.crop, gbuffer=gbuffer,
                      weights=weights, frame_weights=frame_weights)
