"""What does each accumulation precision cost? Against ``single`` at 1920x1080 on PoCL: compensated 1.97x,
double 1.19x in fp64, 3.47x emulated (docs/accumulation.md, "Cost, measured").

Cost per frame of each accumulation precision, relative to ``single``.

    python -m bench.studies.accumulation [--width 1920] [--height 1080] [--channels 3] [--repeats 15]
                                 [--batch 8] [--device pocl] [--json out.json]

One frame = one launch of the accumulate kernel over every pixel (``Accumulator.add``). The
time is the kernel's OpenCL profiling event (device time, no transfer: the frame is already on
the device, as the integrators leave it). Settings are measured round-robin, ``--repeats`` times
each after two warm-up frames, so that a slow moment of a shared machine hits them all alike;
the table gives the median, min and max, and the median relative to ``single``'s.

Besides the three precisions (and the emulated double-float sum that replaces ``double``
without fp64), it measures: EMA past max_frame_count, the Kahan step with its other guards (an experiment: the
program is rebuilt with -DKAHAN_GUARD=2, volatile temporaries, or 0, no guard), work-group shapes,
and ``add_batch`` of ``--batch`` frames per launch (time per frame). The first rows use the
accumulator's default work-group shape for the device (``default_local_size``).
"""
from __future__ import annotations

import argparse
import json
import statistics

import numpy as np
import pyopencl as cl

import pyclpt
from pyclpt.device.program import build_program
from pyclpt.film.accumulator import IMPLEMENTATIONS, Accumulator


def settings(batch: int) -> list[dict]:
    s = [
        {"name": "single", "precision": "single"},
        {"name": "compensated", "precision": "compensated"},
        {"name": "double", "precision": "double"},
        {"name": "double-float (emulated)", "precision": "double", "force_emulated_double": True},
        {"name": "single, EMA", "precision": "single", "max_frame_count": 1, "overflow": "ema"},
        {"name": "compensated, EMA", "precision": "compensated", "max_frame_count": 1, "overflow": "ema"},
        {"name": "double, EMA", "precision": "double", "max_frame_count": 1, "overflow": "ema"},
        {"name": "compensated, volatile guard", "precision": "compensated", "kahan_guard": 2},
        {"name": "compensated, no guard", "precision": "compensated", "kahan_guard": 0},
    ]
    for shape in ((16, 16), (8, 8), (32, 8), (64, 4), (128, 2), (256, 1), (512, 1)):
        s.append({"name": f"single, {shape[0]}x{shape[1]} groups", "precision": "single", "local_size": shape})
        s.append({"name": f"double, {shape[0]}x{shape[1]} groups", "precision": "double", "local_size": shape})
    for p in ("single", "compensated", "double"):
        s.append({"name": f"{p}, batch of {batch}", "precision": p, "batch": batch})
    return s


def make(dev, w: int, h: int, channels: int, cfg: dict) -> Accumulator:
    opts = {k: v for k, v in cfg.items() if k not in ("name", "kahan_guard", "batch")}
    acc = Accumulator(dev, w, h, channels=channels, **opts)
    if "kahan_guard" in cfg:
        defines = {"ACC_PRECISION": IMPLEMENTATIONS[acc.implementation], "ACC_INPUT": 0, "ACC_CHANNELS": channels,
                   "ACC_LOCAL_X": acc.local_size[0], "ACC_LOCAL_Y": acc.local_size[1],
                   "KAHAN_GUARD": cfg["kahan_guard"]}
        prog = build_program(dev, ["film/accumulate.cl"], defines=defines)
        acc._batch_kernel = cl.Kernel(prog, "accumulate_batch")
        acc._frame_kernel = cl.Kernel(prog, "accumulate_frame")
    acc.warm_up()
    return acc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1080)
    ap.add_argument("--channels", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--device", default=None)
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    dev = pyclpt.get_device(a.device)
    w, h, c = a.width, a.height, a.channels
    rng = np.random.default_rng(0)
    frames = (rng.random((a.batch, h, w, c), dtype=np.float32) * np.float32(2.0)).astype(np.float32)
    buf = cl.Buffer(dev.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=frames)
    cfgs = settings(a.batch)
    accs = [make(dev, w, h, c, cfg) for cfg in cfgs]
    times: list[list[float]] = [[] for _ in cfgs]

    def one(i: int) -> float:
        n = cfgs[i].get("batch", 1)
        ev = accs[i].add_batch(buf, n)
        ev.wait()
        return (ev.profile.end - ev.profile.start) * 1e-6 / n

    for i in range(len(cfgs)):  # warm-up frames (EMA settings pass their limit here)
        one(i), one(i)
    for _ in range(a.repeats):
        for i in range(len(cfgs)):
            times[i].append(one(i))
    base = statistics.median(times[0])
    print(f"# accumulate, {w}x{h}x{c} float frames, {a.repeats} frames per setting (round-robin), "
          f"device time per frame, on {dev.name}")
    print("| setting | median ms | min | max | relative to single | state bytes/px |")
    print("|---|---|---|---|---|---|")
    rows = []
    for cfg, acc, t in zip(cfgs, accs, times):
        med = statistics.median(t)
        row = {"setting": cfg["name"], "median_ms": med, "min_ms": min(t), "max_ms": max(t),
               "relative": med / base, "state_bytes_per_pixel": acc.state_bytes // acc.pixels,
               "implementation": acc.implementation, "local_size": list(acc.local_size)}
        rows.append(row)
        print(f"| {cfg['name']} | {med:.2f} | {min(t):.2f} | {max(t):.2f} | {med / base:.2f} | "
              f"{row['state_bytes_per_pixel']} |")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"device": dev.name, "width": w, "height": h, "channels": c, "repeats": a.repeats,
                       "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
