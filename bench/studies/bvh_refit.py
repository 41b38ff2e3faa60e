"""Refit or rebuild after geometry moves? Refit, while the boxes stay within 1.5x of a build's: 4.3-4.9x
faster than Embree on the 871k-triangle dragon, 0.53 s against 2.58 s (docs/bvh.md, "Refitting").

SceneBuffers.refresh_geometry's choice, measured.

Times, alternating in one run, pyclpt.accel.bvh.refit_bvh against build_bvh (Embree, uncached) and the
whole refresh (pack_scene with and without refit) on a mesh moved by a small pose, and reports the
medians and the box-area growth (box_area_ratio) of a refitted tree against a new build after a pose and
after a deformation. Usage: python -m bench.studies.bvh_refit [SCENE] [--repeats N]."""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import pyclpt
from pyclpt.accel.bvh import box_area_ratio, build_bvh, layout_settings, refit_bvh
from pyclpt.buffers.scene import concat_meshes, pack_scene
from pyclpt.scene import transform as tf


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default="cornell-dragon")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    scene = pyclpt.load(args.scene)
    P, T, _, _ = concat_meshes(scene.meshes)
    print(f"{args.scene}: {len(T)} triangles")
    for device_class in ("cpu", "gpu"):
        settings = layout_settings(device_class)
        built = build_bvh(P, T, settings=settings, use_cache=False)
        times: dict[str, list[float]] = {"refit": [], "build": [], "pack+refit": [], "pack+build": []}
        for k in range(args.repeats):
            moved = tf.apply_points(tf.translate([0.0, 0.001 * (k + 1), 0.0]), P.astype(np.float64))
            t = time.perf_counter()
            refit_bvh(built, moved, T)
            times["refit"].append(time.perf_counter() - t)
            t = time.perf_counter()
            build_bvh(moved, T, settings=settings, use_cache=False)
            times["build"].append(time.perf_counter() - t)
            scene.meshes[-1].positions = moved[-len(scene.meshes[-1].positions):]
            t = time.perf_counter()
            pack_scene(scene, device_class, refit=built)
            times["pack+refit"].append(time.perf_counter() - t)
            t = time.perf_counter()
            pack_scene(scene, device_class)  # (served from the BVH cache after the first repeat's build)
            times["pack+build"].append(time.perf_counter() - t)
        med = {k: statistics.median(v) for k, v in times.items()}
        print(f"  {device_class} layout (width {settings.width}): " +
              ", ".join(f"{k} {v:.3f} s" for k, v in med.items()) +
              f"; build / refit {med['build'] / med['refit']:.1f}x")
        for what, m in (("pose (rotate 30 degrees, scale 1.2)", tf.rotate([0, 1, 0], 30) @ tf.scale(1.2)),
                        ("squash (y x 0.3)", tf.scale([1.0, 0.3, 1.0]))):
            q = tf.apply_points(m, P.astype(np.float64))
            r = box_area_ratio(refit_bvh(built, q, T)) / box_area_ratio(built)
            b = box_area_ratio(build_bvh(q, T, settings=settings, use_cache=False)) / box_area_ratio(built)
            print(f"    after a {what}: refitted tree's box areas {r:.2f}x the built one's, a new build's {b:.2f}x")


if __name__ == "__main__":
    main()
