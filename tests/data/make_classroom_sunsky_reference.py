"""Regenerate ``classroom-sunsky-mitsuba3.npz``: Mitsuba 3 renders of the classroom scene
(``$PYCLPT_SCENES/classroom/scene.xml``, a Mitsuba 0.6 file lit by a ``sunsky``) for
tests/test_scenes.py::test_classroom_sunsky_matches_mitsuba3.

    DRJIT_LIBLLVM_PATH=... /tmp/mitsuba-venv/bin/python tests/data/make_classroom_sunsky_reference.py

The file goes through ``bench/report/mitsuba_driver.py``'s ``edit_xml`` (Mitsuba's ``path`` integrator, max depth
8, rr depth 3; a 96x54 ``hdrfilm`` with a box filter; ``independent`` sampler), which turns the 0.6
``sunsky`` into Mitsuba 3's in Mitsuba 3's frame: the same sun direction in the world (``sunDirection``
kept, a -90 degree rotation about x prepended to the sky's ``toWorld``: 0.5's sky is +y up, Mitsuba 3's
+z up), the same turbidity (3), ``skyScale`` 6 and ``sunScale`` 10, ``sun_aperture`` 0.5358 deg x
``sunRadiusScale`` (18.8131), and Mitsuba 0.5's default ground albedo 0.2 (Mitsuba 3's is 0.3). The
sky is the same model (Hosek-Wilkie 2012, RGB) in both versions; the sun is **Mitsuba 3's**
(Hosek-Wilkie 2013 solar radiance, uniform disk), not Mitsuba 0.5's (Preetham/Iqbal) that pyclpt uses
for a 0.6 file. Three renders: as the file says, sky only
(``sunScale`` 0) and sun only (``skyScale`` 0), to tell the two apart. Stored: their per-channel means,
and the full image as float16.
"""
from __future__ import annotations

import argparse
import os
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import mitsuba as mi
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))
from bench.report.mitsuba_driver import edit_xml  # noqa: E402

WIDTH, HEIGHT, MAX_DEPTH, SPP = 96, 54, 8, 4096


def scaled(text: str, sky_scale: float | None = None, sun_scale: float | None = None) -> str:
    """The scene with the sunsky's skyScale / sunScale replaced."""
    root = ET.fromstring(text)
    for em in root.iter("emitter"):
        for child in em.findall("float"):
            if child.get("name") == "skyScale" and sky_scale is not None:
                child.set("value", str(sky_scale))
            if child.get("name") == "sunScale" and sun_scale is not None:
                child.set("value", str(sun_scale))
    return ET.tostring(root, encoding="unicode")


def main() -> None:
    mi.set_variant("llvm_ad_rgb")
    path = Path(os.environ.get("PYCLPT_SCENES", "/work/shared/scenes")) / "classroom" / "scene.xml"
    mi.file_resolver().prepend(str(path.parent))
    a = argparse.Namespace(max_depth=MAX_DEPTH, rr_depth=3, spp=SPP, width=WIDTH, height=HEIGHT)
    out: dict[str, np.ndarray] = {}
    for name, kw in (("full", {}), ("sky", {"sun_scale": 0.0}), ("sun", {"sky_scale": 0.0})):
        scene = mi.load_string(edit_xml(scaled(path.read_text(), **kw), a))
        image = np.array(mi.render(scene, spp=SPP, seed=3), dtype=np.float32)[..., :3]
        out[f"{name}_mean"] = image.reshape(-1, 3).mean(0)
        if name == "full":
            out["image"] = image.astype(np.float16)
        print(name, out[f"{name}_mean"])
    np.savez_compressed(HERE / "classroom-sunsky-mitsuba3.npz", **out, spp=SPP, max_depth=MAX_DEPTH)
    print(HERE / "classroom-sunsky-mitsuba3.npz", mi.__version__)


if __name__ == "__main__":
    main()
