"""Regenerate ``envmap-mitsuba3-eval.npz``: Mitsuba 3's own ``envmap`` emitter evaluated along
200 random directions, for tests/test_lights.py (pyclpt's lat-long convention against Mitsuba's).

    python -m venv /tmp/mts && /tmp/mts/bin/pip install mitsuba
    /tmp/mts/bin/python tests/data/make_envmap_reference.py

A 16x9 random map (so that every texel differs), rotated by to_world, scale 2.
"""
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")
HERE = Path(__file__).parent

rng = np.random.default_rng(0)
pixels = (rng.random((9, 16, 3)) + 0.1).astype(np.float32)
to_world = mi.ScalarTransform4f().rotate(list(np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)), 40)
emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(pixels), "to_world": to_world, "scale": 2.0})
dirs = rng.normal(size=(200, 3))
dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
values = []
for d in dirs:
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(-d)  # eval() looks up the direction -wi
    values.append(np.array(emitter.eval(si)))
np.savez(HERE / "envmap-mitsuba3-eval.npz", pixels=pixels, to_world=np.array(to_world.matrix),
         scale=2.0, dirs=dirs, values=np.array(values))
print(HERE / "envmap-mitsuba3-eval.npz", mi.__version__)
