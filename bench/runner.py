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
                  device: Any = None) -> pyclpt.Renderer:
    integrator, layout = METHODS[method]
    return pyclpt.Renderer(scene, integrator=integrator, layout=layout, max_depth=depth, width=width,
                           height=height, device=device)


def _frame(renderer: pyclpt.Renderer, spp: int, seed: int) -> tuple[float, float]:
    """(host ms, device ms) of one render call."""
    t = time.perf_counter()
    renderer.render(spp, seed=seed, progress=False)
    renderer.device.queue.finish()
    host = 1e3 * (time.perf_counter() - t)
    return host, sum(k["total_ms"] for k in renderer.stats.kernels)


def time_frames(renderer: pyclpt.Renderer, repeats: int, *, warmup: int = 1, first_seed: int = 1) -> dict:
    """Warm-up frames (seed 0), then ``repeats`` timed frames: wall and device ms (median/min/max and each
    frame's), per-kernel ms (mean per frame), per-bounce queue counts of the first timed frame
    and rays per frame (mean; wavefront only, else None)."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    for _ in range(warmup):
        renderer.render(1, seed=0, progress=False)
    host, device, per_seed = [], [], []
    kernels: dict[str, dict] = {}
    bounces: list[dict] = []
    for i in range(repeats):
        h, d = _frame(renderer, 1, first_seed + i)
        host.append(h)
        device.append(d)
        st = renderer.stats
        for k in st.kernels:
            row = kernels.setdefault(k["kernel"], {"kernel": k["kernel"], "ms": 0.0, "launches": 0})
            row["ms"] += k["total_ms"] / repeats
            row["launches"] += k["launches"] / repeats
        if st.bounces:
            per_seed.append(ray_counts(st.bounces))
            if i == 0:
                bounces = [dict(b) for b in st.bounces]
    counts = None
    if per_seed:
        counts = {key: statistics.fmean(c[key] for c in per_seed) for key in per_seed[0]}
    return {"ms": summary(host), "device_ms": summary(device), "frames_ms": host, "frames_device_ms": device,
            "kernels": list(kernels.values()), "bounces": bounces, "counts": counts,
            "seeds": [first_seed + i for i in range(repeats)]}


def time_spp(renderer: pyclpt.Renderer, spp: int, seed: int = 0) -> dict:
    """One render of ``spp`` samples per pixel (after the frames that warmed the renderer up)."""
    h, d = _frame(renderer, spp, seed)
    return {"spp": spp, "seconds": h / 1e3, "device_seconds": d / 1e3}


def count_rays(scene: pyclpt.Scene, depth: int, width: int, height: int, seeds: list[int],
               device: Any = None) -> dict[str, float]:
    """Rays per frame (mean over ``seeds``) of the estimator at this depth and resolution,
    counted by a wavefront run (the megakernel traces the same rays; see the module docstring)."""
    r = make_renderer(scene, "wavefront-soa", depth, width, height, device)
    per_seed = []
    for seed in seeds:
        r.render(1, seed=seed, progress=False)
        per_seed.append(ray_counts(r.stats.bounces))
    return {key: statistics.fmean(c[key] for c in per_seed) for key in per_seed[0]}


def measure(scene: pyclpt.Scene, method: str, depth: int, width: int, height: int, *, repeats: int,
            warmup: int = 1, device: Any = None, spp: int | None = None) -> dict:
    """One configuration: make the renderer (compile and setup timed apart), time its frames
    and, if ``spp`` is given, one render of that many samples."""
    t0 = time.perf_counter()
    r = make_renderer(scene, method, depth, width, height, device)
    create_s = time.perf_counter() - t0
    res = time_frames(r, repeats, warmup=warmup)
    integrator, layout = METHODS[method]
    res.update(scene=scene.name, method=method, integrator=integrator,
               layout=layout if integrator == "wavefront" else None, depth=depth, width=r.width,
               height=r.height, pixels=r.width * r.height, repeats=repeats, warmup=warmup,
               compile_s=r.stats.compile_seconds, setup_s=r.stats.setup_seconds, create_s=create_s,
               memory=dict(r.stats.memory), counts_source="measured" if res["counts"] else None)
    bvh = getattr(getattr(r.scene_buffers, "arrays", None), "bvh", None)
    res["bvh_build_s"] = getattr(bvh, "build_seconds", None)  # 0 when the BVH came from the cache
    if spp:
        res["spp_run"] = time_spp(r, spp)
    return res
