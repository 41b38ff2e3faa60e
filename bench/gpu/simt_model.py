"""A SIMT model of the streaming paper's claim: predicted GPU time ratios of the wavefront (SoA, AoS) and the
megakernel, from the paths pyclpt's instrumented megakernel traces (pyclpt/gpu/simt.py; docs/gpu.md).

    python -m bench.gpu.simt_model [--scenes classroom living-room staircase staircase2 cornell-box builtin:cornell-box]
                               [--size 320x180] [--spp 1] [--depths 3 64] [--sweep living-room]
                               [--json docs/benchmarks/simt.json]

Each scene is traced once at the deepest depth (1 spp of a --size image on this machine's OpenCL device,
CPU is fine) and every shallower depth is that trace cut short (the same paths: random numbers are keyed
by bounce). The traced paths stand for the paper's 1280x720 frame (--target): work, traffic and warp
counts scale with the path count, which is how a 320x180 trace predicts a 1280x720 frame. Prints the
predicted speed-ups beside the paper's Table 1 (depth 3) and Fig. 6 (depth 64), the lane utilisations,
a depth sweep (Fig. 7 analog) and the model's sensitivity to its constants; writes everything to --json.
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict
from pathlib import Path

import pyclpt
from bench.report.machine import git_revision
from pyclpt.gpu.simt import REGISTERS, CostModel, Gpu, simulate, trace_paths
from pyclpt.scene.library import scenes_root

SCENES = ["classroom", "living-room", "staircase", "staircase2", "cornell-box", "builtin:cornell-box"]
# The paper's Table 1 (RTX 3090, max depth 3, 1 spp): FPS of megakernel, wavefront (AoS), wavefront SoA.
PAPER_TABLE1 = {"classroom": (9, 30, 33), "living-room": (8, 24, 26), "staircase": (25, 60, 85),
                "staircase2": (20, 59, 90)}
# Fig. 6 (max depth 64, 1024 spp), given in the text only as ranges over its 11 scenes.
PAPER_FIG6 = {"soa_vs_megakernel": (5.8, 8.6), "soa_vs_aos": (1.5, 3.5)}
# The wavefront variants predicted (pyclpt.gpu.simt.wavefront_work's options).
VARIANTS = {
    "soa": {"layout": "soa"},                                   # pyclpt's code as written, no tail
    "aos": {"layout": "aos"},
    "soa_tail": {"layout": "soa", "tail": 0.25},                # ... with pyclpt's default tail (1/4 wave)
    "soa_scan": {"layout": "soa", "compaction": "scan"},        # a GPU's one-launch scan compaction
    "aos_scan": {"layout": "aos", "compaction": "scan"},
    "soa_scan_queue": {"layout": "soa", "compaction": "scan", "indexing": "queue"},  # state moved with the queue
    # pyclpt as a GPU runs it: the GPU class's work-group compaction and the tail (readback schedule)
    "soa_gpu": {"layout": "soa", "compaction": "group", "tail": 0.25},
    "aos_gpu": {"layout": "aos", "compaction": "group", "tail": 0.25},
    "soa_gpu_pipelined": {"layout": "soa", "compaction": "group", "tail": 0.25, "schedule": "pipelined"},
}
# A design ahead of the code, at the deepest depth and warps of 32 only (the paper's Fig. 6 renders 1,024 spp):
# the wavefront regenerating paths into a pool of a GPU wave's slots (pyclpt.gpu.simt.regenerating_work), priced
# per path in a render of many samples per pixel.
REGENERATION = {
    "soa_regen": {"layout": "soa", "regenerate": 0.25, "passes": 4},
    "aos_regen": {"layout": "aos", "regenerate": 0.25, "passes": 4},
}
SENSITIVITY = {  # name: (CostModel changes, Gpu changes)
    "default": ({}, {}),
    "hide@16 warps": ({"warps_to_hide": 16}, {}),
    "hide@64 warps": ({"warps_to_hide": 64}, {}),
    "32-byte sectors": ({}, {"line_bytes": 32}),
    "traversal x2": ({"node": 360, "prim": 60}, {}),
    "shading x2": ({"surface": 180, "nee": 560, "sample": 620, "material_eval": 160, "material_sample": 200}, {}),
    "no launch cost": ({"launch_us": 0.0, "readback_us": 0.0}, {}),
    "unlimited bandwidth": ({}, {"bandwidth_gbs": 1e9}),
}


def scene_of(name: str):
    if name.startswith("builtin:"):
        return pyclpt.load(name.split(":", 1)[1])
    root = scenes_root()
    if root is None or not (root / name / "scene.xml").is_file():
        return None
    return pyclpt.load(str(root / name / "scene.xml"))


def _r(x: float, n: int = 2) -> float:
    return round(float(x), n)


def speedups(p) -> dict[str, float]:
    """megakernel time / variant time (above 1: the variant is faster), and SoA over AoS."""
    mk = p.times_ms["megakernel"]
    out = {k: _r(mk / v) for k, v in p.times_ms.items() if k != "megakernel"}
    if "soa" in p.times_ms and "aos" in p.times_ms:
        out["soa_vs_aos"] = _r(p.times_ms["aos"] / p.times_ms["soa"])
    if "soa_scan" in p.times_ms and "aos_scan" in p.times_ms:
        out["soa_scan_vs_aos_scan"] = _r(p.times_ms["aos_scan"] / p.times_ms["soa_scan"])
    if "soa_gpu" in p.times_ms and "aos_gpu" in p.times_ms:
        out["soa_gpu_vs_aos_gpu"] = _r(p.times_ms["aos_gpu"] / p.times_ms["soa_gpu"])
    if "soa_regen" in p.times_ms and "aos_regen" in p.times_ms:
        out["soa_regen_vs_aos_regen"] = _r(p.times_ms["aos_regen"] / p.times_ms["soa_regen"])
    return out


def isa_registers(isa: dict | None, scene: str) -> dict[str, int]:
    """sm_90 registers per kernel for ``scene`` from a gpu-isa report: the scene's own variant where the report
    names the scene (without the G-buffer if it has one; a variant shared by several scenes is named after the
    first), else the most registers over the report; :data:`REGISTERS` without a report. A kernel built under the
    driver's register cap that spills there (the megakernel, finish_paths) counts with its uncapped registers: the
    model has no cost for spills, and would credit the cap's occupancy without its local-memory traffic."""
    regs = dict(REGISTERS)
    if isa is None:
        return regs

    def used(c: dict) -> int:
        spills = c.get("spill_stores", 0) or c.get("spill_loads", 0)
        return c.get("uncapped_registers") or c["registers"] if spills else c["registers"]

    costs = [c for c in isa["costs"] if c["target"] == "sm_90" and c["kernel"] in regs]
    for c in sorted(costs, key=used):  # the worst last
        regs[c["kernel"]] = used(c)
    own = sorted((c for c in costs if scene in c.get("scenes", ())), key=lambda c: "-DAOVS=1" not in c["options"])
    for c in own:  # the scene's variant without the G-buffer last: it wins
        regs[c["kernel"]] = used(c)
    return regs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=SCENES, help="shared folder names or builtin:NAME")
    ap.add_argument("--size", default="320x180", help="traced resolution WxH")
    ap.add_argument("--target", default="1280x720", help="the frame the traced paths stand for")
    ap.add_argument("--spp", type=int, default=1)
    ap.add_argument("--depths", type=int, nargs="+", default=[3, 64])
    ap.add_argument("--sweep", nargs="*", default=["living-room"], help="scenes of the depth sweep (Fig. 7)")
    ap.add_argument("--sweep-depths", type=int, nargs="+", default=[1, 2, 3, 4, 8, 16, 32, 64])
    ap.add_argument("--device", default=None)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-sensitivity", action="store_true")
    ap.add_argument("--json", default="docs/benchmarks/simt.json")
    ap.add_argument("--isa", default=None, metavar="ISA_JSON",
                    help="registers per kernel and scene from a `pyclpt gpu-isa` report (isa.json; sm_90, "
                         "without the G-buffer) instead of the defaults (REGISTERS)")
    a = ap.parse_args()
    isa = json.loads(Path(a.isa).read_text()) if a.isa else None
    w, h = (int(v) for v in a.size.lower().split("x"))
    tw, th = (int(v) for v in a.target.lower().split("x"))
    deepest = max(a.depths + (a.sweep_depths if a.sweep else []))
    gpu, cost = Gpu(), CostModel()
    out = {"settings": {"size": [w, h], "target": [tw, th], "spp": a.spp, "depths": a.depths, "seed": a.seed,
                        "traced_depth": deepest, "gpu": asdict(gpu), "cost": asdict(cost), "registers": REGISTERS,
                        "occupancy": gpu.occupancy(), "variants": VARIANTS, "regeneration": REGENERATION,
                        "git": git_revision()},
           "paper": {"table1_fps": PAPER_TABLE1, "fig6": PAPER_FIG6}, "scenes": {}, "skipped": {}}
    t_all = time.perf_counter()
    rows = []
    for name in a.scenes:
        scene = scene_of(name)
        if scene is None:
            out["skipped"][name] = "not in the shared scene folder ($PYCLPT_SCENES)"
            print(f"# {name}: skipped (not in the shared scene folder)")
            continue
        t0 = time.perf_counter()
        trace = trace_paths(scene, spp=a.spp, max_depth=deepest, width=w, height=h, seed=a.seed, device=a.device)
        t_trace = time.perf_counter() - t0
        target = tw * th * a.spp
        entry = {"triangles": scene.triangle_count, "trace_seconds": _r(t_trace, 1),
                 "alive": [int(x) for x in trace.alive_counts()], "depths": {}}
        for d in a.depths:
            tr = trace.truncated(d)
            res = {}
            regs = isa_registers(isa, scene.name)
            entry["registers"] = regs
            for width in (32, 64):
                variants = {**VARIANTS, **REGENERATION} if width == 32 and d == max(a.depths) else VARIANTS
                p = simulate(tr, width=width, target_slots=target, wavefronts=variants, occupancy=gpu.occupancy(regs))
                res[f"width{width}"] = {
                    "times_ms": {k: _r(v, 3) for k, v in p.times_ms.items()}, "speedups": speedups(p),
                    "utilisation": {k: {s: _r(u, 3) for s, u in v.items()} for k, v in p.utilisation.items()},
                    "megakernel_per_bounce": p.per_bounce["megakernel"],
                    "kernels": {k: {s: {m: _r(x, 1) for m, x in v2.items()} for s, v2 in v.items()}
                                for k, v in p.kernels.items()},
                    "lines": {k: {s: int(x) for s, x in v.items()} for k, v in p.lines.items()}}
            if not a.no_sensitivity:
                sens = {}
                for label, (cchg, gchg) in SENSITIVITY.items():
                    changed = Gpu(**gchg)
                    p = simulate(tr, target_slots=target, cost=CostModel(**cchg), gpu=changed,
                                 occupancy=changed.occupancy(regs),
                                 wavefronts={k: VARIANTS[k] for k in ("soa", "aos", "soa_scan", "aos_scan", "soa_gpu",
                                                                      "aos_gpu")})
                    sens[label] = speedups(p)
                res["sensitivity"] = sens
            entry["depths"][str(d)] = res
            rows.append((name, d, res))
        if name in (a.sweep or []):
            sweep = {}
            for d in a.sweep_depths:
                p = simulate(trace.truncated(d), target_slots=target, wavefronts=VARIANTS)
                sweep[str(d)] = {"times_ms": {k: _r(v, 3) for k, v in p.times_ms.items()}, "speedups": speedups(p)}
            entry["sweep"] = sweep
        out["scenes"][name] = entry
        print(f"# {name}: {scene.triangle_count} triangles, traced in {t_trace:.1f} s, alive per bounce "
              f"{entry['alive'][:8]}...", flush=True)
    out["seconds"] = _r(time.perf_counter() - t_all, 1)
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps(out, indent=1) + "\n")
    print_tables(out, rows)


def print_tables(out: dict, rows: list) -> None:
    print("\nPredicted speed-up over the megakernel (megakernel time / wavefront time; warps of 32), beside the "
          "paper's (Table 1 at depth 3: FPS ratios; Fig. 6 at depth 64: 5.8-8.6x SoA, over its 11 scenes)\n")
    print("| scene | depth | paper AoS | paper SoA | AoS | SoA | SoA + tail | AoS, scan | SoA, scan | SoA, scan, "
          "queue-indexed | SoA/AoS (scan) | GPU build: SoA | GPU build: AoS | GPU build: SoA, pipelined | "
          "regeneration, many spp: SoA | regeneration: AoS | megakernel lane util. |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, d, res in rows:
        s = res["width32"]["speedups"]
        paper = out["paper"]["table1_fps"].get(name)
        if d == 3 and paper:
            pa, ps = f"{paper[1] / paper[0]:.2f}", f"{paper[2] / paper[0]:.2f}"
        elif d == 64:
            pa, ps = "", "5.8-8.6"
        else:
            pa = ps = ""
        u = res["width32"]["utilisation"]["megakernel"]["megakernel"]
        print(f"| {name} | {d} | {pa} | {ps} | {s['aos']} | {s['soa']} | {s['soa_tail']} | {s['aos_scan']} | "
              f"{s['soa_scan']} | {s['soa_scan_queue']} | {s['soa_scan_vs_aos_scan']} | {s['soa_gpu']} | "
              f"{s['aos_gpu']} | {s['soa_gpu_pipelined']} | {s.get('soa_regen', '')} | {s.get('aos_regen', '')} | "
              f"{u:.2f} |")
    print("\nLane utilisation per kernel (warps of 32 / wavefronts of 64), SoA, pyclpt's compaction\n")
    stages = ["intersect", "miss", "process_hit", "shadow_test", "light_contribution", "sample_bsdf"]
    print("| scene | depth | megakernel | " + " | ".join(stages) + " |")
    print("|---|---|---|" + "---|" * len(stages))
    for name, d, res in rows:
        cells = []
        for k in ["megakernel"] + stages:
            src = "megakernel" if k == "megakernel" else "soa"
            u32 = res["width32"]["utilisation"][src].get(k)
            u64 = res["width64"]["utilisation"][src].get(k)
            cells.append("" if u32 is None else f"{u32:.2f} / {u64:.2f}")
        print(f"| {name} | {d} | " + " | ".join(cells) + " |")
    for name, entry in out["scenes"].items():
        if "sweep" in entry:
            print(f"\nDepth sweep (Fig. 7 analog), {name}: predicted speed-up over the megakernel\n")
            print("| depth | megakernel ms | SoA | AoS | SoA, scan | AoS, scan | SoA + tail | GPU build: SoA |")
            print("|---|---|---|---|---|---|---|---|")
            for d, v in entry["sweep"].items():
                s = v["speedups"]
                print(f"| {d} | {v['times_ms']['megakernel']} | {s['soa']} | {s['aos']} | {s['soa_scan']} | "
                      f"{s['aos_scan']} | {s['soa_tail']} | {s['soa_gpu']} |")
    sens_rows = [(n, d, r["sensitivity"]) for n, d, r in rows if "sensitivity" in r]
    if sens_rows:
        labels = list(sens_rows[0][2])
        for key, what in (("soa_gpu", "the GPU build's SoA (work-group compaction, tail)"),
                          ("soa_scan", "SoA with the scan compaction")):
            print(f"\nSensitivity: {what}, speed-up over the megakernel under each change\n")
            print("| scene | depth | " + " | ".join(labels) + " |")
            print("|---|---|" + "---|" * len(labels))
            for n, d, s in sens_rows:
                print(f"| {n} | {d} | " + " | ".join(str(s[k][key]) for k in labels) + " |")


if __name__ == "__main__":
    main()
