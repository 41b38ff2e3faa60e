"""Regenerate the Mitsuba 3 reference images used by tests/test_render.py and tests/test_scenes.py.

    python -m venv /tmp/mts && /tmp/mts/bin/pip install mitsuba
    /tmp/mts/bin/python tests/data/make_mitsuba_reference.py [--shared ../shared/scenes]

1. ``cornell-box-mitsuba-64.npy``: Mitsuba's own cornell_box() dict.
2. ``cornell-box-xml-mitsuba-64.npy``: the shared scene file ``cornell-box/scene.xml`` (Bitterli's
   Mitsuba 3 version), read by Mitsuba's own XML parser with ``integrator=path``; only its tent
   pixel filter is replaced by a box (pyclpt jitters uniformly inside the pixel).

Both with Mitsuba's path tracer at max_depth 8, 64x64, 16384 spp, box filter.
"""
import argparse
import tempfile
from pathlib import Path

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")
HERE = Path(__file__).parent
SPP = 16384


def save(name: str, scene) -> None:
    image = np.array(mi.render(scene, spp=SPP, seed=7), dtype=np.float32)
    np.save(HERE / name, image[..., :3])
    print(HERE / name, image.shape, image.reshape(-1, image.shape[-1]).mean(0))


def builtin_cornell_box() -> None:
    scene_dict = mi.cornell_box()
    scene_dict["sensor"]["film"].update(width=64, height=64, rfilter={"type": "box"})
    scene_dict["integrator"] = {"type": "path", "max_depth": 8}
    save("cornell-box-mitsuba-64.npy", mi.load_dict(scene_dict))


def shared_cornell_box(shared: Path) -> None:
    text = (shared / "cornell-box" / "scene.xml").read_text()
    assert '<rfilter type="tent"' in text
    text = text.replace('<rfilter type="tent"', '<rfilter type="box"')
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "scene.xml"
        path.write_text(text)
        scene = mi.load_file(str(path), integrator="path", max_depth="8", resx="64", resy="64")
    save("cornell-box-xml-mitsuba-64.npy", scene)


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--shared", type=Path, default=HERE.parents[2] / "shared" / "scenes")
    p.add_argument("--only", choices=("builtin", "shared"), default=None)
    a = p.parse_args()
    if a.only != "shared":
        builtin_cornell_box()
    if a.only != "builtin":
        shared_cornell_box(a.shared)
