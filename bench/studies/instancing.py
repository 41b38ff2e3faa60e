"""Does instancing cost against flattening? No, it saves: 0.66-0.89x the flattened time per sample, 10 MB of
buffers against 158-635 MB, 16 and 64 bunnies (docs/bvh.md, "Cost against flattening (measured)").

Instancing against flattening: a shapegroup of the Stanford bunny instanced N times on a grid (random
rotations about y, scales 0.8-1.2, one non-uniform), over a floor lit by an area light and a constant
environment. For each N, the instanced scene and the same scene flattened (Scene.flattened: every
instance's triangles copied into plain meshes): the scene's device buffers (SceneArrays.nbytes), the BVH
build (uncached: the bunny's BVH and the top level, against one BVH over every copy), and the render time
per sample (megakernel or wavefront, the variants alternating, medians of --repeats). A third variant,
the flattened scene plus one tiny instance out of sight, measures what the plain meshes pay for going
through the top level as the identity instance.

    python -m bench.studies.instancing [--counts 16,64] [--size 128] [--spp 4] [--depth 4] [--repeats 5]
        [--integrator megakernel|wavefront] [--mesh /work/shared/scenes/meshes/bunny.ply]
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

from bench.report.machine import cpu_model


def bunny_scene(mesh: str, n: int, seed: int = 1) -> dict:
    """The Mitsuba 3 dictionary of n bunnies on a grid."""
    from pyclpt.scene import transform as tf

    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(n)))
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": 50,
                    "to_world": tf.look_at([0, 0.6 * side, 1.3 * side + 1], [0, 0, 0]),
                    "film": {"type": "hdrfilm", "width": 128, "height": 96}},
         "env": {"type": "constant", "radiance": {"type": "rgb", "value": [0.3, 0.3, 0.3]}},
         "bunny": {"type": "shapegroup", "id": "bunny",
                   "mesh": {"type": "ply", "filename": mesh,
                            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.5, 0.4]}}}},
         "floor": {"type": "rectangle", "to_world": tf.scale(side) @ tf.rotate([1, 0, 0], -90)},
         "light": {"type": "rectangle", "to_world": tf.translate([0, side, 0]) @ tf.rotate([1, 0, 0], 90),
                   "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [8, 8, 8]}}}}
    for k in range(n):
        x, z = (k % side - (side - 1) / 2) * 1.2, (k // side - (side - 1) / 2) * 1.2
        s = rng.uniform(0.8, 1.2)
        scale = [s, s * 1.3, s] if k == 0 else [s, s, s]
        d[f"i{k}"] = {"type": "instance", "shape": {"type": "ref", "id": "bunny"},
                      "to_world": tf.translate([x, 0, z]) @ tf.rotate([0, 1, 0], rng.uniform(0, 360))
                      @ tf.scale(scale) @ tf.scale(6.0) @ tf.translate([0.017, -0.033, 0.0015])}
    return d


def with_dummy_instance(scene):
    """``scene`` plus one instance of a one-triangle group out of sight: its plain meshes then go through the
    two-level traversal as the identity instance (the cost of that design against a separate traversal)."""
    from pyclpt.scene.model import Instance, Mesh, Scene, ShapeGroup

    tri = Mesh("dummy", np.array([[0, -50, 0], [1e-3, -50, 0], [0, -50, 1e-3]], np.float32), [[0, 1, 2]], 0)
    return Scene(scene.meshes, scene.materials, scene.camera, scene.film, scene.environment, scene.spp,
                 scene.max_depth, scene.name, groups={"dummy": ShapeGroup("dummy", [tri])},
                 instances=[Instance("dummy", np.eye(4), "dummy")])


def build_seconds(scene) -> tuple[float, float]:
    """Uncached builds: (instanced: each group's BVH + the top level, flattened: one BVH over all)."""
    from pyclpt.accel.bvh import build_bvh
    from pyclpt.accel.instances import build_instanced
    from pyclpt.buffers.scene import concat_meshes

    t = time.perf_counter()
    blas = [build_bvh(*concat_meshes(g.meshes)[:2], use_cache=False) for g in scene.groups.values()]
    plain = build_bvh(*concat_meshes(scene.meshes)[:2], use_cache=False)
    build_instanced([plain, *blas], np.array([0] + [1] * len(scene.instances)),
                    np.array([np.eye(4)] + [i.to_world for i in scene.instances]))
    inst = time.perf_counter() - t
    flat = scene.flattened()
    t = time.perf_counter()
    build_bvh(*concat_meshes(flat.meshes)[:2], use_cache=False)
    return inst, time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--counts", default="16,64")
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--depth", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--integrator", default="megakernel")
    ap.add_argument("--mesh", default=None, help="a mesh file (default: the shared scenes' meshes/bunny.ply)")
    a = ap.parse_args()
    from pyclpt.common import env
    from pyclpt.scene.library import scenes_root

    if env.get("PYCLPT_CACHE_DIR") is None:
        # the flattened scenes' BVHs (millions of triangles) are not worth keeping in the user's cache: run
        # again with a cache folder of this run
        with tempfile.TemporaryDirectory(prefix="pyclpt-instancing-") as tmp:
            child = env.child_environment(PYCLPT_CACHE_DIR=tmp)
            sys.exit(subprocess.run([sys.executable, "-m", __spec__.name, *sys.argv[1:]], env=child).returncode)
    if a.mesh is None:
        root = scenes_root()
        if root is None:
            sys.exit("no --mesh and no shared scene folder: set PYCLPT_SCENES (docs/bvh.md, 'Instances')")
        a.mesh = str(root / "meshes" / "bunny.ply")
    from pyclpt.buffers.scene import pack_scene
    from pyclpt.rendering.renderer import Renderer
    from pyclpt.scene.mitsuba_dict import load_dict

    h = a.size * 3 // 4
    print(f"# CPU: {cpu_model()}; {a.integrator}, {a.size}x{h}, {a.spp} spp a render, depth {a.depth}, "
          f"medians of {a.repeats} alternating renders")
    print("| instances | triangles drawn | variant | scene buffers MB | BVH build s | ms / sample (1 spp of the "
          "image) | ratio |")
    print("|---|---|---|---|---|---|---|")
    for n in (int(c) for c in a.counts.split(",")):
        scene = load_dict(bunny_scene(a.mesh, n))
        flat = scene.flattened()
        variants = {"instanced": scene, "flattened": flat, "flattened + top level": with_dummy_instance(flat)}
        b_inst, b_flat = build_seconds(scene)
        mem = {k: pack_scene(s).nbytes / 2**20 for k, s in variants.items()}
        renderers = {k: Renderer(s, integrator=a.integrator, max_depth=a.depth, width=a.size, height=h)
                     for k, s in variants.items()}
        images = {k: r.render(1, seed=0) for k, r in renderers.items()}  # compile, warm up
        times: dict[str, list[float]] = {k: [] for k in variants}
        for _ in range(a.repeats):
            for k, r in renderers.items():
                t = time.perf_counter()
                images[k] = r.render(a.spp, seed=1)
                times[k].append((time.perf_counter() - t) / a.spp)
        med = {k: statistics.median(v) * 1e3 for k, v in times.items()}
        diff = float(np.mean((images["instanced"] - images["flattened"]) ** 2) / np.mean(images["flattened"] ** 2))
        tris = scene.triangle_count + scene.instanced_triangle_count
        for k in variants:
            print(f"| {n} | {tris:,} | {k} | {mem[k]:.1f} | {b_inst if k == 'instanced' else b_flat:.2f} | "
                  f"{med[k]:.1f} | {med[k] / med['flattened']:.2f} |")
        print(f"#   relMSE instanced vs flattened at {a.spp} spp: {diff:.2e}", flush=True)


if __name__ == "__main__":
    main()
