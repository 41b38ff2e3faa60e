"""Scene load times: XML parse, meshes, textures, BVH; cold (empty cache) and cached.

    python -m bench.timing.load_times [--scenes cornell-box staircase2 ...] [--repeats 3]

Each measurement runs in a fresh Python process. "cold" uses an empty PYCLPT_CACHE_DIR (meshes
parsed from OBJ/PLY, BVH built by Embree); "cached" reuses the cache the cold run filled (meshes
and BVH read back from .npz). Textures and environment maps are decoded by OpenImageIO every time;
a sunsky is baked every time (in "meshes", i.e. the rest of the scene model). "pack" is the rest of
turning the scene into device arrays: concatenating meshes, texels, light tables (envmap CDFs).
Prints a markdown table of medians.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from pyclpt.common.env import child_environment

CHILD = r"""
import json, logging, sys, time
logging.getLogger("pyclpt").setLevel(logging.ERROR)  # what a scene does not use is not timed here
import pyclpt.scene.textures as textures  # the mitsuba_dict loaders look read_texture_image up here per call
from pyclpt.scene.mitsuba_xml import xml_to_dict
from pyclpt.scene.mitsuba_dict import load_dict
from pyclpt.buffers.scene import pack_scene

import pyclpt.buffers.scene as scene_buffers

spent = {"textures": 0.0, "bvh": 0.0}
def timed(fn, key):
    def wrapper(*a, **k):
        t = time.perf_counter()
        try:
            return fn(*a, **k)
        finally:
            spent[key] += time.perf_counter() - t
    return wrapper
textures.read_texture_image = timed(textures.read_texture_image, "textures")  # bitmaps and envmaps
scene_buffers.build_bvh = timed(scene_buffers.build_bvh, "bvh")

path = sys.argv[1]
from pathlib import Path
t0 = time.perf_counter()
d = xml_to_dict(path)
t1 = time.perf_counter()
scene = load_dict(d, base_dir=Path(path).parent, name=Path(path).parent.name, origin=path)
t2 = time.perf_counter()
arrays = pack_scene(scene)
t3 = time.perf_counter()
print(json.dumps({"parse": t1 - t0, "meshes": (t2 - t1) - spent["textures"], "textures": spent["textures"],
                  "bvh": spent["bvh"], "pack": (t3 - t2) - spent["bvh"], "total": t3 - t0,
                  "triangles": scene.triangle_count,
                  "textures_count": len(arrays.textures)}))
"""


def run(path: Path, cache: str) -> dict:
    env = child_environment(PYCLPT_CACHE_DIR=cache)
    out = subprocess.run([sys.executable, "-c", CHILD, str(path)], env=env, capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    from pyclpt.scene.library import scenes_root

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", nargs="*", default=["cornell-box", "staircase2", "living-room", "staircase",
                                                   "classroom"])
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args(argv)
    root = scenes_root()
    if root is None:
        print("the shared scene folder was not found (PYCLPT_SCENES)", file=sys.stderr)
        return 1
    keys = ("parse", "meshes", "textures", "bvh", "pack", "total")
    print("| scene | triangles | textures | run | " + " | ".join(f"{k} (s)" for k in keys) + " |")
    print("|---|---|---|---|" + "---|" * len(keys))
    for name in a.scenes:
        path = root / name / "scene.xml"
        cold, warm = [], []
        for _ in range(a.repeats):
            with tempfile.TemporaryDirectory(prefix="pyclpt-load-") as cache:
                cold.append(run(path, cache))
                warm.append(run(path, cache))
        for label, rows in (("cold", cold), ("cached", warm)):
            med = {k: statistics.median(r[k] for r in rows) for k in keys}
            print(f"| {name} | {rows[0]['triangles']:,} | {rows[0]['textures_count']} | {label} | "
                  + " | ".join(f"{med[k]:.2f}" for k in keys) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
