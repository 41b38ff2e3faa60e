"""Devices side by side: Msamples/s of each integrator on PoCL and Intel's CPU OpenCL runtime.

    python -m bench.timing.devices [--scene cornell-box] [--size 256] [--spp 64] [--depth 8]
                            [--repeats 5] [--devices pocl intel] [--json out.json]

One process, one scene, the same settings on every device. Each repeat renders ``--spp`` samples
per pixel with every (device, integrator) in turn, the order alternating between repeats, so that
load from other processes on a shared machine falls on all of them alike; the table gives the
median over repeats (with min and max) and each integrator's Intel / PoCL ratio of medians.
Compilation and setup come before the first repeat (one warm-up frame per renderer) and are not
timed. A device that is not there (``pip install "pyclpt[intel]"`` for Intel's) is reported and
left out.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import pyclpt
from bench.report.machine import cpu_model

INTEGRATORS = [("megakernel", "soa"), ("wavefront", "soa")]


def measure(scene_name: str = "cornell-box", size: int = 256, spp: int = 64, depth: int = 8, repeats: int = 5,
            devices: tuple[str, ...] = ("pocl", "intel"), integrators=INTEGRATORS, seed: int = 0) -> dict:
    """Msamples/s per (device, integrator, layout): medians, mins and maxes over ``repeats`` renders."""
    scene = pyclpt.load(scene_name)
    renderers, missing = {}, {}
    for spec in devices:
        try:
            dev = pyclpt.get_device(spec)
        except pyclpt.DeviceError as exc:
            missing[spec] = str(exc)
            continue
        for integrator, layout in integrators:
            r = pyclpt.Renderer(scene, integrator=integrator, layout=layout, max_depth=depth, width=size,
                                height=size, device=dev)
            r.render(spp=1, seed=seed)  # compilation and the driver's first launch, untimed
            renderers[(spec, integrator, layout)] = (dev, r)
    samples = size * size * spp
    times: dict = {k: [] for k in renderers}
    keys = list(renderers)
    for rep in range(repeats):
        for key in (keys if rep % 2 == 0 else keys[::-1]):
            r = renderers[key][1]
            start = time.perf_counter()
            r.render(spp=spp, seed=seed)
            times[key].append(time.perf_counter() - start)
    rows = []
    for (spec, integrator, layout), (dev, _) in renderers.items():
        ts = times[(spec, integrator, layout)]
        rows.append({"device": spec, "device_name": dev.name, "integrator": integrator, "layout": layout,
                     "seconds": ts, "median_s": statistics.median(ts),
                     "msamples_per_s": samples / statistics.median(ts) / 1e6,
                     "min_msamples_per_s": samples / max(ts) / 1e6, "max_msamples_per_s": samples / min(ts) / 1e6})
    return {"scene": scene_name, "size": size, "spp": spp, "max_depth": depth, "repeats": repeats,
            "cpu": cpu_model(), "rows": rows, "missing": missing}


def table(res: dict) -> str:
    lines = [f"# {res['scene']} {res['size']}x{res['size']}, {res['spp']} spp, depth {res['max_depth']}, "
             f"median of {res['repeats']} (alternating order), {res['cpu']}",
             "", "| device | integrator | Msamples/s (median) | min | max | vs PoCL |", "|---|---|---|---|---|---|"]
    base = {(r["integrator"], r["layout"]): r["msamples_per_s"] for r in res["rows"] if r["device"] == "pocl"}
    for r in res["rows"]:
        b = base.get((r["integrator"], r["layout"]))
        ratio = f"{r['msamples_per_s'] / b:.2f}x" if b else "-"
        name = r["integrator"] if r["integrator"] == "megakernel" else f"{r['integrator']} {r['layout'].upper()}"
        lines.append(f"| {r['device_name']} | {name} | {r['msamples_per_s']:.2f} | {r['min_msamples_per_s']:.2f} | "
                     f"{r['max_msamples_per_s']:.2f} | {ratio} |")
    for spec, why in res["missing"].items():
        lines.append(f"\n{spec}: not measured ({why})")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="cornell-box")
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--depth", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--devices", nargs="+", default=["pocl", "intel"])
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    res = measure(a.scene, a.size, a.spp, a.depth, a.repeats, tuple(a.devices))
    print(table(res))
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
