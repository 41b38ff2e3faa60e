"""Which BVH node width, and does sorting rays pay? Width 8: 1.7-3x the binary BVH's traversal rate on the
large scenes, 1.1-1.8x whole renders; sorting does not: within 10% of pixel order (docs/bvh.md, "Measurements").

BVH node width and ray order: device traversal throughput and whole-render speed.

    python -m bench.studies.bvh_traversal                      # every table, the default scenes
    python -m bench.studies.bvh_traversal --scenes cornell-box,shared/living-room --repeats 7
    python -m bench.studies.bvh_traversal --no-render --no-order   # traversal table only

Scenes: the built-in ``cornell-box`` and the five scenes of the shared folder
(``$PYCLPT_SCENES``, default ``../shared/scenes``; missing ones are skipped).

Rays (incoherent, as a path tracer's bounces): one jittered camera ray per pixel
of a ``--size`` image is traced (binary BVH) to its first hit; from each hit
point, offset along the geometric normal, a cosine-distributed direction
("bounce", closest hit, tmax = inf) and a segment to a random point on a random
emitting triangle, area-weighted ("shadow", any hit, tmax = 0.999 of the
distance; a random direction with tmax = the scene's diagonal where no
triangle emits).

Tables:

1. traversal: Mrays/s of the closest-hit and any-hit kernels for each node
   width (2 = binary, 4, 8), rays in pixel order; every repeat runs every
   width in turn (alternating), the figure is the median over repeats of
   rays / wall time of the kernel (OpenCL profiling event);
2. order: the same kernels on the rays reordered on the host (pixel order,
   shuffled, sorted by direction octant, by the Morton code of the origin
   quantised to 2^10 cells a side in the scene bounds, by octant then
   Morton), for the default width and the fastest width; plus the numpy
   sort's own time per ray;
3. render: whole-render Msamples/s of the megakernel (``Renderer``,
   ``--render-size`` pixels square, ``--spp`` samples, max depth
   ``--depth``) for each width, alternating, median over ``--render-repeats``.

Every result is checked: each width returns the same hit triangle and t as the
binary BVH for every ray (a mismatch is printed).
"""
from __future__ import annotations

import argparse
import platform
import time

import numpy as np
import pyopencl as cl

import pyclpt
from bench.report.embree_ceiling import bounce_and_shadow_rays, camera_rays, scene_triangles
from bench.report.machine import cpu_model
from pyclpt.accel import bvh as bvh_mod
from pyclpt.accel.bvh import DEFAULT_SETTINGS, DEFAULT_WIDTH, build_bvh, leaf_packet_buffer
from pyclpt.buffers import scene as scene_mod
from pyclpt.scene.library import scenes_root

KERNELS = r"""
#include "scene/bvh.h"
__kernel SCALAR_KERNEL void closest(__global const float* nodes, __global const float* tris,
                      __global const float* org, __global const float* dir,
                      __global float* out_t, __global int* out_prim) {
    int i = get_global_id(0);
    Hit h;
    bool ok = bvh_closest(nodes, tris, load3(org, i), load3(dir, i), INFINITY, &h);
    out_t[i] = ok ? h.t : -1.0f;
    out_prim[i] = h.prim;
}
__kernel SCALAR_KERNEL void any_hit(__global const float* nodes, __global const float* tris,
                      __global const float* org, __global const float* dir,
                      __global const float* tmax, __global int* out_any) {
    int i = get_global_id(0);
    out_any[i] = bvh_any(nodes, tris, load3(org, i), load3(dir, i), tmax[i]) ? 1 : 0;
}
"""

DEFAULT_SCENES = ("cornell-box", "shared/cornell-box", "shared/staircase2", "shared/living-room",
                  "shared/staircase", "shared/classroom")
WIDTHS = bvh_mod.WIDTHS


def load_scene(name: str):
    if name.startswith("shared/"):
        root = scenes_root()
        path = None if root is None else root / name.removeprefix("shared/") / "scene.xml"
        if path is None or not path.is_file():
            return None
        return pyclpt.load(path)
    return pyclpt.load(name)


class Tracer:
    """The bench kernels compiled for every node width; traces one width's BVH."""

    def __init__(self, device: str | None = None, defines: dict | None = None) -> None:
        from pyclpt.device.context import get_device
        from pyclpt.device.program import build_program

        self.dev = get_device(device)
        self.ctx, self.queue = self.dev.context, self.dev.queue
        self.progs = {w: build_program(self.dev, source=KERNELS, name=f"bench_bvh_w{w}",
                                       defines={"BVH_WIDTH": w, "BVH_LEAF_PACKETS": self.packets(w), **(defines or {})})
                      for w in WIDTHS}

    @staticmethod
    def packets(width: int) -> bool:
        """Whether scenes of this width are traversed with leaf packets (as pyclpt.buffers.scene does)."""
        return scene_mod.LEAF_PACKETS and width == 8

    def buf(self, a: np.ndarray) -> cl.Buffer:
        return cl.Buffer(self.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                         hostbuf=np.ascontiguousarray(a))

    def setup(self, width: int, bvh, org, dirs, tmax) -> dict:
        """The kernels of this width (with leaf packets where the renderer uses them) on these rays."""
        nodes = leaf_packet_buffer(bvh) if self.packets(width) else bvh.nodes
        return self.kernels(self.progs[width], nodes, bvh.tris, org, dirs, tmax)

    def kernels(self, prog: cl.Program, nodes, tris, org, dirs, tmax) -> dict:
        """``prog``'s closest and any_hit kernels set up on these buffers and rays (for :meth:`time`)."""
        n = len(org)
        s = {"n": n, "nodes": self.buf(nodes), "tris": self.buf(tris), "org": self.buf(org),
             "dir": self.buf(dirs), "tmax": self.buf(tmax.astype(np.float32)),
             "t": cl.Buffer(self.ctx, cl.mem_flags.WRITE_ONLY, 4 * n),
             "p": cl.Buffer(self.ctx, cl.mem_flags.WRITE_ONLY, 4 * n),
             "a": cl.Buffer(self.ctx, cl.mem_flags.WRITE_ONLY, 4 * n)}
        kc = cl.Kernel(prog, "closest")
        ka = cl.Kernel(prog, "any_hit")
        kc.set_args(s["nodes"], s["tris"], s["org"], s["dir"], s["t"], s["p"])
        ka.set_args(s["nodes"], s["tris"], s["org"], s["dir"], s["tmax"], s["a"])
        s["kernels"] = {"closest": kc, "any": ka}
        return s

    def time(self, s: dict, which: str) -> float:
        ev = cl.enqueue_nd_range_kernel(self.queue, s["kernels"][which], (s["n"],), None)
        ev.wait()
        return (ev.profile.end - ev.profile.start) * 1e-9

    def results(self, s: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = s["n"]
        t, p, a = np.empty(n, np.float32), np.empty(n, np.int32), np.empty(n, np.int32)
        cl.enqueue_copy(self.queue, t, s["t"])
        cl.enqueue_copy(self.queue, p, s["p"])
        cl.enqueue_copy(self.queue, a, s["a"]).wait()
        return t, p, a


def make_rays(tracer: Tracer, scene, size: int, seed: int):
    """Bounce (closest hit) and shadow (any hit) rays from the first hits of camera rays."""
    rng = np.random.default_rng(seed)
    pos, idx, emissive = scene_triangles(scene)
    lo, hi = pos.min(0), pos.max(0)
    binary = build_bvh(pos, idx, settings=bvh_mod.BuildSettings(width=2))
    org, dirs = camera_rays(scene, size, size, rng)
    s = tracer.setup(2, binary, org, dirs, np.full(len(org), np.inf))
    tracer.time(s, "closest")
    t, prim, _ = tracer.results(s)
    hit = prim >= 0
    p = org[hit].astype(np.float64) + t[hit, None].astype(np.float64) * dirs[hit]
    tri = binary.tris[prim[hit]].astype(np.float64)
    p, bounce, shadow, smax = bounce_and_shadow_rays(p, np.cross(tri[:, 3:6], tri[:, 6:9]), dirs[hit], pos, idx,
                                                     emissive, rng)
    f32 = np.float32
    return (pos, idx, (lo, hi), p.astype(f32), bounce.astype(f32), shadow.astype(f32), smax.astype(f32),
            float(hit.mean()))


def morton30(org: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """30-bit Morton code of the origins quantised to 2^10 cells a side in [lo, hi]."""
    q = ((org - lo) / np.maximum(hi - lo, 1e-30) * 1024.0).astype(np.int64)
    q = np.clip(q, 0, 1023)

    def spread(x):
        x = (x | (x << 16)) & 0x030000FF
        x = (x | (x << 8)) & 0x0300F00F
        x = (x | (x << 4)) & 0x030C30C3
        x = (x | (x << 2)) & 0x09249249
        return x

    return spread(q[:, 0]) | (spread(q[:, 1]) << 1) | (spread(q[:, 2]) << 2)


def orders(org: np.ndarray, dirs: np.ndarray, bounds, rng) -> dict[str, tuple[np.ndarray, float]]:
    """Ray permutations and the host time to compute each (seconds)."""
    out = {"pixel": (np.arange(len(org)), 0.0), "shuffled": (rng.permutation(len(org)), 0.0)}
    t0 = time.perf_counter()
    octant = (dirs[:, 0] < 0).astype(np.int64) | (dirs[:, 1] < 0) << 1 | (dirs[:, 2] < 0) << 2
    out["octant"] = (np.argsort(octant, kind="stable"), time.perf_counter() - t0)
    t0 = time.perf_counter()
    m = morton30(org, *bounds)
    out["morton"] = (np.argsort(m, kind="stable"), time.perf_counter() - t0)
    t0 = time.perf_counter()
    octant = (dirs[:, 0] < 0).astype(np.int64) | (dirs[:, 1] < 0) << 1 | (dirs[:, 2] < 0) << 2
    out["octant+morton"] = (np.argsort(octant << 30 | morton30(org, *bounds), kind="stable"),
                            time.perf_counter() - t0)
    return out


def traversal(tracer: Tracer, label: str, bvhs: dict, p, bounce, shadow, smax, repeats: int,
              widths) -> dict:
    inf = np.full(len(p), np.inf, np.float32)
    sets = {w: (tracer.setup(w, bvhs[w], p, bounce, inf), tracer.setup(w, bvhs[w], p, shadow, smax))
            for w in widths}
    times = {(w, k): [] for w in widths for k in ("closest", "any")}
    for w in widths:  # warm-up (driver's lazy compile) and the exactness check
        tracer.time(sets[w][0], "closest")
        tracer.time(sets[w][1], "any")
    ref = None
    for w in widths:
        t, prim, _ = tracer.results(sets[w][0])
        _, _, anyhit = tracer.results(sets[w][1])
        tri = np.where(prim >= 0, bvhs[w].tri_order[np.maximum(prim, 0)], -1)
        if ref is None:
            ref = (t, tri, anyhit)
        else:
            # ties: another triangle at the same distance, or one within 2 ulp (coplanar
            # overlapping triangles, whose boxes' entry distance may round past the hit)
            near = np.abs(t - ref[0]) <= 2 * np.spacing(np.abs(ref[0]))
            bad_t = np.count_nonzero(~near)
            ties = np.count_nonzero(near & (tri != ref[1]))
            bad_any = np.count_nonzero(anyhit != ref[2])
            if bad_t or bad_any:
                print(f"  {label} width {w}: {bad_t} closest-hit t and {bad_any} any-hit results differ "
                      f"from width {widths[0]}")
            if ties:
                print(f"  {label} width {w}: {ties} ties (t within 2 ulp, another triangle)")
    for _ in range(repeats):
        for w in widths:
            times[w, "closest"].append(tracer.time(sets[w][0], "closest"))
            times[w, "any"].append(tracer.time(sets[w][1], "any"))
    return {k: len(p) / float(np.median(v)) / 1e6 for k, v in times.items()}


def render_speed(scene, widths, size: int, spp: int, depth: int, repeats: int) -> dict:
    from pyclpt.rendering.renderer import Renderer

    renderers = {}
    compile_s = {}
    for w in widths:
        bvh_mod.DEFAULT_SETTINGS = bvh_mod.BuildSettings(width=w)
        try:
            renderers[w] = Renderer(scene, width=size, height=size, max_depth=depth)
        finally:
            bvh_mod.DEFAULT_SETTINGS = DEFAULT_SETTINGS
        compile_s[w] = renderers[w].stats.compile_seconds
        renderers[w].render(1)
    times = {w: [] for w in widths}
    images = {}
    for _ in range(repeats):
        for w in widths:
            t0 = time.perf_counter()
            images[w] = renderers[w].render(spp, seed=1)
            times[w].append(time.perf_counter() - t0)
    same = all(np.array_equal(images[w], images[widths[0]]) for w in widths)
    return {w: size * size * spp / float(np.median(times[w])) / 1e6 for w in widths}, same, compile_s


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default=",".join(DEFAULT_SCENES))
    ap.add_argument("--size", type=int, default=512, help="camera rays: size x size (default 512)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--widths", default=",".join(map(str, WIDTHS)))
    ap.add_argument("--no-order", action="store_true", help="skip the ray-order table")
    ap.add_argument("--no-render", action="store_true", help="skip the whole-render table")
    ap.add_argument("--render-size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--depth", type=int, default=8)
    ap.add_argument("--render-repeats", type=int, default=5)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    widths = tuple(int(w) for w in a.widths.split(","))
    tracer = Tracer()
    print(f"CPU: {cpu_model()} ({platform.machine()}); device: {tracer.dev.device.name}")
    print(f"default width {DEFAULT_WIDTH}; {a.size}x{a.size} camera rays; medians of {a.repeats} "
          f"alternating repeats")
    trav_rows, order_rows, render_rows = [], [], []
    for name in a.scenes.split(","):
        scene = load_scene(name)
        if scene is None:
            print(f"{name}: not found, skipped")
            continue
        pos, idx, bounds, p, bounce, shadow, smax, hit = make_rays(tracer, scene, a.size, a.seed)
        bvhs = {w: build_bvh(pos, idx, settings=bvh_mod.BuildSettings(width=w)) for w in widths}
        r = traversal(tracer, name, bvhs, p, bounce, shadow, smax, a.repeats, widths)
        trav_rows.append((name, len(idx), len(p), {w: bvhs[w].node_count for w in widths}, r))
        print(f"{name}: {len(idx)} triangles, {len(p)} rays ({100 * hit:.0f}% of camera rays hit)", flush=True)
        for w in widths:
            print(f"  width {w}: {bvhs[w].node_count:7d} nodes  closest {r[w, 'closest']:6.2f}  "
                  f"any {r[w, 'any']:6.2f} Mrays/s", flush=True)
        if not a.no_order:
            rng = np.random.default_rng(a.seed)
            best = max(widths, key=lambda w: r[w, "closest"])
            ow = sorted({DEFAULT_WIDTH, best} & set(widths))
            rows = {}
            for oname, (perm, sort_s) in orders(p, bounce, bounds, rng).items():
                # the shadow rays are sorted by their own directions
                perm_s = orders(p, shadow, bounds, np.random.default_rng(a.seed))[oname][0]
                rb = traversal(tracer, f"{name} {oname}", {w: bvhs[w] for w in ow}, p[perm], bounce[perm],
                               shadow[perm_s], smax[perm_s], a.repeats, ow)
                rows[oname] = (rb, sort_s / len(p) * 1e9)
                print(f"  order {oname:14s} " + "  ".join(
                    f"w{w} closest {rb[w, 'closest']:6.2f} any {rb[w, 'any']:6.2f}" for w in ow)
                    + f"  sort {rows[oname][1]:5.0f} ns/ray", flush=True)
            order_rows.append((name, ow, rows))
        if not a.no_render:
            speed, same, compile_s = render_speed(scene, widths, a.render_size, a.spp, a.depth,
                                                  a.render_repeats)
            render_rows.append((name, speed, same))
            print("  render " + "  ".join(f"w{w} {speed[w]:.3f}" for w in widths)
                  + f" Msamples/s; images identical: {same}; compile s "
                  + " ".join(f"{compile_s[w]:.1f}" for w in widths), flush=True)

    print("\n## Traversal, Mrays/s (closest: bounce rays; any: shadow rays)\n")
    head = " | ".join(f"w{w} closest | w{w} any" for w in widths)
    print(f"| scene | triangles | rays | {head} | nodes (" + ", ".join(f"w{w}" for w in widths) + ") |")
    print("|---" * (4 + 2 * len(widths)) + "|")
    for name, tris, nr, nodes, r in trav_rows:
        cells = " | ".join(f"{r[w, 'closest']:.2f} | {r[w, 'any']:.2f}" for w in widths)
        print(f"| {name} | {tris} | {nr} | {cells} | " + ", ".join(str(nodes[w]) for w in widths) + " |")
    if order_rows:
        print("\n## Ray order, Mrays/s (closest / any) and host sort ns per ray\n")
        for name, ow, rows in order_rows:
            for oname, (rb, ns) in rows.items():
                cells = " | ".join(f"w{w} {rb[w, 'closest']:.2f} / {rb[w, 'any']:.2f}" for w in ow)
                print(f"| {name} | {oname} | {cells} | {ns:.0f} |")
    if render_rows:
        print(f"\n## Megakernel render, Msamples/s ({a.render_size}^2, {a.spp} spp, depth {a.depth}, "
              f"median of {a.render_repeats})\n")
        print("| scene | " + " | ".join(f"w{w}" for w in widths) + " | images identical |")
        print("|---" * (2 + len(widths)) + "|")
        for name, speed, same in render_rows:
            print(f"| {name} | " + " | ".join(f"{speed[w]:.3f}" for w in widths) + f" | {same} |")


if __name__ == "__main__":
    main()
