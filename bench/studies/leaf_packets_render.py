"""Do leaf packets speed whole renders? Yes: megakernel Msamples/s 1.10-1.26x on PoCL, 1.01-1.19x on Intel's
runtime (docs/bvh.md, "Leaf packets (width 8, default)").

Whole renders: the scalar leaf loop on the old 8-wide build (leaves 1..16, intersection cost 0.35)
versus leaf packets on the new default build (LEAF_DEFAULTS), alternating, medians of --repeats.

    python -m bench.studies.leaf_packets_render [--device pocl|intel] [--size 256] [--spp 16] [--depth 8]
        [--repeats 5] [--mode megakernel|wavefront] scene...
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from bench.studies.bvh_traversal import cpu_model, load_scene
from pyclpt.accel import bvh as bvh_mod
from pyclpt.buffers import scene as scene_mod

VARIANTS = {"scalar, old build": (False, bvh_mod.BuildSettings(width=8, min_leaf=1, intersection_cost=0.35)),
            "packets, new build": (True, bvh_mod.BuildSettings(width=8))}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--device", default=None)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--depth", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--mode", default=None)
    a = ap.parse_args()
    from pyclpt.rendering.renderer import Renderer

    kw = {"integrator": a.mode} if a.mode else {}
    if a.device:
        kw["device"] = a.device
    print(f"# {cpu_model()}, device {a.device or 'default'}, {a.size}^2 {a.spp} spp depth {a.depth}, "
          f"medians of {a.repeats}")
    for name in a.scenes:
        scene = load_scene(name)
        r = {}
        for k, (packets, settings) in VARIANTS.items():
            old = scene_mod.LEAF_PACKETS, bvh_mod.DEFAULT_SETTINGS
            scene_mod.LEAF_PACKETS, bvh_mod.DEFAULT_SETTINGS = packets, settings
            try:
                r[k] = Renderer(scene, width=a.size, height=a.size, max_depth=a.depth, **kw)
            finally:
                scene_mod.LEAF_PACKETS, bvh_mod.DEFAULT_SETTINGS = old
            r[k].render(1)
        times = {k: [] for k in r}
        img = {}
        for _ in range(a.repeats):
            for k in r:
                t0 = time.perf_counter()
                img[k] = r[k].render(a.spp, seed=1)
                times[k].append(time.perf_counter() - t0)
        m = {k: a.size * a.size * a.spp / float(np.median(v)) / 1e6 for k, v in times.items()}
        ks = list(r)
        diff = float(np.mean(np.abs(img[ks[0]] - img[ks[1]])))
        print(f"{name}: " + ", ".join(f"{k} {m[k]:.3f} Msamples/s" for k in ks)
              + f"; ratio {m[ks[1]] / m[ks[0]]:.2f}; mean |image difference| {diff:.2e}", flush=True)


if __name__ == "__main__":
    main()
