"""The boundary term of primary visibility against the exact answer, finite differences and Mitsuba 3's
projective integrators, on the square of tests/test_edges.py: d(red sum of the image's left half)/dx.

    python -m bench.evaluations.visibility_gradients [--mitsuba-python PATH/TO/mitsuba-venv/bin/python]

pyclpt: ``primary_boundary`` over 8 seeds at 4,096 edge samples (mean, standard deviation, median
seconds); central finite differences of rendered images (256 spp, step 0.05); Mitsuba (when its Python is
given; it needs DRJIT_LIBLLVM_PATH for llvm_ad_rgb): ``direct_projective`` and ``prb_projective`` at 64
spp over 8 seeds, on the mesh and on its analytic ``rectangle``."""
from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import time
from pathlib import Path

import numpy as np

import pyclpt
from pyclpt.gradients.edges import primary_boundary
from pyclpt.scene import transform as tf

W = H = 48
FOV, DIST, L_SHAPE, L_BG = 40.0, 5.0, 1.0, 0.25


def scene(dx: float = 0.0) -> pyclpt.Scene:
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": FOV, "to_world": tf.look_at([0, 0, DIST], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"}}},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": [L_BG] * 3}},
        "shape": {"type": "rectangle", "to_world": tf.translate([dx, 0, 0]) @ tf.scale([0.8, 0.6, 1.0]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}},
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [L_SHAPE] * 3}}}})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mitsuba-python", type=Path)
    ap.add_argument("--seeds", type=int, default=8)
    a = ap.parse_args()
    s = (W / 2) / (DIST * math.tan(math.radians(FOV / 2)))
    rows = [("exact", -(L_SHAPE - L_BG) * 1.2 * s * s, 0.0, None)]
    g = np.zeros((H, W, 3), np.float32)
    g[:, : W // 2, 0] = 1.0
    sc = scene()
    est, secs = [], []
    primary_boundary(sc, g, ["shape.to_world"], samples=4096, seed=99)  # compiles the kernel: not timed
    for k in range(a.seeds):
        t = time.perf_counter()
        est.append(float(primary_boundary(sc, g, ["shape.to_world"], samples=4096, seed=k)["shape.to_world"][0, 3]))
        secs.append(time.perf_counter() - t)
    rows.append(("pyclpt primary_boundary, 4096 edge samples", statistics.mean(est), statistics.stdev(est),
                 statistics.median(secs)))
    h = 0.05
    fd = (pyclpt.render(scene(h), spp=256, seed=3)[:, : W // 2, 0].sum()
          - pyclpt.render(scene(-h), spp=256, seed=3)[:, : W // 2, 0].sum()) / (2 * h)
    rows.append(("pyclpt finite differences, 256 spp", float(fd), float("nan"), None))
    if a.mitsuba_python:
        script = Path(__file__).resolve().parents[1] / "peers" / "mitsuba_visibility.py"
        for integrator in ("direct_projective", "prb_projective"):
            for extra in ([], ["--rectangle"]):
                out = subprocess.run([str(a.mitsuba_python), str(script), "--integrator", integrator, "--seeds",
                                      str(a.seeds), *extra], capture_output=True, text=True, check=True)
                last = [line for line in out.stdout.splitlines() if "{" in line][-1]  # after Mitsuba's log colours
                r = json.loads(last[last.index("{"):])
                rows.append((f"Mitsuba {r['mitsuba']} {integrator}, {r['shape']}, {r['spp']} spp",
                             statistics.mean(r["grads"]), statistics.stdev(r["grads"]), r["seconds"]))
    print("| estimator | d/dx | std over seeds | seconds |\n|---|---|---|---|")
    for name, mean, std, sec in rows:
        print(f"| {name} | {mean:.2f} | {std:.2f} | {'' if sec is None else f'{sec:.3f}'} |")


if __name__ == "__main__":
    main()
