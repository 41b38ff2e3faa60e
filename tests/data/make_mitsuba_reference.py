"""Regenerate the Mitsuba 3 reference images used by tests/test_reference.py.

    python -m venv /tmp/mts && /tmp/mts/bin/pip install mitsuba
    /tmp/mts/bin/python tests/data/make_mitsuba_reference.py

Mitsuba's own cornell_box() with a box pixel filter (pyclpt jitters uniformly
inside the pixel), its path tracer at max_depth 8, 64x64, 16384 spp.
"""
from pathlib import Path

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")
scene_dict = mi.cornell_box()
scene_dict["sensor"]["film"].update(width=64, height=64, rfilter={"type": "box"})
scene_dict["integrator"] = {"type": "path", "max_depth": 8}
scene = mi.load_dict(scene_dict)
image = np.array(mi.render(scene, spp=16384, seed=7), dtype=np.float32)
out = Path(__file__).with_name("cornell-box-mitsuba-64.npy")
np.save(out, image[..., :3])
print(out, image.shape, image.reshape(-1, image.shape[-1]).mean(0))
