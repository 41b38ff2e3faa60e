"""Distributed rendering on this machine (pyclpt.distributed on a dask LocalCluster): the speed-up of 2
workers over 1 with each worker held to one core (PoCL's POCL_MAX_PTHREAD_COUNT=1), the cost of a
2-worker cluster of whole-machine workers (and of one) over a plain local render of the same spp, the fixed
cost per task (a sweep of task sizes on the one-core clusters, fitted as time = a + b * tasks), from which the
task size that keeps that cost under 5 % follows; and the largest relative difference of the merged
image from the local one (double means). Medians of --repeats; every worker has loaded the
scene (and compiled) before the timings. docs/distributed.md quotes its output.

    python -m bench.cluster.speedup [--scene /work/shared/scenes/living-room/scene.xml] [--width 128]
        [--height 72] [--spp 256] [--repeats 3] [--sweep 256,64,16,4] [--whole-sweep 128,32,8] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from bench.report.machine import cpu_model, load_average

ONE_CORE = {"POCL_MAX_PTHREAD_COUNT": "1"}


def _warm(source, settings) -> str:
    """On a worker: load the scene and compile (one sample), so the timings count rendering only."""
    from pyclpt.distributed.worker import renderer_for

    r = renderer_for(source, settings)
    r.render(1)
    return r.device.name


def _cpu_seconds() -> float:
    """This process's CPU time (user + system), children excluded."""
    t = os.times()
    return t.user + t.system


def _timed(dr, spp: int, task_spp: int | None, repeats: int) -> dict:
    """Medians over ``repeats`` renders: wall time, time inside the tasks (all workers together), CPU time
    of the workers and of this process (the client and, in a LocalCluster, the scheduler)."""
    times, busy, workers_cpu, client_cpu = [], [], [], []
    for _ in range(repeats):
        w0, c0 = dr.client.run(_cpu_seconds), _cpu_seconds()
        t0 = time.perf_counter()
        dr.render(spp, 0, task_spp=task_spp)
        times.append(time.perf_counter() - t0)
        c1, w1 = _cpu_seconds(), dr.client.run(_cpu_seconds)
        busy.append(sum(p.seconds for p in dr.parts))
        workers_cpu.append(sum(w1[k] - w0[k] for k in w0 if k in w1))
        client_cpu.append(c1 - c0)
    return {"median_s": statistics.median(times), "times_s": [round(t, 3) for t in times],
            "tasks": len(dr.parts), "busy_s": round(statistics.median(busy), 3),
            "workers_cpu_s": round(statistics.median(workers_cpu), 3),
            "client_scheduler_cpu_s": round(statistics.median(client_cpu), 3)}


def _cluster_runs(scene: str, size: dict, workers: int, env: dict | None, spp: int, repeats: int,
                  task_spp: int | None, sweep: list[int] = (), reference: np.ndarray | None = None) -> dict:
    from distributed import Client

    from pyclpt.distributed import DistributedRenderer, local_cluster

    with local_cluster(workers, env=env) as cluster, Client(cluster) as client:
        client.wait_for_workers(workers)
        dr = DistributedRenderer(client, scene, **size)
        devices = client.run(_warm, dr.source, dr.settings)
        out = {"workers": workers, "env": env or {}, "device": sorted(set(devices.values())),
               "render": _timed(dr, spp, task_spp, repeats)}
        if reference is not None:  # the merged mean against one machine's double mean (docs: <= 1e-12)
            mean = dr.render_sum(spp, 0, task_spp=task_spp) / spp
            rel = np.abs(mean - reference) / np.maximum(np.abs(reference), np.finfo(np.float64).tiny)
            out["max_relative_difference"] = float(rel.max())
        rows = [{"task_spp": ts, **_timed(dr, spp, ts, max(1, repeats - 1))} for ts in sweep]
        if rows:
            tasks = np.array([r["tasks"] for r in rows], float)
            secs = np.array([r["median_s"] for r in rows])
            per_task, base = np.polyfit(tasks, secs, 1)  # time = base + per_task * tasks
            out["sweep"] = rows
            out["per_task_s"] = float(per_task)
            out["per_sample_s"] = float(base / spp)
    return out


def _local_runs(scene: str, size: dict, spp: int, repeats: int) -> dict:
    import pyclpt

    r = pyclpt.Renderer(pyclpt.load(scene), **size)
    r.render(1)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        r.render(spp, 0)
        times.append(time.perf_counter() - t0)
    return {"median_s": statistics.median(times), "times_s": [round(t, 3) for t in times], "device": r.device.name,
            "mean": r.film.accumulator.image(np.float64)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="/work/shared/scenes/living-room/scene.xml")
    ap.add_argument("--width", type=int, default=128)
    ap.add_argument("--height", type=int, default=72)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sweep", default="256,64,16,4", help="task sizes (spp) of the per-task cost fit")
    ap.add_argument("--whole-sweep", default="", help="task sizes (spp) of a per-task cost fit on the 2-worker "
                                                      "cluster of whole-machine workers (none by default)")
    ap.add_argument("--json", default=None, help="write the results here")
    a = ap.parse_args()
    size = {"width": a.width, "height": a.height}
    sweep = [int(x) for x in a.sweep.split(",") if x]
    res = {"command": " ".join(["python -m bench.cluster.speedup", *sys.argv[1:]]), "cpu": cpu_model(),
           "load_average_before": load_average(), "scene": a.scene, "size": size, "spp": a.spp}
    # one core a worker: 1 -> 2 workers (default task size: about 4 tasks a worker), and the task-size sweep
    one = _cluster_runs(a.scene, size, 1, ONE_CORE, a.spp, a.repeats, None, sweep)
    two = _cluster_runs(a.scene, size, 2, ONE_CORE, a.spp, a.repeats, None, sweep)
    res["one_core_workers"] = {"1": one, "2": two, "speedup": one["render"]["median_s"] / two["render"]["median_s"]}
    # whole-machine workers against a plain local render
    local = _local_runs(a.scene, size, a.spp, a.repeats)
    whole1 = _cluster_runs(a.scene, size, 1, None, a.spp, a.repeats, None)
    whole_sweep = [int(x) for x in a.whole_sweep.split(",") if x]
    whole = _cluster_runs(a.scene, size, 2, None, a.spp, a.repeats, None, whole_sweep, reference=local.pop("mean"))
    res["whole_machine"] = {"local": local, "cluster1": whole1, "cluster2": whole,
                            "overhead_1_worker": whole1["render"]["median_s"] / local["median_s"] - 1,
                            "overhead": whole["render"]["median_s"] / local["median_s"] - 1}
    # a task of n samples pays per_task once: under 5 % when per_task <= 0.05 * n * per_sample (wall times
    # of the cluster); the larger of the two one-core clusters' answers
    need = [int(np.ceil(max(c["per_task_s"], 0) / (0.05 * c["per_sample_s"]))) for c in (one, two) if "per_task_s" in c]
    if need:
        res["task_spp_for_5_percent"] = max(need)
    res["load_average_after"] = load_average()
    text = json.dumps(res, indent=1)
    print(text)
    if a.json:
        Path(a.json).write_text(text + "\n")


if __name__ == "__main__":
    main()
