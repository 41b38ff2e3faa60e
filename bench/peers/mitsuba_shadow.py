"""Mitsuba 3's side of the hard-shadow test (tests/test_shadows.py, docs/differentiable.md "The boundary term of
hard shadows"): run by the Python of a separate Mitsuba environment (never imported by pyclpt). A 0.6 x 0.6 black
square mesh half-way between a light at (-4, 0, 3) and a diffuse floor (albedo 0.5), 48 x 48, box filter, the
camera looking straight down from (0, 0, 3); prints, as JSON, d(image sum)/d(translation x of the square's
vertices) per seed (``dr.backward``) and the seconds of each render + backward pass. The exact value for a point
light of intensity 20 is 153.897 (the test's quadrature).

    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so python -m bench.peers.mitsuba_shadow --light point
    DRJIT_LIBLLVM_PATH=... python -m bench.peers.mitsuba_shadow --light sphere --radius 0.05

``--light sphere`` replaces the point light by a small spherical area light of the same intensity (radiance
I / (pi r^2)), whose soft shadow the projective integrators do sample.
"""
from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from pathlib import Path

W = H = 48
INTENSITY = 20.0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--integrator", default="direct_projective")
    ap.add_argument("--light", choices=("point", "sphere"), default="point")
    ap.add_argument("--radius", type=float, default=0.05)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--variant", default="llvm_ad_rgb")
    a = ap.parse_args(argv)
    import drjit as dr
    import mitsuba as mi
    import numpy as np

    mi.set_variant(a.variant)
    tmp = Path(tempfile.mkdtemp(prefix="mitsuba-shadow-"))
    c, s = math.cos(math.radians(25)), math.sin(math.radians(25))
    verts = [(-2 + 0.3 * (c * x - s * y), 0.3 * (s * x + c * y), 1.5) for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    ply = tmp / "occluder.ply"
    ply.write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                   "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
                   + "".join(f"{x} {y} {z}\n" for x, y, z in verts) + "3 0 1 2\n3 0 2 3\n")
    if a.light == "point":
        light = {"type": "point", "position": [-4, 0, 3], "intensity": {"type": "rgb", "value": [INTENSITY] * 3}}
    else:
        radiance = INTENSITY / (math.pi * a.radius ** 2)
        light = {"type": "sphere", "center": [-4, 0, 3], "radius": a.radius,
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [radiance] * 3}}}
    black = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}}
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": a.integrator},
        "sensor": {"type": "perspective", "fov": 40.0, "fov_axis": "x",
                   "to_world": mi.ScalarTransform4f().look_at([0, 0, 3], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"},
                            "pixel_format": "rgb"}},
        "light": light,
        "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale(6.0),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}}},
        "occluder": {"type": "ply", "filename": str(ply), "bsdf": black},
    })
    params = mi.traverse(scene)
    key = "occluder.vertex_positions"
    rest = dr.unravel(mi.Point3f, params[key])
    grads, seconds = [], []
    for seed in range(a.seeds):
        t = mi.Float(0.0)
        dr.enable_grad(t)
        params[key] = dr.ravel(rest + mi.Vector3f(t, 0, 0))
        params.update()
        start = time.perf_counter()
        image = mi.render(scene, params, spp=a.spp, seed=seed)
        dr.backward(dr.sum(image))
        grads.append(float(np.asarray(dr.grad(t)).reshape(-1)[0]))
        seconds.append(time.perf_counter() - start)
    print(json.dumps({"integrator": a.integrator, "light": a.light, "radius": a.radius if a.light == "sphere" else 0,
                      "spp": a.spp, "grads": grads, "mean": float(np.mean(grads)),
                      "std_of_mean": float(np.std(grads, ddof=1) / math.sqrt(len(grads))) if len(grads) > 1 else None,
                      "seconds": seconds}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
