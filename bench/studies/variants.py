"""Which wavefront scheduling, wave size and work-group size? readback (SoA 0.78x of the megakernel, capacity
0.71x; pipelined: docs/wavefront.md, "Scheduling"), work-groups of 64 (16, 256: 2-15% slower), waves of 2^18,
2^16-2^20 alike (docs/wavefront.md, "Measured").

Wavefront tuning on this device: scheduling, wave size and work-group size, all in one run.

    python -m bench.studies.variants [--scene cornell-bunny] [--size 256] [--depth 64] [--repeats 5]

Prints the median frame time (1 spp, compile excluded) of each variant and its ratio to the
megakernel measured in the same run.
"""
from __future__ import annotations

import argparse

import pyclpt
from bench.report.runner import time_frames


def median_ms(r: pyclpt.Renderer, repeats: int) -> float:
    """Median wall ms of ``repeats`` 1-spp frames after a warm-up frame."""
    return time_frames(r, repeats)["ms"]["median"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="cornell-bunny")
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--depth", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args()
    scene = pyclpt.load(a.scene)
    common = dict(max_depth=a.depth, width=a.size, height=a.size)
    variants = [("megakernel", {"integrator": "megakernel"})]
    for ls in (16, 64, 256):
        variants.append((f"megakernel local {ls}", {"integrator": "megakernel", "local_size": ls}))
    for layout in ("aos", "soa"):
        for schedule in ("readback", "pipelined", "capacity"):
            for ls in (16, 64, 256):
                variants.append((f"wavefront {layout} {schedule} local {ls}",
                                 {"integrator": "wavefront", "layout": layout, "schedule": schedule,
                                  "local_size": ls}))
    base = None
    print(f"# {a.scene} {a.size}x{a.size}, depth {a.depth}, 1 spp/frame, median of {a.repeats}")
    print("| variant | median ms | vs megakernel |\n|---|---|---|")
    for name, opts in variants:
        ms = median_ms(pyclpt.Renderer(scene, **common, **opts), a.repeats)
        base = base or ms
        print(f"| {name} | {ms:.0f} | {base / ms:.2f} |", flush=True)


if __name__ == "__main__":
    main()
