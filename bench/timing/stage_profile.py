"""Per-stage throughput of the wavefront and its ratio to the megakernel; per-kernel vectorizer remarks.

    python -m bench.timing.stage_profile speed [--repeats 5] [--size 256] [--scenes cornell-box cornell-bunny]
                                        [--depths 64 8]
    POCL_VECTORIZER_REMARKS=1 POCL_KERNEL_CACHE=0 python -m bench.timing.stage_profile remarks

``speed``: per scene and max depth, 1-spp frames of the megakernel, wavefront SoA and wavefront AoS,
alternated frame by frame (after a warm-up frame each), ``--repeats`` frames each; prints one JSON
line per setting with each integrator's median frame ms, the wavefront / megakernel speed ratios
(megakernel ms / wavefront ms: > 1 means the wavefront is faster) and, for the wavefront SoA, each
stage's median Mitems/s and share of the kernel time. A stage's items are what it processes:
path_init the paths, intersect the rays, miss the misses, process_hit and sample_bsdf the hits,
shadow_test the shadow rays, light_contribution the unoccluded shadow rays, the compaction
(compact_count, compact_scatter) the entries of the queues it compacts (rays + 2 hits + shadow rays).

``remarks``: renders a 64x64 frame with the wavefront SoA, each kernel's first launch (when PoCL
compiles it) framed by markers, and prints every kernel's loop-vectorizer remarks (LLVM prints them on
stdout) with counts (the loop vectorizer's only; PoCL vectorizes across work-items by vectorizing the
work-item loop it wraps around a kernel). Needs PoCL's kernel cache off.

It runs against whichever pyclpt the interpreter imports, so the same script measures two checkouts.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from collections import defaultdict

import pyclpt

from .vectorizer_remarks import collect

ITEMS = {"path_init": "paths", "intersect": "rays", "miss": "misses", "process_hit": "hits",
         "sample_bsdf": "hits", "shadow_test": "shadow_rays", "light_contribution": "unoccluded",
         "compact_count": "compacted", "compact_scatter": "compacted"}


def frame(r: pyclpt.Renderer, seed: int) -> tuple[float, dict[str, float], dict[str, int]]:
    """One 1-spp frame: wall ms, per-kernel device ms, items per kind."""
    w = r.integrator
    w.profile.clear()
    if hasattr(w, "reset_stats"):
        w.reset_stats()
    q = r.device.queue
    q.finish()
    start = time.perf_counter()
    w.render_frame(seed, 0)
    q.finish()
    ms = (time.perf_counter() - start) * 1e3
    kernel_ms = {row["kernel"]: float(row["total_ms"]) for row in w.profile.table()}
    items: dict[str, int] = {"paths": r.film.pixels}
    if hasattr(w, "bounce_stats"):
        for row in w.bounce_stats():
            for k, v in row.items():
                if k != "bounce":
                    items[k] = items.get(k, 0) + v
        items["compacted"] = items["rays"] + 2 * items["hits"] + items["shadow_rays"]
    return ms, kernel_ms, items


def speed(args: argparse.Namespace) -> None:
    variants = {"megakernel": {"integrator": "megakernel"},
                "wavefront_soa": {"integrator": "wavefront", "layout": "soa"},
                "wavefront_aos": {"integrator": "wavefront", "layout": "aos"}}
    for scene_name in args.scenes:
        scene = pyclpt.load(scene_name)
        for depth in args.depths:
            rs = {name: pyclpt.Renderer(scene, max_depth=depth, width=args.size, height=args.size, **kw)
                  for name, kw in variants.items()}
            for r in rs.values():
                frame(r, 0)  # warm-up
            ms: dict[str, list[float]] = defaultdict(list)
            stage_rate: dict[str, list[float]] = defaultdict(list)
            stage_ms: dict[str, list[float]] = defaultdict(list)
            for rep in range(args.repeats):
                names = list(rs)
                names = names[rep % len(names):] + names[:rep % len(names)]  # rotate who goes first
                for name in names:
                    t, kernel_ms, items = frame(rs[name], rep + 1)
                    ms[name].append(t)
                    if name == "wavefront_soa":
                        for k, v in kernel_ms.items():
                            stage_ms[k].append(v)
                            if k in ITEMS and v > 0:
                                stage_rate[k].append(items[ITEMS[k]] / (v * 1e3))
            med = {k: statistics.median(v) for k, v in ms.items()}
            total = sum(statistics.median(v) for v in stage_ms.values()) or 1.0
            print(json.dumps({
                "pyclpt": os.path.dirname(pyclpt.__file__), "scene": scene_name, "size": args.size,
                "max_depth": depth, "repeats": args.repeats,
                "median_ms": {k: round(v, 2) for k, v in med.items()},
                "min_max_ms": {k: [round(min(v), 2), round(max(v), 2)] for k, v in ms.items()},
                "vs_megakernel": {k: round(med["megakernel"] / v, 3) for k, v in med.items() if k != "megakernel"},
                "soa_stage_mitems_s": {k: round(statistics.median(v), 3) for k, v in stage_rate.items()},
                "soa_stage_share": {k: round(statistics.median(v) / total, 3) for k, v in stage_ms.items()},
            }), flush=True)


def remarks(args: argparse.Namespace) -> None:
    def render() -> None:
        r = pyclpt.Renderer(pyclpt.load(args.scenes[0]), integrator="wavefront", layout=args.layout,
                            max_depth=8, width=64, height=64)
        r.render(1, progress=False)
    print(json.dumps({"pyclpt": os.path.dirname(pyclpt.__file__), **collect(render)}, indent=1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=("speed", "remarks"))
    ap.add_argument("--scenes", nargs="+", default=["cornell-box", "cornell-bunny"])
    ap.add_argument("--depths", nargs="+", type=int, default=[64, 8])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--layout", default="soa")
    args = ap.parse_args()
    {"speed": speed, "remarks": remarks}[args.mode](args)


if __name__ == "__main__":
    main()
