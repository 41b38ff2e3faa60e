"""Timing frames of a renderer, and counting the rays they trace.

A *frame* is one sample of every pixel (``Renderer.render(1, seed)``). Every measurement
starts with warm-up frames (untimed), then times ``repeats`` frames, each with its own seed
(``first_seed``, ``first_seed + 1``, ...), and reports the median, min and max of

- the wall time of the frame on the host (``render`` returns only after the image is read
  back, and the queue is ``finish()``-ed, so all device work of the frame is in it), and
- the device time: the sum of the frame's kernels' OpenCL profiling events.

Compile time (program builds and the driver's first-launch compilation) and scene setup
(BVH build or cache load, upload) happen when the ``Renderer`` is made and are recorded
apart (``RenderStats.compile_seconds``, ``setup_seconds``), never inside a frame.

Rays traced per frame: camera rays (bounce 0), extension rays (bounces 1, 2, ...) and shadow
rays, from the wavefront's per-bounce queue counters. The megakernel runs the identical
estimator on identical random numbers, so for the same (scene, depth, resolution, seed) it
traces exactly the rays the wavefront counts; its counts are taken from a wavefront run of
the same seeds (:func:`count_rays`).
"""
from __future__ import annotations

import statistics
import time
from typing import Any

import pyclpt

METHODS = {"megakernel": ("megakernel", "soa"), "wavefront-aos": ("wavefront", "aos"),
           "wavefront-soa": ("wavefront", "soa")}


def method_name(integrator: str, layout: str) -> str:
    return "megakernel" if integrator == "megakernel" else f"{integrator}-{layout}"


def methods_for(integrators: list[str], layouts: list[str]) -> list[str]:
    """The methods of the integrators x layouts asked for, megakernel first (the baseline)."""
    out = []
    for name, (integrator, layout) in METHODS.items():
        if integrator in integrators and (integrator == "megakernel" or layout in layouts):
            out.append(name)
    return out


def summary(values: list[float]) -> dict[str, float]:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def ray_counts(bounces: list[dict]) -> dict[str, int]:
    """Camera, extension and shadow rays of the per-bounce queue counts (``RenderStats.bounces``)."""
    camera = bounces[0]["rays"] if bounces else 0
    extension = sum(b["rays"] for b in bounces[1:])
    shadow = sum(b["shadow_rays"] for b in bounces)
    return {"camera": camera, "extension": extension, "shadow": shadow, "total": camera + extension + shadow}


def make_renderer(scene: pyclpt.Scene, method: str, depth: int, width: int, height: int,
                  device: Any = None, **options: Any) -> pyclpt.Renderer:
    integrator, layout = METHODS[method]
    return pyclpt.Renderer(scene, integrator=integrator, layout=layout, max_depth=depth, width=width,
                           height=height, device=device, **options)


def _frame(renderer: pyclpt.Renderer, spp: int, seed: int, first_sample: int = 0) -> tuple[float, float, float]:
    """(host wall ms, device ms, process CPU ms) of one render call."""
    c = time.process_time()
    t = time.perf_counter()
    renderer.render(spp, seed=seed, progress=False, first_sample=first_sample)
    renderer.device.queue.finish()
    host = 1e3 * (time.perf_counter() - t)
    cpu = 1e3 * (time.process_time() - c)
    return host, sum(k["total_ms"] for k in renderer.stats.kernels), cpu


class FrameLog:
    """The timed frames of one renderer: wall, device and CPU ms per frame, per-kernel ms, and
    the queue counts (wavefront only)."""

    def __init__(self, renderer: pyclpt.Renderer) -> None:
        self.renderer = renderer
        self.host: list[float] = []
        self.device: list[float] = []
        self.cpu: list[float] = []
        self.seeds: list[int] = []
        self.kernel_sums: dict[str, dict] = {}
        self.per_seed: list[dict] = []
        self.bounces: list[dict] = []

    def warm_up(self, frames: int) -> None:
        for _ in range(frames):
            self.renderer.render(1, seed=0, progress=False)

    def frame(self, seed: int) -> None:
        h, d, c = _frame(self.renderer, 1, seed)
        self.host.append(h)
        self.device.append(d)
        self.cpu.append(c)
        self.seeds.append(seed)
        st = self.renderer.stats
        for k in st.kernels:
            row = self.kernel_sums.setdefault(k["kernel"], {"kernel": k["kernel"], "ms": 0.0, "launches": 0})
            row["ms"] += k["total_ms"]
            row["launches"] += k["launches"]
        if st.bounces:
            if not any(b.get("tail") for b in st.bounces):  # finish_paths counts none of its bounces
                self.per_seed.append(ray_counts(st.bounces))
            if len(self.seeds) == 1:
                self.bounces = [dict(b) for b in st.bounces]

    def result(self) -> dict:
        n = len(self.host)
        if n == 0:
            raise ValueError("no frame was timed")
        kernels = [{"kernel": k["kernel"], "ms": k["ms"] / n, "launches": k["launches"] / n}
                   for k in self.kernel_sums.values()]
        counts = None
        if self.per_seed:
            counts = {key: statistics.fmean(c[key] for c in self.per_seed) for key in self.per_seed[0]}
        return {"ms": summary(self.host), "device_ms": summary(self.device), "cpu_ms": summary(self.cpu),
                "frames_ms": self.host, "frames_device_ms": self.device, "frames_cpu_ms": self.cpu,
                "kernels": kernels, "bounces": self.bounces, "counts": counts, "seeds": list(self.seeds)}


def time_frames(renderer: pyclpt.Renderer, repeats: int, *, warmup: int = 1, first_seed: int = 1) -> dict:
    """Warm-up frames (seed 0), then ``repeats`` timed frames (seeds ``first_seed``, ...): wall,
    device and process-CPU ms (median/min/max and each frame's), per-kernel ms (mean per frame),
    per-bounce queue counts of the first timed frame and rays per frame (mean; wavefront only,
    else None)."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    log = FrameLog(renderer)
    log.warm_up(warmup)
    for i in range(repeats):
        log.frame(first_seed + i)
    return log.result()


def time_spp(renderers: dict[str, pyclpt.Renderer], spp: int, seed: int = 0, chunks: int = 4) -> dict[str, dict]:
    """``spp`` samples per pixel with each renderer, as ``chunks`` render calls (samples
    [0, a), [a, b), ... of the same seed: together the same samples as one call) interleaved
    across the renderers in rotating order; the times of a renderer's calls are summed."""
    names = list(renderers)
    chunks = max(1, min(chunks, spp))
    edges = [round(spp * j / chunks) for j in range(chunks + 1)]
    acc = {m: [0.0, 0.0, 0.0] for m in names}
    for j in range(chunks):
        k = j % len(names)
        for m in names[k:] + names[:k]:
            h, d, c = _frame(renderers[m], edges[j + 1] - edges[j], seed, first_sample=edges[j])
            acc[m] = [acc[m][0] + h, acc[m][1] + d, acc[m][2] + c]
    return {m: {"spp": spp, "chunks": chunks, "seconds": h / 1e3, "device_seconds": d / 1e3,
                "cpu_seconds": c / 1e3} for m, (h, d, c) in acc.items()}


def count_rays(scene: pyclpt.Scene, depth: int, width: int, height: int, seeds: list[int],
               device: Any = None, bounces: list[dict] | None = None) -> dict[str, float]:
    """Rays per frame (mean over ``seeds``) of the estimator at this depth and resolution,
    counted by a wavefront run (the megakernel traces the same rays; see the module docstring), every
    bounce through the queues (``tail_paths=0``: finish_paths does not count the bounces it runs)."""
    r = make_renderer(scene, "wavefront-soa", depth, width, height, device, tail_paths=0)
    per_seed = []
    for seed in seeds:
        r.render(1, seed=seed, progress=False)
        per_seed.append(ray_counts(r.stats.bounces))
        if bounces is not None and not bounces:  # the first seed's rows, if asked for
            bounces += [dict(b) for b in r.stats.bounces]
    return {key: statistics.fmean(c[key] for c in per_seed) for key in per_seed[0]}


def measure_depth(scene: pyclpt.Scene, methods: list[str], depth: int, width: int, height: int, *,
                  repeats: int, warmup: int = 1, device: Any = None, spp: int | None = None,
                  on_method: Any = None) -> list[dict]:
    """Every method at one max depth: make the renderers (compile and setup timed apart), warm
    each up, then time ``repeats`` rounds of one frame per method (frame i of every method uses
    seed i + 1; the method order rotates each round), so that a change in the machine's load
    hits all methods alike; then, if ``spp`` is given, that many samples per pixel with each
    (:func:`time_spp`, interleaved likewise).
    ``on_method(method)`` is called as each renderer is made (for progress bars)."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    logs, info = {}, {}
    for m in methods:
        if on_method:
            on_method(m)
        t0 = time.perf_counter()
        r = make_renderer(scene, m, depth, width, height, device)
        create_s = time.perf_counter() - t0
        bvh = getattr(getattr(r.scene_buffers, "arrays", None), "bvh", None)
        info[m] = {"compile_s": r.stats.compile_seconds, "setup_s": r.stats.setup_seconds, "create_s": create_s,
                   "bvh_build_s": getattr(bvh, "build_seconds", None)}  # 0 when the BVH came from the cache
        logs[m] = FrameLog(r)
        logs[m].warm_up(warmup)
    for i in range(repeats):
        k = i % len(methods)
        for m in methods[k:] + methods[:k]:
            logs[m].frame(1 + i)
    spp_runs = time_spp({m: logs[m].renderer for m in methods}, spp) if spp else {}
    out = []
    for m in methods:
        r = logs[m].renderer
        res = logs[m].result()
        integrator, layout = METHODS[m]
        res.update(scene=scene.name, method=m, integrator=integrator,
                   layout=layout if integrator == "wavefront" else None, depth=depth, width=r.width,
                   height=r.height, pixels=r.width * r.height, repeats=repeats, warmup=warmup,
                   traced=r.film.width * r.film.height,  # a splatting film's margin too (pyclpt/film/splat.py)
                   memory=dict(r.stats.memory), counts_source="measured" if res["counts"] else None, **info[m])
        if spp:
            res["spp_run"] = spp_runs[m]
        out.append(res)
    return out


def measure(scene: pyclpt.Scene, method: str, depth: int, width: int, height: int, *, repeats: int,
            warmup: int = 1, device: Any = None, spp: int | None = None) -> dict:
    """One configuration alone (see :func:`measure_depth`)."""
    return measure_depth(scene, [method], depth, width, height, repeats=repeats, warmup=warmup, device=device,
                         spp=spp)[0]
