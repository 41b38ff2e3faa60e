"""Tiles on a cluster (pyclpt.distributed, ``tile=``): the render time of an image split into tiles of a
few sizes (one task a tile, all its samples) against the same image split into sample ranges of the whole
image, on a LocalCluster of 2 one-core workers (PoCL's POCL_MAX_PTHREAD_COUNT=1); the bytes each task
sends back, and that the tiled image equals the untiled one bit for bit. Medians of --repeats; every
worker has loaded the scene and compiled (whole image and tiles) before the timings. docs/distributed.md
quotes its output.

    python -m bench.cluster.tiles [--scene /work/shared/scenes/living-room/scene.xml] [--width 512]
        [--height 288] [--spp 16] [--tiles 256,128,64] [--repeats 3] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np

from bench.cluster.speedup import ONE_CORE
from bench.report.machine import cpu_model, load_average


def _time(dr, spp: int, tile, task_spp: int | None, repeats: int) -> tuple[dict, np.ndarray]:
    dr.render_sum(1, 0, tile=tile, task_spp=1)  # every worker builds its tile renderers (and compiles)
    dr.render_sum(1, 0, tile=tile, task_spp=1)
    times, total = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        total = dr.render_sum(spp, 0, tile=tile, task_spp=task_spp)
        times.append(time.perf_counter() - t0)
    per_task = max(24 * p.crop.width * p.crop.height if p.crop else 24 * total.shape[0] * total.shape[1]
                   for p in dr.parts)
    return {"tile": tile, "tasks": len(dr.parts), "median_s": statistics.median(times),
            "times_s": [round(t, 3) for t in times], "bytes_per_task": per_task}, total


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="/work/shared/scenes/living-room/scene.xml")
    ap.add_argument("--width", type=int, default=512)
    ap.add_argument("--height", type=int, default=288)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--tiles", default="256,128,64")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", default=None)
    a = ap.parse_args()

    from distributed import Client

    from pyclpt.distributed import DistributedRenderer, local_cluster

    out = {"cpu": cpu_model(), "scene": a.scene, "size": f"{a.width}x{a.height}", "spp": a.spp, "runs": []}
    with local_cluster(2, env=ONE_CORE) as cluster, Client(cluster) as client:
        client.wait_for_workers(2)
        dr = DistributedRenderer(client, a.scene, width=a.width, height=a.height)
        out["load_before"] = load_average()
        whole, ref = _time(dr, a.spp, None, None, a.repeats)
        out["runs"].append(whole)
        print(f"whole image, {whole['tasks']} sample ranges: {whole['median_s']:.2f} s, "
              f"{whole['bytes_per_task'] / 2**20:.1f} MiB a task", flush=True)
        for side in (int(t) for t in a.tiles.split(",")):
            row, total = _time(dr, a.spp, side, a.spp, a.repeats)
            row["equal_to_whole"] = bool(np.array_equal(total, ref))
            row["relative_to_whole"] = row["median_s"] / whole["median_s"]
            out["runs"].append(row)
            print(f"tiles of {side}: {row['tasks']} tasks, {row['median_s']:.2f} s "
                  f"({row['relative_to_whole']:.3f}x the whole image's), {row['bytes_per_task'] / 2**20:.2f} MiB "
                  f"a task at most, bit-identical: {row['equal_to_whole']}", flush=True)
        out["load_after"] = load_average()
    print(f"CPU: {out['cpu']}")
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
