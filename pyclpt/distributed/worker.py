"""What runs on a worker: a task's sample range rendered with a renderer the worker keeps.

Each worker process loads a scene once and keeps its :class:`~pyclpt.rendering.renderer.Renderer`
(scene buffers, BVH, compiled programs) in a small cache keyed by the scene (file path and
modification time, ``-D`` parameters, or a shipped scene's token) and the renderer settings, so the
many tasks of one render pay for the scene once. The device is the worker's own choice, as pyclpt
makes it on one machine (``PYCLPT_DEVICE`` in the worker's environment, else the default device).

A scene a worker cannot open, or a worker without an OpenCL device, fails the task with a
:class:`WorkerError` naming the worker and the file; the client re-raises it and cancels the job.
"""
from __future__ import annotations

import logging
import os
import threading
import time
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np

from pyclpt.device.context import DeviceError
from pyclpt.distributed.merge import PartialSum
from pyclpt.distributed.tasks import RenderTask, SceneSource
from pyclpt.rendering.renderer import Renderer
from pyclpt.scene.library import builtin_dir, load

log = logging.getLogger("pyclpt.distributed")

CACHE_SIZE = 2  # renderers a worker keeps (least recently used first out)
_cache: OrderedDict[tuple, Renderer] = OrderedDict()
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


def _file_stamp(source: SceneSource) -> int:
    """The scene file's modification time (ns), so an edited file is loaded again; 0 for a shipped scene."""
    if source.path is None:
        return 0
    for path in (Path(source.path), builtin_dir() / f"{source.path}.json"):
        if path.is_file():
            return path.stat().st_mtime_ns
    return 0


def renderer_for(source: SceneSource, settings: tuple[tuple[str, Any], ...]) -> Renderer:
    """This worker's renderer of ``source`` with ``settings`` (loaded and built on first use)."""
    key = (source.path, source.defines, source.token, _file_stamp(source), settings)
    r = _cache.get(key)
    if r is not None:
        _cache.move_to_end(key)
        return r
    try:
        scene = load(source.path, **dict(source.defines)) if source.path is not None else source.scene
    except Exception as exc:
        raise WorkerError(f"worker {worker_name()}: cannot open scene {source.name}: "
                          f"{type(exc).__name__}: {exc}") from None
    try:
        r = Renderer(scene, **dict(settings))
    except DeviceError as exc:
        raise WorkerError(f"worker {worker_name()}: no usable OpenCL device for scene {source.name}: {exc}") from None
    _cache[key] = r
    while len(_cache) > CACHE_SIZE:
        _cache.popitem(last=False)
    return r


def run_task(task: RenderTask, source: SceneSource | None = None) -> PartialSum:
    """Render ``task`` on this worker: its samples' sum (or, per-sample, each sample's frame).
    ``source``: the scene, when it was sent to the workers once rather than with every task."""
    source = task.source if source is None else source
    with _lock:
        r = renderer_for(source, task.settings)
        scene_camera = r.scene.camera
        if task.camera is not None:  # a frame of a sequence: its view (refresh_camera checks its kind)
            r.scene.camera = task.camera
            r.scene_buffers.refresh_camera(previous=None)
        try:
            t0 = time.perf_counter()
            if task.per_sample:
                frames = np.stack([r.render(1, task.seed, first_sample=task.first_sample + k)
                                   for k in range(task.count)])
                total = None
            else:
                total, frames = r.render_sum(task.count, task.seed, first_sample=task.first_sample), None
            seconds = time.perf_counter() - t0
            dropped = r.stats.dropped_samples
        finally:
            if task.camera is not None:
                r.scene.camera = scene_camera
                r.scene_buffers.refresh_camera(previous=None)
    return PartialSum(task.first_sample, task.count, total, frame=task.frame, dropped=dropped,
                      worker=worker_name(), seconds=seconds, frames=frames)
