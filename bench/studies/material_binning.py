"""Does binning hit paths by material kind pay? No: at most 1.2-1.3x on two stages of the living room, 0.88-1.07x
on cornell-bunny, before binning's own cost (docs/wavefront.md, "Binning by material kind, measured").

Issue 11, item 2, asked for "paths binned or sorted by material kind into contiguous runs ... if measured to pay".

    python -m bench.studies.material_binning [--device intel] [--scene cornell-bunny] [--size 256] [--bounce 1]
                                             [--repeats 7]

Runs the wavefront SoA up to ``sample_bsdf`` of one bounce of one frame, snapshots the path state, then
times ``sample_bsdf`` and ``process_hit`` over the hit queue as the compaction left it (slot order) and
over the same entries reordered so that paths of one material kind form contiguous runs (a stable sort
by kind: within a kind the slots stay ascending), restoring the state before every launch. The kernels
are the same (a branch on the kind per path); what changes is how many kinds a SIMD group of
work-items (Intel's vectorizer: 8 or 16 lanes) meets. The reordering itself is not timed: it is the
upper bound of what binning could gain. Prints Mitems/s of each (median of ``--repeats``).
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np
import pyopencl as cl

import pyclpt
from bench.report.machine import cpu_model
from pyclpt.buffers.materials import MAT_TYPE, MAT_TYPES
from pyclpt.integrators.wavefront import Q_HIT, Q_LIGHT, Q_MISS, Q_RAY, Q_SHADOW

TRI_MAT_MASK = 0x00FFFFFF


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default=None)
    ap.add_argument("--scene", default="cornell-bunny")
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--bounce", type=int, default=1, help="the bounce whose hits are timed")
    ap.add_argument("--repeats", type=int, default=7)
    a = ap.parse_args(argv)
    r = pyclpt.Renderer(pyclpt.load(a.scene), integrator="wavefront", layout="soa", max_depth=a.bounce + 2,
                        width=a.size, height=a.size, device=a.device, tail_paths=0)
    w, q = r.integrator, r.device.queue
    w._scene_args = w.scene.args(w.film.width, w.film.height)
    n = w.film.pixels
    cl.enqueue_fill_buffer(q, w.counters, np.int32(0), 0, w._counts.nbytes)
    w.path_init(n, 1, 0, 0)
    for b in range(a.bounce + 1):
        rays = w._read_count(b, Q_RAY)
        w.intersect(rays, b, 1, 0)
        w.compact(rays, b, Q_RAY, w.ray_queues[b % 2], w.hit_queue, Q_HIT, rest=w.miss_queue, rest_q=Q_MISS)
        w.miss(rays, b)
        if b == a.bounce:
            break
        w.process_hit(rays, b, 1, 0)
        w.compact(rays, b, Q_HIT, w.hit_queue, w.shadow_queue, Q_SHADOW)
        w.shadow_test(rays, b, 1, 0)
        w.compact(rays, b, Q_SHADOW, w.shadow_queue, w.light_queue, Q_LIGHT)
        w.light_contribution(rays, b)
        w.sample_bsdf(rays, b, 1, 0)
        w.compact(rays, b, Q_HIT, w.hit_queue, w.ray_queues[(b + 1) % 2], Q_RAY, out_bounce=b + 1)
    b = a.bounce
    hits = w._read_count(b, Q_HIT)
    queue = np.empty(w.capacity, np.int32)
    cl.enqueue_copy(q, queue, w.hit_queue)
    queue = queue[:hits]
    prims = np.empty(w.capacity, np.int32)
    cl.enqueue_copy(q, prims, w.paths.component("hit_prim"))
    arrays = r.scene_buffers.arrays
    kinds = arrays.materials[arrays.tri_info[prims[queue], 0] & TRI_MAT_MASK, MAT_TYPE].astype(np.int32)
    order = np.argsort(kinds, kind="stable")
    binned = np.ascontiguousarray(queue[order])
    snapshot = [cl.Buffer(r.device.context, cl.mem_flags.READ_WRITE, b_.size) for b_ in w.paths.buffers]
    for src, dst in zip(w.paths.buffers, snapshot):
        cl.enqueue_copy(q, dst, src)
    q.finish()

    def timed(stage: str, entries: np.ndarray) -> float:
        cl.enqueue_copy(q, w.hit_queue, entries)
        times = []
        for _ in range(a.repeats):
            for src, dst in zip(snapshot, w.paths.buffers):
                cl.enqueue_copy(q, dst, src)
            q.finish()
            start = time.perf_counter()
            getattr(w, stage)(hits, b, 1, 0)
            q.finish()
            times.append(time.perf_counter() - start)
        return hits / statistics.median(times) / 1e6

    # runs: how often the kind changes between neighbouring entries
    changes = {"slot order": int(np.count_nonzero(np.diff(kinds))),
               "binned": int(np.count_nonzero(np.diff(kinds[order])))}
    inverse = {v: k for k, v in MAT_TYPES.items()}
    counts = {inverse[int(k)]: int(c) for k, c in zip(*np.unique(kinds, return_counts=True))}
    print(f"{r.device.name} on {cpu_model()}: {a.scene} {a.size}x{a.size}, bounce {b}: {hits} hits {counts}")
    print(f"  kind changes between neighbouring queue entries: {changes}")
    for stage in ("process_hit", "sample_bsdf"):
        plain, sorted_ = timed(stage, queue), timed(stage, binned)
        print(f"  {stage:12s} slot order {plain:7.1f} Mitems/s, binned {sorted_:7.1f} Mitems/s: "
              f"{sorted_ / plain:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
