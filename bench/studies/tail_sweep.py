"""How many paths should the wavefront's tail take? A quarter of the wave: 0.25-0.30x of the megakernel without a
tail -> 0.72-0.90x at depth 65 on 128² frames, 1.16x at depth 8 on Intel (docs/wavefront.md, "The tail").

The wavefront's tail: megakernel time over wavefront SoA time for
several ``tail_paths``, given as fractions of the wave, in one run on one device.

    python -m bench.studies.tail_sweep [--device intel] [--repeats 3] [--spp 16] [--fractions 0 16 8 4 2]

Settings: cornell-box 256x256 at max depth 8, cornell-box and the shared staircase2 128x128 at depth
65 (``PYCLPT_SCENES`` must name the shared scene folder). Each round renders ``--spp`` samples with
every renderer, the order fixed within a round; medians over ``--repeats`` rounds after one warm-up
sample each; compile excluded. Fraction 0 means no tail (``tail_paths=0``), f means ``wave // f``.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time

import pyclpt
from bench.report.machine import cpu_model
from pyclpt.scene.library import shared_path

SETTINGS = (("cornell-box", 256, 8), ("cornell-box", 128, 65), ("staircase2", 128, 65))


def load(name: str) -> pyclpt.Scene:
    return pyclpt.load(name if name == "cornell-box" else shared_path(f"{name}/scene.xml"))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default=None)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--fractions", type=int, nargs="+", default=[0, 16, 8, 4, 2])
    a = ap.parse_args(argv)
    print(f"{pyclpt.get_device(a.device).name} on {cpu_model()}; {a.spp} spp, median of {a.repeats}")
    print("scene, size, depth: megakernel time / wavefront SoA time for tail_paths = wave // fraction")
    for name, size, depth in SETTINGS:
        scene = load(name)
        kw = dict(max_depth=depth, width=size, height=size, device=a.device)
        renderers = {"megakernel": pyclpt.Renderer(scene, integrator="megakernel", **kw)}
        for f in a.fractions:
            tail = size * size // f if f else 0
            renderers[f"1/{f}" if f else "no tail"] = pyclpt.Renderer(scene, integrator="wavefront",
                                                                      tail_paths=tail, **kw)
        times: dict[str, list[float]] = {k: [] for k in renderers}
        for r in renderers.values():
            r.render(1, seed=0)
        for rep in range(a.repeats):
            for key, r in renderers.items():
                start = time.perf_counter()
                r.render(a.spp, seed=rep + 1)
                times[key].append(time.perf_counter() - start)
        med = {k: statistics.median(v) for k, v in times.items()}
        ratios = ", ".join(f"{k} {med['megakernel'] / v:.2f}x" for k, v in med.items() if k != "megakernel")
        print(f"{name} {size}x{size}, depth {depth}: {ratios}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
