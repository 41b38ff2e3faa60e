"""Frame time of the megakernel and the wavefront (AoS and SoA path state).

    python -m bench.timing.frame_time [--scene cornell-bunny] [--size 512] [--depths 3 64]
                               [--repeats 5] [--json out.json]

Each frame is 1 spp of every pixel; compile time (program builds and the driver's
first-launch compilation) and scene setup are excluded and reported apart. Times
are medians over --repeats frames after one warm-up frame, with min and max; the
device time is the sum of the kernels' OpenCL profiling events. The wavefront's
per-kernel profile and per-bounce queue sizes are printed for the SoA layout.
Also compares the wavefront's scheduling (readback, pipelined, capacity) and wave sizes.
"""
from __future__ import annotations

import argparse
import json

import pyclpt
from bench.report.runner import time_frames as _time_frames

CONFIGS = [("megakernel", "soa"), ("wavefront", "aos"), ("wavefront", "soa")]


def time_frames(renderer: pyclpt.Renderer, repeats: int) -> dict:
    """One warm-up frame, then ``repeats`` timed frames (see :func:`bench.report.runner.time_frames`)."""
    res = _time_frames(renderer, repeats)
    return {"median_ms": res["ms"]["median"], "min_ms": res["ms"]["min"], "max_ms": res["ms"]["max"],
            "device_median_ms": res["device_ms"]["median"], "kernels": res["kernels"],
            "bounces": res["bounces"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="cornell-bunny")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--depths", type=int, nargs="+", default=[3, 64])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--device", default=None)
    ap.add_argument("--no-variants", action="store_true", help="skip the schedule / wave-size comparison")
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    scene = pyclpt.load(a.scene)
    results = []
    dev = pyclpt.get_device(a.device)
    print(f"# {a.scene} {a.size}x{a.size}, 1 spp/frame, {a.repeats} frames per setting, on {dev.name}")
    print(f"# {scene.triangle_count} triangles\n")
    for depth in a.depths:
        base = None
        print("| depth | integrator | layout | median ms | min | max | device ms | speed-up | compile s |")
        print("|---|---|---|---|---|---|---|---|---|")
        for integrator, layout in CONFIGS:
            r = pyclpt.Renderer(scene, integrator=integrator, layout=layout, max_depth=depth,
                                width=a.size, height=a.size, device=dev)
            res = time_frames(r, a.repeats)
            base = base or res["median_ms"]
            res.update(depth=depth, integrator=integrator, layout=layout,
                       compile_s=r.stats.compile_seconds, setup_s=r.stats.setup_seconds)
            results.append(res)
            print(f"| {depth} | {integrator} | {layout if integrator == 'wavefront' else '-'} | "
                  f"{res['median_ms']:.0f} | {res['min_ms']:.0f} | {res['max_ms']:.0f} | "
                  f"{res['device_median_ms']:.0f} | {base / res['median_ms']:.2f} | {res['compile_s']:.2f} |")
        soa = results[-1]
        print("\nwavefront-soa per kernel (mean per frame):")
        for k in soa["kernels"]:
            share = k["ms"] / max(sum(x["ms"] for x in soa["kernels"]), 1e-9)
            print(f"  {k['kernel']:20s} {k['launches']:6.0f} launches {k['ms']:9.1f} ms {100 * share:5.1f}%")
        print("wavefront-soa per bounce (first timed frame): rays / hits / misses / shadow / unoccluded")
        for b in soa["bounces"][:12]:
            print(f"  {b['bounce']:3d}: {b['rays']:8d} {b['hits']:8d} {b['misses']:8d} {b['shadow_rays']:8d} "
                  f"{b['unoccluded']:8d}")
        print()
    if not a.no_variants:
        depth = max(a.depths)
        print(f"| variant (wavefront-soa, depth {depth}) | median ms | device ms |")
        print("|---|---|---|")
        for schedule in ("readback", "pipelined", "capacity"):
            for wave in (1 << 16, 1 << 18, 1 << 20):
                r = pyclpt.Renderer(scene, integrator="wavefront", layout="soa", max_depth=depth,
                                    width=a.size, height=a.size, device=dev, wave_size=wave)
                r.integrator.schedule = schedule
                res = time_frames(r, a.repeats)
                res.update(variant=f"{schedule} wave={wave}")
                results.append(res)
                print(f"| {schedule}, wave {wave} | {res['median_ms']:.0f} | {res['device_median_ms']:.0f} |")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
