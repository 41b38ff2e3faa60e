"""Rendering a scene: scene buffers + an integrator + the film, one sample per
pixel per frame, frames averaged on the device.

Frames are summed by the film's accumulator (:mod:`pyclpt.film.accumulator`) in double precision
by default (``precision=``; emulated double-float on a device without fp64).
:class:`pyclpt.rendering.progressive.ProgressiveRenderer` renders frame by frame with auto-reset.

Seed contract: the image is a pure function of (scene, seed, spp, max_depth,
resolution). Sample ``s`` of pixel ``p`` draws its random numbers from the
counter-based generator keyed by (seed, p, s, bounce, dimension) whatever
integrator, layout or wave size renders it, so integrators can be compared
image to image.
"""
from __future__ import annotations

import importlib
import logging
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pyclpt.buffers.scene import SceneBuffers, scene_meshes
from pyclpt.common.checks import check_choice, check_int, check_optional_bool, check_optional_int
from pyclpt.device.context import Device, get_device
from pyclpt.device.program import compile_notice
from pyclpt.film.accumulator import check_options
from pyclpt.film.aovs import check_aovs, unpack
from pyclpt.film.crop import Crop
from pyclpt.film.film import DEFAULT_PRECISION, Film
from pyclpt.integrators.megakernel import Megakernel
from pyclpt.rendering.frame_loop import FramePacer, progress_bar
from pyclpt.rendering.memory import batch_frames, check_render_memory
from pyclpt.scene.model import Scene

log = logging.getLogger("pyclpt")

INTEGRATORS = ("megakernel", "wavefront")
# max_depth -1 (unlimited: paths end by Russian roulette) runs as this many bounces at most.
UNLIMITED_DEPTH = 1024
LAYOUTS = ("soa", "aos")
MAX_RESOLUTION = 65536  # pixels a side


@dataclass
class RenderStats:
    """What the last render of a :class:`Renderer` cost (``Renderer.stats``; ``pyclpt render --stats``).

    Attributes:
        spp: Samples per pixel rendered.
        seconds: Device and host time of the frames; kernel compilation and scene setup excluded.
        compile_seconds: Time spent building the kernel programs (near 0 from the kernel cache).
        setup_seconds: Scene packing (BVH build or cache load) and upload to the device.
        dropped_samples: NaN or infinite samples the film dropped.
        kernels: One row per kernel: ``kernel``, ``launches``, ``total_ms``, ``mean_ms``, ``share``.
        bounces: The wavefront integrator's rows per bounce (paths alive, hits, misses, shadow rays,
            unoccluded, ``tail``); empty for the megakernel.
        tail_alive: The wavefront's paths alive per bounce inside its tail (finish_paths: counted in no
            row of ``bounces``); paths alive at bounce b are ``bounces[b]["rays"] + tail_alive[b]``.
        memory: The wavefront integrator's wave size, bytes per path and path-state bytes.
        accumulation: ``Accumulator.stats()``: precision, frames, counters.
        denoise: The denoiser's passes (a :class:`ProgressiveRenderer` with a denoiser).
    """

    spp: int = 0
    seconds: float = 0.0  # device + host time of the frames, compile and scene setup excluded
    compile_seconds: float = 0.0
    setup_seconds: float = 0.0  # scene packing (BVH build or cache load) and upload
    dropped_samples: int = 0  # NaN/inf samples dropped
    kernels: list[dict] = field(default_factory=list)
    bounces: list[dict] = field(default_factory=list)
    tail_alive: list[int] = field(default_factory=list)  # wavefront: paths alive per bounce inside the tail
    memory: dict = field(default_factory=dict)  # wavefront: wave size, bytes per path, path-state bytes
    accumulation: dict = field(default_factory=dict)  # Accumulator.stats(): precision, frames, counters
    denoise: list[dict] = field(default_factory=list)  # the denoiser's passes (ProgressiveRenderer with one)


def check_scene(scene: object) -> Scene:
    """``scene`` itself, after the checks of its values (:meth:`Scene.validate`); TypeError for
    anything but a Scene."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a pyclpt.Scene (pyclpt.load() and pyclpt.load_dict() make one), "
                        f"got {type(scene).__name__} {scene!r:.60}")
    scene.validate()
    return scene


class Renderer:
    """A scene prepared on a device for one integrator and resolution.

    ``crop`` (x, y, width, height): render only that window of the width x height image (its pixels
    exactly the whole image's; :mod:`pyclpt.film.crop`); :meth:`render` then returns the window.
    ``scene_buffers``: the scene as another renderer of it on the same device already holds it
    (:meth:`cropped` passes its own), instead of packing and uploading it again."""

    def __init__(self, scene: Scene, *, integrator: str = "megakernel", layout: str = "soa",
                 max_depth: int | None = None, width: int | None = None, height: int | None = None,
                 device: Device | str | None = None, wave_size: int | None = None,
                 local_size: int | None = None, schedule: str | None = None, tail_paths: int | None = None,
                 precision: str = DEFAULT_PRECISION, aovs: Sequence[str] | str | bool | None = None,
                 crop: Sequence[int] | None = None, scene_buffers: SceneBuffers | None = None) -> None:
        self._options = dict(integrator=integrator, layout=layout, max_depth=max_depth, width=width, height=height,
                             wave_size=wave_size, local_size=local_size, schedule=schedule, tail_paths=tail_paths,
                             precision=precision, aovs=aovs)
        if scene_buffers is None:
            check_scene(scene)
        elif scene_buffers.scene is not scene:  # checked when they were made; they render as they were then
            raise ValueError(f"scene_buffers must hold this scene, {scene.name!r}: they hold "
                             f"{scene_buffers.scene.name!r}")
        self.aov_names = check_aovs(aovs)
        check_choice(integrator, "integrator", INTEGRATORS)
        check_choice(layout, "layout", LAYOUTS)
        max_depth = check_optional_int(max_depth, "max_depth", lo=-1, note=" (-1 = unlimited)")
        width = check_optional_int(width, "width", lo=1, hi=MAX_RESOLUTION, note=" (None: the scene's)")
        height = check_optional_int(height, "height", lo=1, hi=MAX_RESOLUTION, note=" (None: the scene's)")
        wave_size = check_optional_int(wave_size, "wave_size", lo=1)
        local_size = check_optional_int(local_size, "local_size", lo=1)
        tail_paths = check_optional_int(tail_paths, "tail_paths", lo=0, note=" (wavefront: 0 never hands paths on)")
        check_options(precision=precision)
        self.scene = scene
        self.device = get_device(device)
        self.max_depth = scene.max_depth if max_depth is None else max_depth
        if self.max_depth < -1:
            raise ValueError(f"max_depth must be -1 (unlimited) or >= 0, got {self.max_depth}")
        self.width = int(scene.film.width if width is None else width)
        self.height = int(scene.film.height if height is None else height)
        if not (0 < self.width <= 65536 and 0 < self.height <= 65536):
            raise ValueError(f"resolution must be 1..65536 pixels a side, got {self.width}x{self.height}")
        self.crop = None if crop is None else Crop.of(crop, self.width, self.height)
        film_w, film_h = (self.width, self.height) if self.crop is None else self.crop[2:]
        self.depth_limit = UNLIMITED_DEPTH if self.max_depth == -1 else self.max_depth
        # the wave (and film batch) size: the device's default unless given (GPUs take larger waves); the
        # megakernel's launch size only when given
        from pyclpt.integrators.wavefront import Wavefront, default_wave_size

        launch_size, wave_size = wave_size, wave_size or default_wave_size(self.device)
        # all the buffers below together, before any is made (alloc() checks each on its own)
        check_render_memory(self.device, scene, film_w, film_h, precision=precision,
                            integrator=integrator, wave_size=wave_size, max_depth=self.depth_limit,
                            aovs=bool(self.aov_names), scene_buffers=scene_buffers is None)
        self.stats = RenderStats()
        t0 = time.perf_counter()
        if scene_buffers is not None and scene_buffers.device is not self.device:
            raise ValueError(f"scene_buffers must be on this renderer's device, {self.device.name}: they are on "
                             f"{scene_buffers.device.name}")
        self.scene_buffers = scene_buffers or SceneBuffers(scene, self.device)
        self.device.queue.finish()
        t1 = time.perf_counter()
        # the programs, and the drivers' lazy compilation on the first launches: a slow first build logs
        # "compiling kernels for SCENE ..." (pyclpt.device.program.compile_notice)
        with compile_notice(scene.name):
            # small images: a batch of frames (samples) per wave or launch (rendering/memory.py: batch_frames)
            self.film = Film(self.device, self.width, self.height, precision=precision,
                             batch=batch_frames(film_w * film_h, wave_size), aovs=bool(self.aov_names), crop=self.crop,
                             rfilter=scene.film.rfilter)
            options: dict = {"wave_size": launch_size} if launch_size else {}
            if local_size:
                options["local_size"] = int(local_size)
            if integrator == "megakernel":
                self.integrator = Megakernel(self.device, self.scene_buffers, self.film, self.depth_limit, **options)
            else:
                options["wave_size"] = wave_size
                if schedule:
                    options["schedule"] = schedule
                if tail_paths is not None:
                    options["tail_paths"] = tail_paths
                self.integrator = Wavefront(self.device, self.scene_buffers, self.film, self.depth_limit,
                                            layout=layout, **options)
            self.integrator.warm_up()
            self.film.warm_up()
        # setup: scene packing (BVH build or cache load) and upload;
        # compile: program builds plus the driver's lazy compilation on the first launches
        self.stats.setup_seconds = t1 - t0
        self.stats.compile_seconds = time.perf_counter() - t1
        self.pacer = FramePacer()  # the frame loop waits for the device often enough for Ctrl-C to stop it

    def cropped(self, crop: Sequence[int] | None) -> Renderer:
        """A renderer of the window ``crop`` (x, y, width, height) of this one's image (None: all of it)
        with this one's settings, sharing its scene buffers (and, through the device's cache, its
        compiled programs): a tile of the image."""
        return Renderer(self.scene, device=self.device, crop=crop, scene_buffers=self.scene_buffers, **self._options)

    def render(self, spp: int, seed: int = 0, progress: bool | None = None, first_sample: int = 0) -> np.ndarray:
        """Average of samples [first_sample, first_sample + spp) of every pixel, (H, W, 3) float32 (with
        a crop: of the window's pixels, (crop height, crop width, 3)).
        ``progress``: True shows a bar once the render has run a couple of seconds; None or False
        show none. Ctrl-C raises KeyboardInterrupt within about a second, and no image is returned."""
        start = self._render_samples(spp, seed, progress, first_sample)
        image = self.film.image()
        self.collect_stats(spp, time.perf_counter() - start)
        return image

    def render_sum(self, spp: int, seed: int = 0, progress: bool | None = None, first_sample: int = 0) -> np.ndarray:
        """The sum of samples [first_sample, first_sample + spp) of every pixel as the film's accumulator
        keeps it, (H, W, 3) float64 (with ``precision="double"``: the float32 samples added in sample
        order in double). Partial sums of a split sample range add up to :meth:`render`'s sum up to the
        rounding of double (:mod:`pyclpt.distributed` merges them); a splatting film's is its image times
        spp, a ratio per range: split ranges merge by :meth:`render_sums`."""
        start = self._render_samples(spp, seed, progress, first_sample)
        total = self.film.sum()
        self.collect_stats(spp, time.perf_counter() - start)
        return total

    def render_sums(self, spp: int, seed: int = 0, progress: bool | None = None,
                    first_sample: int = 0) -> tuple[np.ndarray, np.ndarray | None]:
        """What a split sample range merges by (:meth:`Film.sums <pyclpt.film.film.Film.sums>`): the sum of
        samples [first_sample, first_sample + spp) as :meth:`render_sum` and None; a splatting film
        (:mod:`pyclpt.film.splat`): the sums of its weighted radiance, (H, W, 3) float64, and of its
        weights, (H, W) float64, which :func:`pyclpt.distributed.merge.merge` pools over the ranges (their
        per-range ratio, :meth:`render_sum`, does not add up)."""
        start = self._render_samples(spp, seed, progress, first_sample)
        sums = self.film.sums()
        self.collect_stats(spp, time.perf_counter() - start)
        return sums

    def _render_samples(self, spp: int, seed: int, progress: bool | None, first_sample: int) -> float:
        """Clear the film and accumulate samples [first_sample, first_sample + spp); returns the start time."""
        spp = check_int(spp, "spp", lo=1, hi=2**32)
        seed = check_int(seed, "seed", lo=0, hi=2**32 - 1)
        progress = check_optional_bool(progress, "progress")
        first_sample = check_int(first_sample, "first_sample", lo=0, hi=2**32 - spp,
                                 note=" (sample indices are 32-bit)")
        self.film.clear()
        self.integrator.profile.clear()
        if hasattr(self.integrator, "reset_stats"):
            self.integrator.reset_stats()
        start = time.perf_counter()
        with progress_bar(spp, f"{self.scene.name} {self.integrator.name}", "spp", progress) as bar:
            s, end = first_sample, first_sample + spp
            while s < end:  # batches of frames (samples s, s + 1, ...), added in sample order
                frames = min(self.film.batch, end - s)
                self.integrator.render_frames(int(seed), s, frames)
                self.film.add_frames(frames, seed, s)
                bar.update(self.pacer.frame(self.device.queue, frames))
                s += frames
        return start

    def aovs(self, names: Sequence[str] | None = None) -> dict[str, np.ndarray]:
        """The G-buffer of the samples rendered since the film was last cleared (:meth:`render`: all its
        samples; a progressive frame: that frame's), by name (``names``: those asked for when made, by
        default): (H, W, 3) albedo and normal, (H, W, 2) motion, (H, W) roughness, depth and hitdist,
        (H, W) int32 ids (-1 where the camera ray left the scene); see :mod:`pyclpt.film.aovs`."""
        if self.film.aov is None:
            raise ValueError("this renderer records no AOVs: make it with aovs=[...] (or aovs=True)")
        wanted = self.aov_names if names is None else check_aovs(names)
        arrays = self.scene_buffers.arrays
        meshes = scene_meshes(self.scene)  # instanced scenes: the plain meshes, then the shapegroups' meshes
        starts = np.cumsum([0] + [m.triangle_count for m in meshes[:-1]])
        return unpack(self.film.aov.read(), wanted, arrays.bvh.tri_order, starts, arrays.instance_tri_bits)

    def collect_stats(self, spp: int, seconds: float) -> RenderStats:
        """Fill ``stats`` after frames were rendered (profile, bounces, memory, counters); returns it."""
        self.stats.spp = spp
        self.stats.seconds = seconds
        self.stats.dropped_samples = self.film.dropped_samples()
        self.stats.accumulation = self.film.accumulator.stats()
        self.stats.kernels = self.integrator.profile.table()
        self.stats.bounces = getattr(self.integrator, "bounce_stats", lambda: [])()
        self.stats.tail_alive = getattr(self.integrator, "tail_alive", lambda: [])()
        if hasattr(self.integrator, "paths"):
            self.stats.memory = {"wave_size": self.integrator.capacity,
                                 "bytes_per_path": self.integrator.bytes_per_path,
                                 "path_state_bytes": self.integrator.paths.nbytes}
        if self.stats.dropped_samples:
            log.warning("%s: dropped %d NaN/inf samples", self.scene.name, self.stats.dropped_samples)
        return self.stats


def render(scene: Scene | str, spp: int | None = None, max_depth: int | None = None, seed: int = 0,
           integrator: str = "megakernel", width: int | None = None, height: int | None = None,
           device: Device | str | None = None, layout: str = "soa", progress: bool | None = None,
           wave_size: int | None = None, precision: str = DEFAULT_PRECISION,
           aovs: Sequence[str] | str | bool | None = None, client: Any = None,
           task_spp: int | None = None) -> np.ndarray | tuple[np.ndarray, dict[str, np.ndarray]]:
    """Render ``scene`` (a Scene or a built-in scene name / file) to a (H, W, 3) float32 linear image.

    ``spp`` and ``max_depth`` default to the scene's; ``width``/``height`` override its film.
    ``progress``: True shows a bar (on stderr, once the render has run a couple of seconds); None or
    False show none. Ctrl-C stops the render within about a second (KeyboardInterrupt; no image).
    ``precision``: how the frames are summed (``single``, ``compensated``, ``double``; see
    :mod:`pyclpt.film.accumulator`).
    ``aovs``: AOV names (or True: all; :data:`pyclpt.film.aovs.AOV_NAMES`); then the result is
    ``(image, {name: array})``, the G-buffer averaged over the same samples (:meth:`Renderer.aovs`).
    ``client``: a ``dask.distributed.Client``; then the same image is rendered on that cluster's workers
    (the ``[distributed]`` extra; ``task_spp`` samples a task), by the function that
    ``pyclpt.rendering.renderer.CLUSTER_RENDER`` names in the distributed layer. A distributed
    render takes no ``device`` (each worker picks its own: ``PYCLPT_DEVICE``) and no ``aovs``.
    """
    if client is not None:
        return cluster_render()(client, scene, spp=spp, max_depth=max_depth, seed=seed, integrator=integrator,
                                width=width, height=height, device=device, layout=layout, progress=progress,
                                wave_size=wave_size, precision=precision, aovs=aovs, task_spp=task_spp)
    if task_spp is not None:
        raise ValueError("task_spp splits a distributed render: give client= too")
    spp = check_optional_int(spp, "spp", lo=1, hi=2**32, note=" (None: the scene's)")
    check_int(seed, "seed", lo=0, hi=2**32 - 1)
    check_optional_bool(progress, "progress")
    if isinstance(scene, (str, os.PathLike)):
        from pyclpt.scene.library import load

        scene = load(scene)
    check_scene(scene)
    r = Renderer(scene, integrator=integrator, layout=layout, max_depth=max_depth, width=width,
                 height=height, device=device, wave_size=wave_size, precision=precision, aovs=aovs)
    image = r.render(scene.spp if spp is None else spp, seed=seed, progress=progress)
    return (image, r.aovs()) if r.aov_names else image


#: The cluster path of :func:`render` (``client=``), as ``"module:function"``: the distributed layer, above
#: this one, provides it, so this layer names it rather than importing it (the layers contract of setup.cfg);
#: it is imported on the first render given a client, and takes the client, the scene and render's keywords.
CLUSTER_RENDER = "pyclpt.distributed.renderer:render_on_cluster"


def cluster_render() -> Callable[..., Any]:
    """The function :data:`CLUSTER_RENDER` names, imported."""
    module, _, name = CLUSTER_RENDER.partition(":")
    return getattr(importlib.import_module(module), name)
