"""How noisy is the boundary term of primary visibility (pyclpt.gradients.edges), and what does stratifying
the edge points save? The square of tests/test_edges.py (a 1.6 x 1.2 emitter over a constant background,
48 x 48, box filter), d(red sum of the left half)/dx against its exact value, over 32 seeds per setting.
Usage: python -m bench.evaluations.edge_sampling."""
from __future__ import annotations

import math

import numpy as np

import pyclpt
from pyclpt.gradients.edges import primary_boundary
from pyclpt.scene import transform as tf

W = H = 48
FOV, DIST, L_SHAPE, L_BG = 40.0, 5.0, 1.0, 0.25


def scene() -> pyclpt.Scene:
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": FOV, "to_world": tf.look_at([0, 0, DIST], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"}}},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": [L_BG] * 3}},
        "shape": {"type": "rectangle", "to_world": tf.scale([0.8, 0.6, 1.0]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}},
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [L_SHAPE] * 3}}}})


def main() -> None:
    sc = scene()
    g = np.zeros((H, W, 3), np.float32)
    g[:, : W // 2, 0] = 1.0
    s = (W / 2) / (DIST * math.tan(math.radians(FOV / 2)))
    exact = -(L_SHAPE - L_BG) * 1.2 * s * s
    print(f"exact {exact:.3f}")
    for stratified in (False, True):
        for n in (256, 1024, 4096):
            est = [primary_boundary(sc, g, ["shape.to_world"], samples=n, seed=k, stratified=stratified)
                   ["shape.to_world"][0, 3] for k in range(32)]
            err = np.asarray(est) - exact
            print(f"{'stratified' if stratified else 'independent':11s} {n:5d} samples: mean error "
                  f"{err.mean() / abs(exact):+.2e}, relative std {np.std(est) / abs(exact):.2e}")


if __name__ == "__main__":
    main()
