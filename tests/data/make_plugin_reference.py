"""Regenerate the Mitsuba 3 renders that the plug-in tests compare pyclpt's renders of the same files with:
``NAME-mitsuba.npy`` for each ``NAME.xml`` below.

    /tmp/mts/bin/python tests/data/make_plugin_reference.py [NAME ...]

- ``delta-emitters.xml``: a spot and a directional light over a floor and a box (tests/test_lights.py);
- ``cylinder.xml``: a textured cylinder given by p0, p1 and radius (tests/test_plugins.py);
- ``thinlens.xml``, ``orthographic.xml``: the two other cameras, over boxes at several depths;
- ``uv-shapes.xml``: the texture coordinates of the rectangle, disk, sphere and cube
  (tests/test_plugins.py);
- ``uv-transforms.xml``: a checkerboard as a colour and as a mask's opacity, a bitmap under to_uv
  scale + translate + rotate, a rotated checkerboard on a sphere (tests/test_plugins.py);
- ``emitter-textures.xml``: an area light with a bitmap radiance and a spot light projecting a bitmap
  (tests/test_plugins.py);
- ``rfilter.xml`` with ``filter=tent`` and ``filter=gaussian``: ``rfilter-tent-mitsuba.npy``,
  ``rfilter-gaussian-mitsuba.npy``, the reconstruction filters (tests/test_rfilter.py);
- ``sunsky.xml``: Mitsuba 3's ``sunsky`` (sun from a place and time) over a floor and a box
  (tests/test_plugins.py);
- ``anisotropy.xml``: anisotropic rough conductors and a rough dielectric, as it is and, as
  ``anisotropy-swapped``, with alpha_u and alpha_v swapped (tests/test_plugins.py);
- ``twosided-pair.xml``: twosided with a different BSDF on each side (tests/test_plugins.py);
- ``instances.xml``: a shapegroup of three shapes instanced four times (rotations, a non-uniform scale)
  (tests/test_instances.py).

Mitsuba's path tracer as each file says (box filter unless the name says otherwise), 16384 spp.
"""
import sys
from pathlib import Path

import mitsuba as mi
import numpy as np

mi.set_variant("llvm_ad_rgb" if "llvm_ad_rgb" in mi.variants() else "scalar_rgb")
HERE = Path(__file__).parent
NAMES = ("delta-emitters", "cylinder", "thinlens", "orthographic", "uv-shapes", "uv-transforms",
         "emitter-textures", "sunsky", "rfilter-tent", "rfilter-gaussian", "anisotropy", "anisotropy-swapped",
         "twosided-pair", "instances")
#: references of one file rendered with other parameters (<default> values): name -> (file, parameters)
VARIANTS = {"rfilter-tent": ("rfilter", {"filter": "tent"}), "rfilter-gaussian": ("rfilter", {"filter": "gaussian"}),
            "anisotropy-swapped": ("anisotropy", {"au": "0.35", "av": "0.04"})}

if __name__ == "__main__":
    for name in sys.argv[1:] or NAMES:
        file, params = VARIANTS.get(name, (name, {}))
        scene = mi.load_file(str(HERE / f"{file}.xml"), **params)
        image = np.array(mi.render(scene, spp=16384, seed=7), dtype=np.float32)[..., :3]
        np.save(HERE / f"{name}-mitsuba.npy", image)
        print(name, image.shape, image.reshape(-1, 3).mean(0))
