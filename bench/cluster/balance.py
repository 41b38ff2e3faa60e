"""A cluster of unequal workers (pyclpt.distributed): does the faster one take proportionally more sample
ranges? Two one-core workers on this machine that pick different OpenCL devices by ``PYCLPT_DEVICE``, as
a cluster mixing CPU and GPU nodes does: Intel's CPU runtime (one TBB thread) and PoCL (one pthread),
about 4x apart on the living room. Dask's scheduler hands a task to whichever worker has a free thread,
so a worker's share of the samples should follow its speed. For each task size: the samples and busy
seconds of each worker, its speed (samples per busy second), its share of the samples against its share
of the speed, and the wall time against the ideal (all samples / the sum of the speeds). Medians of
--repeats. docs/distributed.md quotes its output.

    python -m bench.cluster.balance [--scene /work/shared/scenes/living-room/scene.xml] [--width 128]
        [--height 72] [--spp 256] [--task-spp 32,16,8] [--repeats 3] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

from bench.cluster.speedup import _warm
from bench.report.machine import cpu_model, load_average

WORKERS = {  # name: the worker's environment
    "intel": {"PYCLPT_DEVICE": "intel", "CL_CONFIG_CPU_TBB_NUM_WORKERS": "1"},
    "pocl": {"PYCLPT_DEVICE": "pocl", "POCL_MAX_PTHREAD_COUNT": "1"},
}


def _cluster():
    from distributed import Nanny, Scheduler, SpecCluster

    return SpecCluster(scheduler={"cls": Scheduler, "options": {"dashboard_address": ":0"}},
                       workers={name: {"cls": Nanny, "options": {"nthreads": 1, "env": env, "name": name}}
                                for name, env in WORKERS.items()}, asynchronous=False)


def _run(dr, spp: int, task_spp: int, names: dict[str, str]) -> dict:
    t0 = time.perf_counter()
    dr.render(spp, 0, task_spp=task_spp)
    wall = time.perf_counter() - t0
    per = {n: {"samples": 0, "tasks": 0, "busy_s": 0.0} for n in names.values()}
    for p in dr.parts:
        w = per[names[p.worker]]
        w["samples"] += p.count
        w["tasks"] += 1
        w["busy_s"] += p.seconds
    return {"wall_s": wall, "workers": per}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="/work/shared/scenes/living-room/scene.xml")
    ap.add_argument("--width", type=int, default=128)
    ap.add_argument("--height", type=int, default=72)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--task-spp", default="32,16,8")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", default=None)
    a = ap.parse_args()

    from distributed import Client

    from pyclpt.distributed import DistributedRenderer

    out = {"cpu": cpu_model(), "scene": a.scene, "size": f"{a.width}x{a.height}", "spp": a.spp, "runs": []}
    with _cluster() as cluster, Client(cluster) as client:
        client.wait_for_workers(len(WORKERS))
        names = {addr: info["name"] for addr, info in client.scheduler_info()["workers"].items()}
        dr = DistributedRenderer(client, a.scene, width=a.width, height=a.height)
        devices = client.run(_warm, dr.source, dr.settings)
        out["devices"] = {names[k]: v for k, v in devices.items()}
        out["load_before"] = load_average()
        for task_spp in (int(t) for t in a.task_spp.split(",")):
            runs = [_run(dr, a.spp, task_spp, names) for _ in range(a.repeats)]
            speed = {}  # samples per busy second, over the repeats
            for n in WORKERS:
                busy = sum(r["workers"][n]["busy_s"] for r in runs)
                speed[n] = sum(r["workers"][n]["samples"] for r in runs) / max(busy, 1e-9)
            ideal = a.spp / sum(speed.values())
            row = {"task_spp": task_spp, "tasks": -(-a.spp // task_spp),
                   "wall_s": statistics.median(r["wall_s"] for r in runs), "ideal_s": ideal, "workers": {}}
            for n in WORKERS:
                samples = statistics.median(r["workers"][n]["samples"] for r in runs)
                row["workers"][n] = {"samples": samples, "share": samples / a.spp,
                                     "speed_share": speed[n] / sum(speed.values()),
                                     "samples_per_s": speed[n]}
            out["runs"].append(row)
            print(f"task_spp {task_spp:4d} ({row['tasks']} tasks): wall {row['wall_s']:.2f} s, ideal {ideal:.2f} s "
                  f"({row['wall_s'] / ideal:.2f}x); " + "; ".join(
                      f"{n}: {w['samples']:.0f} spp = {w['share']:.0%} of the samples, {w['speed_share']:.0%} of "
                      f"the speed ({w['samples_per_s']:.1f} spp/s)" for n, w in row["workers"].items()), flush=True)
        out["load_after"] = load_average()
    print(f"CPU: {out['cpu']}; devices: {out['devices']}")
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
