"""Mitsuba 3's side of ``bench/evaluations/visibility_gradients.py``: run by the Python of a separate Mitsuba
environment (never imported by pyclpt). Renders the square scene of tests/test_edges.py (a 1.6 x 1.2 two-triangle mesh
emitter, radiance 1, over a constant background 0.25, 48 x 48, box filter) with ``direct_projective`` or
``prb_projective`` and prints, as JSON, d(red sum of the image's left half)/d(translation x of the mesh's
vertices) per seed (``dr.backward``) and the median seconds of a render + backward pass.

    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so python -m bench.peers.mitsuba_visibility --seeds 8

``--rectangle`` uses Mitsuba's analytic ``rectangle`` shape moved by its ``to_world`` instead of the mesh.
"""
from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

W = H = 48
VERTS = [(-0.8, -0.6, 0.0), (0.8, -0.6, 0.0), (0.8, 0.6, 0.0), (-0.8, 0.6, 0.0)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--integrator", default="direct_projective")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--rectangle", action="store_true")
    a = ap.parse_args(argv)
    import drjit as dr
    import mitsuba as mi
    import numpy as np

    mi.set_variant(a.variant)
    tmp = Path(tempfile.mkdtemp(prefix="mitsuba-visibility-"))
    ply = tmp / "square.ply"
    ply.write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                   "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
                   + "".join(f"{x} {y} {z}\n" for x, y, z in VERTS) + "3 0 1 2\n3 0 2 3\n")
    shape = ({"type": "rectangle", "to_world": mi.ScalarTransform4f().scale([0.8, 0.6, 1.0])} if a.rectangle
             else {"type": "ply", "filename": str(ply)})
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": a.integrator},
        "sensor": {"type": "perspective", "fov": 40.0, "fov_axis": "x",
                   "to_world": mi.ScalarTransform4f().look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"},
                            "pixel_format": "rgb"}},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": [0.25] * 3}},
        "shape": {**shape, "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}},
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1.0] * 3}}}})
    params = mi.traverse(scene)
    mask = np.zeros((H, W, 3), np.float32)
    mask[:, : W // 2, 0] = 1.0
    key = "shape.to_world" if a.rectangle else "shape.vertex_positions"
    base = mi.Transform4f(params[key]) if a.rectangle else dr.unravel(mi.Point3f, params[key])
    grads, seconds = [], []
    for seed in range(a.seeds + 1):  # the first round compiles Dr.Jit's kernels: not kept
        start = time.perf_counter()
        x = mi.Float(0.0)
        dr.enable_grad(x)
        if a.rectangle:
            params[key] = mi.Transform4f().translate(mi.Point3f(x, 0.0, 0.0)) @ base
        else:
            params[key] = dr.ravel(base + mi.Vector3f(x, 0.0, 0.0))
        params.update()
        img = mi.render(scene, params, spp=a.spp, seed=seed + 1)
        dr.backward(dr.sum(img * mi.TensorXf(mask), axis=None))
        g = float(dr.grad(x)[0])
        if seed:
            grads.append(g)
            seconds.append(time.perf_counter() - start)
    print(json.dumps({"integrator": a.integrator, "spp": a.spp, "shape": "rectangle" if a.rectangle else "mesh",
                      "grads": grads, "seconds": statistics.median(seconds), "mitsuba": mi.__version__}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
