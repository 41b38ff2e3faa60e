"""Do leaf packets beat the scalar leaf loop? Yes, hits bit-identical, traversal 1.06-1.68x (closest) on five
scenes, PoCL and Intel, with the 2..16-leaf build (docs/bvh.md, "Leaf packets (width 8, default)").

Leaf packets (cl/scene/bvh.h BVH_LEAF_PACKETS) versus the scalar leaf loop: exactness and speed.

Same rays as bench/studies/bvh_traversal.py (bounce rays for closest hit, shadow rays for any hit, from the
first hits of camera rays); the two variants run alternately, figures are medians of --repeats.
Checks that closest-hit t and prim and any-hit results are identical.

    python -m bench.studies.leaf_packets [--device pocl|intel] [--width 8] [--size 256] [--repeats 7] [scenes...]
"""

from __future__ import annotations

import argparse

import numpy as np

from bench.studies.bvh_traversal import KERNELS, Tracer, cpu_model, load_scene, make_rays
from pyclpt.accel import bvh as bvh_mod
from pyclpt.accel.bvh import build_bvh, leaf_packet_buffer


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="*", default=["cornell-box", "shared/cornell-box", "shared/staircase2",
                                                   "shared/living-room"])
    ap.add_argument("--device", default=None)
    ap.add_argument("--width", type=int, default=8)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--tuned", action="append", default=[],
                    help="also packets on a BVH built with MIN,MAX,INTERSECTION_COST leaves "
                         "(repeatable; s:MIN,MAX,COST: the scalar loop)")
    a = ap.parse_args()
    tr = Tracer(a.device)
    from pyclpt.device.program import build_program

    progs = {v: build_program(tr.dev, source=KERNELS, name=f"bench_leaf_w{a.width}_{v}",
                              defines={"BVH_WIDTH": a.width, "BVH_LEAF_PACKETS": v}) for v in (0, 1)}
    print(f"# {cpu_model()}, {tr.dev.name}, width {a.width}, "
          f"{a.size}^2 rays, medians of {a.repeats}")
    print("| scene | variant | closest Mrays/s | vs scalar | any Mrays/s | vs scalar |")
    print("|---|---|---|---|---|---|")
    for name in a.scenes:
        scene = load_scene(name)
        if scene is None:
            continue
        pos, idx, bounds, p, bounce, shadow, smax, _ = make_rays(tr, scene, a.size, 1)
        bvh = build_bvh(pos, idx, settings=bvh_mod.BuildSettings(width=a.width))
        inf = np.full(len(p), np.inf, np.float32)
        variants = {"scalar": (0, bvh, bvh.nodes), "packets": (1, bvh, leaf_packet_buffer(bvh))}
        for spec in a.tuned:
            scalar = spec.startswith("s:")
            lo, hi, ic = spec.removeprefix("s:").split(",")
            b = build_bvh(pos, idx, settings=bvh_mod.BuildSettings(width=a.width, min_leaf=int(lo), max_leaf=int(hi),
                                                                   intersection_cost=float(ic)))
            variants[f"{'scalar' if scalar else 'packets'} {lo}-{hi} {ic} ({b.node_count} nodes)"] = \
                (0, b, b.nodes) if scalar else (1, b, leaf_packet_buffer(b))
        sets = {k: (tr.kernels(progs[v], nb, b.tris, p, bounce, inf), tr.kernels(progs[v], nb, b.tris, p, shadow, smax))
                for k, (v, b, nb) in variants.items()}
        for k in variants:
            tr.time(sets[k][0], "closest")
            tr.time(sets[k][1], "any")
        (t0, p0, _), (t1, p1, _) = tr.results(sets["scalar"][0]), tr.results(sets["packets"][0])
        a0, a1 = tr.results(sets["scalar"][1])[2], tr.results(sets["packets"][1])[2]
        bad = (np.count_nonzero(t0.view(np.int32) != t1.view(np.int32)), np.count_nonzero(p0 != p1),
               np.count_nonzero(a0 != a1))
        print(f"  {name}: {bvh.node_count} nodes; packets vs scalar differ in t {bad[0]}, prim {bad[1]}, "
              f"any {bad[2]} of {len(p)} rays")
        times = {(k, q): [] for k in variants for q in ("closest", "any")}
        for _ in range(a.repeats):
            for k in variants:
                times[k, "closest"].append(tr.time(sets[k][0], "closest"))
                times[k, "any"].append(tr.time(sets[k][1], "any"))
        m = {k: len(p) / float(np.median(x)) / 1e6 for k, x in times.items()}
        for k in variants:
            print(f"| {name} | {k} | {m[k, 'closest']:.2f} | {m[k, 'closest'] / m['scalar', 'closest']:.2f} "
                  f"| {m[k, 'any']:.2f} | {m[k, 'any'] / m['scalar', 'any']:.2f} |", flush=True)

if __name__ == "__main__":
    main()
