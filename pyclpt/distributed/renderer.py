"""Renders spread over a Dask cluster: :class:`DistributedRenderer`, and :func:`render_on_cluster`, the
cluster path of :func:`pyclpt.render` (``client=``).

A render of ``spp`` samples becomes tasks of ``task_spp`` samples each (:mod:`.tasks`); the workers
render them with the renderer they keep for the scene (:mod:`.worker`) and send back the sums; the
client adds them in sample order (:mod:`.merge`). The image equals the one-machine render of the
same spp and seed within 1e-12 relative (only the joins of the ranges round differently).

A sequence (:meth:`DistributedRenderer.render_frames`) is one task per frame when the frames are
independent (each view its own samples); a sequence whose frames accumulate
(:meth:`DistributedRenderer.render_progressive`: the image after each sample) is split by sample
range with every sample's frame sent back, and the client adds them in order.

Faults: Dask reruns the task of a worker that died (tasks are pure: a rerun renders the same
samples), so a lost worker changes nothing; a task that fails (:class:`~.worker.WorkerError`: the
scene cannot be opened, no OpenCL device) fails the job with that error and the other tasks are
cancelled, as they are when the client stops waiting (Ctrl-C, ``timeout``).
"""
from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from pyclpt.common.checks import check_int, check_optional_bool, check_optional_int
from pyclpt.denoise import Denoiser, DenoiserSettings
from pyclpt.device.context import Device
from pyclpt.distributed.cluster import import_distributed
from pyclpt.distributed.merge import (
    PartialSum,
    RunningAverage,
    average,
    merge,
    merge_tiles,
    running_averages,
    splat_average,
)
from pyclpt.distributed.tasks import (
    RENDERER_SETTINGS,
    RenderTask,
    SceneSource,
    default_task_spp,
    split_samples,
    tile_size,
)
from pyclpt.distributed.worker import image_size, run_task
from pyclpt.film.crop import tiles
from pyclpt.film.film import DEFAULT_PRECISION
from pyclpt.rendering.frame_loop import PROGRESS_DELAY_S
from pyclpt.rendering.renderer import render  # noqa: F401  (pyclpt.render, here before it moved: kept importable)
from pyclpt.scene.camera_path import CameraPath
from pyclpt.scene.model import Camera, Scene, content_digest

# Samples a task of a running-average sequence written as it goes (render_progressive's on_frame) renders at
# most: each sends back a frame per sample, and a task's frames are written only once all have arrived.
PROGRESSIVE_TASK_SPP = 16


class DistributedRenderer:
    """A scene rendered on the workers of a Dask ``client``.

    ``scene``: a scene file path or built-in name (every worker opens it; ``defines``: Mitsuba ``-D``
    parameters) or a Scene (sent to the workers once). The settings are
    :class:`~pyclpt.rendering.renderer.Renderer`'s; each worker picks its own device."""

    def __init__(self, client: Any, scene: Scene | str | os.PathLike, *, defines: dict[str, object] | None = None,
                 integrator: str = "megakernel", layout: str = "soa", max_depth: int | None = None,
                 width: int | None = None, height: int | None = None, wave_size: int | None = None,
                 precision: str = DEFAULT_PRECISION) -> None:
        self._distributed = import_distributed()
        self.client = client
        # how errors name the cluster once its scheduler is gone (the client then forgets it)
        self.scheduler_address = str(getattr(getattr(client, "scheduler", None), "address", None) or "?")
        if isinstance(scene, os.PathLike) or (isinstance(scene, str) and os.path.isfile(scene)):
            scene = os.path.abspath(scene)  # the workers see the same path (shared storage)
        self.source = SceneSource.of(scene, defines)
        values = dict(integrator=integrator, layout=layout, max_depth=max_depth, width=width, height=height,
                      wave_size=wave_size, precision=precision)
        self.settings = tuple((k, values[k]) for k in RENDERER_SETTINGS)
        # a Scene goes to the workers once, not with every task; again when it changed (_ship)
        self._shipped = None
        self._digest: tuple[bytes, bytes] | None = None
        self._size: tuple[int, int] | None = None
        self._ships = 0  # copies of the Scene sent so far
        self._ship()
        self.parts: list[PartialSum] = []  # the last job's partial results (worker, seconds, samples)

    def _ship(self) -> None:
        """Send a Scene to the workers when it was not sent yet or has changed since it was sent: any
        array edited in place (vertices, texels), any field assigned (content_digest, checked at the
        start of every render: about 0.1 ms for the Cornell box, a few ms for 100k triangles). The new
        copy has a new token, so the workers' caches never render the copy sent before."""
        scene = self.source.scene
        if scene is None:
            return
        digest = content_digest(scene)
        if digest == self._digest:
            return
        if self._shipped is not None:
            self.client.cancel([self._shipped])
        if self._ships:
            self.source = SceneSource.of(scene)  # not the first copy: a new token
            self._size = None
        self._shipped = self.client.scatter(self.source, broadcast=True)
        self._digest = digest
        self._ships += 1

    @property
    def workers(self) -> int:
        """Workers the cluster has now."""
        return max(1, len(self.client.nthreads()))

    def _task(self, seed: int, first: int, count: int, **extra: Any) -> RenderTask:
        source = self.source if self._shipped is None else SceneSource(token=self.source.token)
        extra.setdefault("settings", self.settings)
        return RenderTask(source=source, seed=seed, first_sample=first, count=count, **extra)

    def image_size(self) -> tuple[int, int]:
        """The width and height of the image: the settings', else the scene's film (a scene file's is read
        by a worker, which keeps the scene for the render)."""
        settings = dict(self.settings)
        if settings["width"] is not None and settings["height"] is not None:
            return settings["width"], settings["height"]
        if self._size is None:
            if self.source.scene is not None:
                film = self.source.scene.film
                self._size = (settings["width"] or film.width, settings["height"] or film.height)
            else:
                future = self.client.submit(image_size, self.source, self.settings, pure=False)
                self._size = future.result()
        return self._size

    def _run(self, tasks: list[RenderTask], progress: bool | None, desc: str, unit_of=lambda t: t.count,
             timeout: float | None = None, on_result: Callable[[int, PartialSum], None] | None = None,
             window: int | None = None, consumed: Callable[[], int] | None = None) -> list[PartialSum]:
        """Run ``tasks`` on the cluster, a bar over their units; the results in the tasks' order
        (``on_result(i, part)``: called with each as it arrives). Any failure (or Ctrl-C, or ``timeout``
        seconds) cancels the tasks not finished. ``window``: task i is submitted only once ``consumed()``
        (how many tasks, in order, ``on_result`` has used up) is above i - window, so that at most ``window``
        tasks' results are running or held at a time (a long sequence need not fit in memory)."""
        d = self._distributed
        args = () if self._shipped is None else (self._shipped,)
        futures: list[Any] = []
        index: dict[Any, int] = {}

        def submit_more() -> list[Any]:
            limit = len(tasks) if window is None else min(len(tasks), consumed() + window)
            new = []
            while len(futures) < limit:
                t = tasks[len(futures)]
                f = self.client.submit(run_task, t, *args, key=f"pyclpt-{t.key}", pure=False, retries=0)
                index[f.key] = len(futures)
                futures.append(f)
                new.append(f)
            return new

        results: list[PartialSum | None] = [None] * len(tasks)
        try:
            with tqdm(total=sum(unit_of(t) for t in tasks), desc=desc, unit="spp", disable=not progress,
                      delay=PROGRESS_DELAY_S, leave=False) as bar:
                running = d.as_completed(submit_more(), with_results=True, timeout=timeout)
                for future, part in running:
                    i = index[future.key]
                    if not isinstance(part, PartialSum):  # cancelled or failed: its exception, not a result
                        self._failed(future, part, desc, sum(r is not None for r in results), len(tasks))
                    results[i] = part
                    if on_result is not None:
                        on_result(i, part)
                    bar.update(unit_of(tasks[i]))
                    if window is not None:
                        futures[i].release()  # the worker forgets the result (the client has it)
                        running.update(submit_more())
        except TimeoutError:
            left = sum(r is None for r in results)
            raise TimeoutError(f"{desc}: not finished within timeout={timeout} s: {left} of {len(tasks)} tasks "
                               f"left (cancelled)") from None
        finally:
            pending = [f for f in futures if not f.done()]
            if pending:
                self.client.cancel(pending, force=True)
        self.parts = results
        return results

    def _failed(self, future: Any, outcome: object, desc: str, done: int, total: int) -> None:
        """Raise the error of a task that did not return its part: ConnectionError when the client lost
        the scheduler (every task is cancelled then), else the task's own exception or a RuntimeError."""
        reason = str(getattr(outcome, "reason", "") or "")
        status = str(getattr(self.client, "status", "running"))
        if reason == "scheduler-connection-lost" or status not in ("running", "newly-created"):
            raise ConnectionError(f"{desc}: lost the connection to the Dask scheduler at {self.scheduler_address} "
                                  f"during the render ({done} of {total} tasks finished; nothing merged, no image)")
        if isinstance(outcome, tuple) and len(outcome) == 3 and isinstance(outcome[1], BaseException):
            raise outcome[1].with_traceback(outcome[2])  # an error's (type, exception, traceback)
        if isinstance(outcome, Exception) and not isinstance(outcome, self._cancelled_errors()):
            raise outcome
        raise RuntimeError(f"{desc}: task {future.key} on the Dask scheduler at {self.scheduler_address} "
                           f"returned no result ({type(outcome).__name__}: {outcome}); "
                           f"{done} of {total} tasks finished")

    @staticmethod
    def _cancelled_errors() -> tuple[type[BaseException], ...]:
        import asyncio
        import concurrent.futures

        return (asyncio.CancelledError, concurrent.futures.CancelledError)

    def render_sum(self, spp: int, seed: int = 0, *, task_spp: int | None = None, first_sample: int = 0,
                   tile: int | tuple[int, int] | str | None = "auto", progress: bool | None = None,
                   timeout: float | None = None) -> np.ndarray:
        """The sum of samples [first_sample, first_sample + spp) of every pixel, (H, W, 3) float64."""
        self._ship()
        spp = check_int(spp, "spp", lo=1, hi=2**32)
        seed = check_int(seed, "seed", lo=0, hi=2**32 - 1)
        task_spp = check_optional_int(task_spp, "task_spp", lo=1, note=" (None: about 4 tasks a worker)")
        progress = check_optional_bool(progress, "progress")
        width, height = self.image_size() if tile is not None else (0, 0)
        size = tile_size(tile, width, height)
        crops = [None] if size is None else tiles(width, height, *size)
        task_spp = task_spp or default_task_spp(spp, self.workers, tiles=len(crops))
        tasks = [self._task(seed, s, n, crop=c) for c in crops for s, n in split_samples(spp, task_spp, first_sample)]
        what = "" if size is None else f", {len(crops)} tiles"
        share = {c: 1.0 if c is None else c.width * c.height / (width * height) for c in crops}
        parts = self._run(tasks, progress, f"{self.source.name} on {self.workers} workers{what}",
                          unit_of=lambda t: t.count * share[t.crop], timeout=timeout)
        if size is None:
            total, self.dropped_samples = merge(parts, spp, first_sample)
        else:
            total, self.dropped_samples = merge_tiles(parts, spp, width, height, first_sample)
        return total

    def render(self, spp: int, seed: int = 0, *, task_spp: int | None = None, first_sample: int = 0,
               tile: int | tuple[int, int] | str | None = "auto", progress: bool | None = None,
               timeout: float | None = None) -> np.ndarray:
        """The average of samples [first_sample, first_sample + spp), (H, W, 3) float32: the image of
        ``Renderer(scene).render(spp, seed, first_sample=first_sample)``. ``task_spp``: samples per task
        (default: about 4 tasks a worker); ``tile``: tasks render tiles of this size (one side, or
        (width, height)) instead of the whole image; ``"auto"``: tiles of 512 pixels for an image of more
        than 2 Mpixels (docs/distributed.md)."""
        total = self.render_sum(spp, seed, task_spp=task_spp, first_sample=first_sample, tile=tile,
                                progress=progress, timeout=timeout)
        return average(total, spp)

    def render_frames(self, cameras: Sequence[Camera], spp: int = 1, seed: int = 0, *, first_sample: int = 0,
                      progress: bool | None = None, timeout: float | None = None) -> list[np.ndarray]:
        """Independent frames, one task each: frame k is samples [first_sample, first_sample + spp) seen
        from ``cameras[k]`` (e.g. ``CameraPath.camera(k)``), (H, W, 3) float32 each."""
        spp = check_int(spp, "spp", lo=1, hi=2**32)
        seed = check_int(seed, "seed", lo=0, hi=2**32 - 1)
        self._ship()
        if not cameras or not all(isinstance(c, Camera) for c in cameras):
            raise TypeError("cameras must be a non-empty sequence of pyclpt.Camera")
        tasks = [self._task(seed, first_sample, spp, camera=c, frame=k) for k, c in enumerate(cameras)]
        parts = self._run(tasks, progress, f"{self.source.name}: {len(tasks)} frames", timeout=timeout)
        return [splat_average(p.total, p.weights, spp) for p in parts]

    def render_progressive(self, spp: int, seed: int = 0, *, task_spp: int | None = None,
                           progress: bool | None = None, timeout: float | None = None,
                           on_frame: Callable[[int, np.ndarray], None] | None = None) -> list[np.ndarray]:
        """The image after each of ``spp`` samples, as a progressive render's accumulation gives them
        (frame k: the average of samples 0..k), (H, W, 3) float32 each: sample ranges on the workers,
        every sample's frame sent back and added in order on the client.

        ``on_frame(k, image)``: called with each frame in order as soon as the samples before it have
        arrived (the CLI writes it then); the frames are then not kept, and at most
        :attr:`window` tasks (of at most :data:`PROGRESSIVE_TASK_SPP` samples by default) are running or
        held at a time: a long sequence needs bounded memory on the client, and what is done is on disk
        when it is stopped. Else the frames are returned."""
        spp = check_int(spp, "spp", lo=1, hi=2**32)
        seed = check_int(seed, "seed", lo=0, hi=2**32 - 1)
        task_spp = check_optional_int(task_spp, "task_spp", lo=1) or default_task_spp(spp, self.workers)
        self._ship()
        if on_frame is None:
            tasks = [self._task(seed, s, n, per_sample=True) for s, n in split_samples(spp, task_spp)]
            parts = self._run(tasks, progress, f"{self.source.name}: {spp} frames", timeout=timeout)
            return running_averages(parts, spp)
        task_spp = min(task_spp, PROGRESSIVE_TASK_SPP)
        tasks = [self._task(seed, s, n, per_sample=True) for s, n in split_samples(spp, task_spp)]
        waiting: dict[int, PartialSum] = {}  # tasks arrived before the one whose frames come next
        state = {"next": 0}
        acc = RunningAverage()
        self.held_tasks = 0  # the most tasks held at once (arrived, not yet added): bounded by the window

        def add_in_order(i: int, part: PartialSum) -> None:
            waiting[i] = part
            self.held_tasks = max(self.held_tasks, len(waiting))
            while state["next"] in waiting:
                ready = waiting.pop(state["next"])
                first = acc.count
                for k, image in enumerate(acc.add_part(ready)):
                    on_frame(first + k, image)
                ready.frames = ready.frame_weights = None  # added: only the task's record stays
                state["next"] += 1

        self._run(tasks, progress, f"{self.source.name}: {spp} frames", timeout=timeout, on_result=add_in_order,
                  window=self.window, consumed=lambda: state["next"])
        return []

    @property
    def window(self) -> int:
        """How many tasks of a sequence written as it goes may be running or held at once: two a worker."""
        return 2 * self.workers

    def render_denoised(self, frames: int, seed: int = 0, *, camera_path: CameraPath | None = None,
                        denoiser: str = "svgf", denoiser_settings: DenoiserSettings | None = None,
                        device: Device | str | None = None,
                        on_frame: Callable[[int, np.ndarray], None] | None = None, progress: bool | None = None,
                        timeout: float | None = None) -> list[np.ndarray]:
        """A denoised sequence: what ``ProgressiveRenderer(scene, denoiser=denoiser, camera_path=camera_path,
        seed=seed)`` gives frame after frame (:meth:`~pyclpt.ProgressiveRenderer.denoised`), bit for bit.
        Each frame (sample index k, the path's camera k, motion vectors back to camera k - 1) is a task
        that returns the frame and its G-buffer; the client denoises them in frame order on ``device``
        (default: its default device) as they arrive, the denoiser's history carried from frame to
        frame. ``on_frame(k, image)``: called with each denoised frame in order, which then is not kept
        (a long sequence need not fit in memory); else the frames are returned, (H, W, 3) float32 each.
        ``denoiser``: ``"svgf"`` or ``"blend"`` (``"oidn"`` denoises the running average: render it with
        one machine)."""
        frames = check_int(frames, "frames", lo=1, hi=2**32)
        seed = check_int(seed, "seed", lo=0, hi=2**32 - 1)
        if denoiser not in ("svgf", "blend"):
            raise ValueError(f"denoiser {denoiser!r}: a cluster renders sequences for the temporal denoisers "
                             f"'svgf' and 'blend' ('oidn' denoises the running average: render it with "
                             f"pyclpt.ProgressiveRenderer)")
        if camera_path is not None and not isinstance(camera_path, CameraPath):
            raise TypeError(f"camera_path must be a pyclpt.CameraPath, got {type(camera_path).__name__}")
        self._ship()
        width, height = self.image_size()
        dn = Denoiser(device, width, height, mode=denoiser, settings=denoiser_settings)
        cameras = [None] * frames if camera_path is None else [camera_path.camera(k) for k in range(frames)]
        settings = (*self.settings, ("aovs", True))
        tasks = [self._task(seed, k, 1, camera=c, previous=cameras[k - 1] if k else None, frame=k, gbuffer=True,
                            settings=settings) for k, c in enumerate(cameras)]
        out: list[np.ndarray] = []
        waiting: dict[int, PartialSum] = {}  # frames arrived before the one the denoiser needs next
        next_frame = 0

        def denoise_in_order(k: int, part: PartialSum) -> None:
            nonlocal next_frame
            waiting[k] = part
            while next_frame in waiting:
                ready = waiting.pop(next_frame)
                image = dn.denoise_gbuffer(ready.frames[0], ready.gbuffer)
                ready.frames = ready.gbuffer = None  # denoised: only the task's record stays
                if on_frame is not None:
                    on_frame(next_frame, image)
                else:
                    out.append(image)
                next_frame += 1

        self._run(tasks, progress, f"{self.source.name}: {frames} frames, denoised", timeout=timeout,
                  on_result=denoise_in_order)
        return out

    def close(self) -> None:
        """Forget the scene sent to the workers (their caches keep a renderer until it ages out)."""
        if self._shipped is not None:
            self.client.cancel([self._shipped])
            self._shipped = None
            self._digest = None

    def __enter__(self) -> DistributedRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def render_on_cluster(client: Any, scene: Scene | str, spp: int | None = None, max_depth: int | None = None,
                      seed: int = 0, integrator: str = "megakernel", width: int | None = None,
                      height: int | None = None, device: Any = None, layout: str = "soa",
                      progress: bool | None = None, wave_size: int | None = None,
                      precision: str = DEFAULT_PRECISION, aovs: Sequence[str] | str | bool | None = None,
                      task_spp: int | None = None) -> np.ndarray:
    """The cluster path of :func:`pyclpt.render` (``client=``, a ``dask.distributed.Client``; named by
    :data:`pyclpt.rendering.renderer.CLUSTER_RENDER`): the same image rendered on that cluster's workers
    (:class:`DistributedRenderer`; ``task_spp`` samples a task). It takes no ``device`` (each worker picks
    its own: ``PYCLPT_DEVICE``) and no ``aovs``."""
    if device is not None:
        raise ValueError("a distributed render runs on each worker's own device (PYCLPT_DEVICE in the "
                         "workers' environment); leave device=None")
    if aovs:
        raise ValueError("AOVs are not rendered on a cluster; render them with client=None")
    if spp is None:
        from pyclpt.scene.library import load

        spp = (scene if isinstance(scene, Scene) else load(scene)).spp
    dr = DistributedRenderer(client, scene, integrator=integrator, layout=layout, max_depth=max_depth,
                             width=width, height=height, wave_size=wave_size, precision=precision)
    with dr:
        return dr.render(spp, seed, task_spp=task_spp, progress=progress)
