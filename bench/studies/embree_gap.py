"""How close is the device's traversal to Embree's? At or above Embree's single-ray rate on Intel's
runtime on every shared scene since any-hit visits children unsorted (docs/bvh.md, "Against Embree"):
the kernels' closest-hit and any-hit rates against Embree's single-ray queries (``rtcIntersect1`` /
``rtcOccluded1`` through embreex) on the same rays.

    python -m bench.studies.embree_gap --device intel                 # the default scenes
    python -m bench.studies.embree_gap --device pocl --scenes shared/staircase --size 256 --repeats 9

Rays, per scene (``bench/studies/bvh_traversal.py``'s, incoherent as a path tracer's): ``camera``, one
jittered camera ray per pixel of a ``--size`` square image (closest hit); ``bounce``, from each camera
ray's first hit a cosine-distributed direction (closest hit); ``shadow``, from the same points a segment
to a random point on an emitting triangle (any hit).

pyclpt traces them with the renderer's own BVH (the default width, leaf packets where the renderer uses
them: ``cl/scene/bvh.h``), one work-item a ray, the time of the kernel (OpenCL profiling event). Embree
traces them on the host from as many threads as the device has compute units (the same cores), one
``rtcIntersect1`` / ``rtcOccluded1`` per ray, the wall time of the call. Each repeat runs every
measurement in turn (alternating); figures are medians of the repeats. Every pyclpt result is checked
against Embree's: the closest hit's distance within 1e-4 relative (or another triangle at the same
distance, a tie) and the any-hit answer the same, the mismatches are counted in the table.

The issue's goal: ≥ 2/3 of Embree's rate on every shared scene, on Intel's runtime (docs/bvh.md,
"Against Embree").
"""
from __future__ import annotations

import argparse
import json
import platform
from pathlib import Path

import numpy as np

from bench.report.embree_ceiling import EmbreeTracer, camera_rays
from bench.report.machine import cpu_model
from bench.studies.bvh_traversal import DEFAULT_SCENES, Tracer, load_scene, make_rays
from pyclpt.accel import bvh as bvh_mod
from pyclpt.accel.bvh import DEFAULT_WIDTH, build_bvh

KINDS = ("camera", "bounce", "shadow")


def _mismatches(kind: str, ours: tuple, embree: dict, ref_t: np.ndarray) -> int:
    """pyclpt's answers that differ from Embree's beyond ties and rounding."""
    t, prim, anyhit = ours
    if kind == "shadow":
        return int(np.count_nonzero(anyhit.astype(bool) != (np.asarray(embree) != -1)))
    e_hit = embree["primID"] >= 0
    o_hit = prim >= 0
    both = e_hit & o_hit
    close = np.abs(t[both] - embree["tfar"][both]) <= 1e-4 * np.maximum(1.0, np.abs(ref_t[both]))
    return int(np.count_nonzero(e_hit != o_hit) + np.count_nonzero(~close))


def measure(tracer: Tracer, name: str, size: int, repeats: int, seed: int, threads: int) -> dict | None:
    scene = load_scene(name)
    if scene is None:
        return None
    pos, idx, _, p, bounce, shadow, smax, _ = make_rays(tracer, scene, size, seed)
    cam_o, cam_d = camera_rays(scene, size, size, np.random.default_rng(seed + 1))
    bvh = build_bvh(pos, idx, settings=bvh_mod.BuildSettings(width=DEFAULT_WIDTH))
    inf_cam = np.full(len(cam_o), np.inf, np.float32)
    inf = np.full(len(p), np.inf, np.float32)
    sets = {"camera": tracer.setup(DEFAULT_WIDTH, bvh, cam_o, cam_d, inf_cam),
            "bounce": tracer.setup(DEFAULT_WIDTH, bvh, p, bounce, inf),
            "shadow": tracer.setup(DEFAULT_WIDTH, bvh, p, shadow, smax)}
    rays = {"camera": (cam_o, cam_d, None), "bounce": (p, bounce, None), "shadow": (p, shadow, smax)}
    which = {"camera": "closest", "bounce": "closest", "shadow": "any"}
    query = {"camera": "INTERSECT", "bounce": "INTERSECT", "shadow": "OCCLUDED"}
    embree = EmbreeTracer(pos, idx, threads)
    try:
        out = {"triangles": int(len(idx)), "nodes": int(bvh.node_count), "rays": {}, "mismatches": {}}
        for k in KINDS:  # warm-up (the driver's lazy compile) and the check against Embree
            tracer.time(sets[k], which[k])
            ours = tracer.results(sets[k])
            o, d, dist = rays[k]
            ref = embree.run(o, d, dist, query[k], output=k != "shadow")
            out["rays"][k] = int(len(o))
            out["mismatches"][k] = _mismatches(k, ours, ref, ours[0])
        times = {(k, e): [] for k in KINDS for e in ("pyclpt", "embree")}
        for _ in range(repeats):
            for k in KINDS:
                times[k, "pyclpt"].append(tracer.time(sets[k], which[k]))
                o, d, dist = rays[k]
                times[k, "embree"].append(embree.throughput(o, d, dist, query[k], repeats=1)["best_s"])
        out["mrays_per_s"] = {f"{k} {e}": out["rays"][k] / float(np.median(v)) / 1e6 for (k, e), v in times.items()}
        out["ratio"] = {k: out["mrays_per_s"][f"{k} pyclpt"] / out["mrays_per_s"][f"{k} embree"] for k in KINDS}
        return out
    finally:
        embree.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default=None, help="OpenCL device (pyclpt's device selector), default the default")
    ap.add_argument("--scenes", default=",".join(DEFAULT_SCENES))
    ap.add_argument("--size", type=int, default=512, help="camera rays: size x size (default 512)")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=0, help="Embree's host threads (default: the device's units)")
    ap.add_argument("--define", action="append", default=[], metavar="NAME=VALUE",
                    help="a -D for the kernels (a traversal variant of cl/scene/bvh.h), repeatable")
    ap.add_argument("--json", type=Path, default=None, help="also write the results here")
    a = ap.parse_args()
    tracer = Tracer(a.device, dict(d.split("=", 1) for d in a.define))
    threads = a.threads or int(tracer.dev.device.max_compute_units)
    print(f"CPU: {cpu_model()} ({platform.machine()}); device: {tracer.dev.device.name} "
          f"({tracer.dev.device.platform.name}); Embree on {threads} threads; width {DEFAULT_WIDTH}; "
          f"{a.size}x{a.size} camera rays; medians of {a.repeats} alternating repeats", flush=True)
    results = {}
    for name in a.scenes.split(","):
        r = measure(tracer, name, a.size, a.repeats, a.seed, threads)
        if r is None:
            print(f"{name}: not found, skipped", flush=True)
            continue
        results[name] = r
        m = r["mrays_per_s"]
        print(f"{name}: " + "  ".join(f"{k} {m[k + ' pyclpt']:.2f}/{m[k + ' embree']:.2f} ({r['ratio'][k]:.2f})"
                                      for k in KINDS) + f"  mismatches {r['mismatches']}", flush=True)
    print("\n| scene | triangles | " + " | ".join(f"{k}: pyclpt / Embree Mrays/s (ratio)" for k in KINDS)
          + " | mismatches |")
    print("|---" * (3 + len(KINDS)) + "|")
    for name, r in results.items():
        m = r["mrays_per_s"]
        cells = " | ".join(f"{m[k + ' pyclpt']:.2f} / {m[k + ' embree']:.2f} ({r['ratio'][k]:.2f})" for k in KINDS)
        print(f"| {name} | {r['triangles']} | {cells} | {sum(r['mismatches'].values())} |")
    if a.json:
        a.json.write_text(json.dumps({"cpu": cpu_model(), "device": tracer.dev.device.name, "threads": threads,
                                      "size": a.size, "repeats": a.repeats, "scenes": results}, indent=1))


if __name__ == "__main__":
    main()
