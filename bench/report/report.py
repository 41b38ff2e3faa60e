"""``pyclpt bench``: the streaming paper's tables and plots, measured on this OpenCL device.

    pyclpt bench [-o bench-report] [--quick] [--scenes builtin shared ...]
                 [--integrators megakernel wavefront] [--layouts aos soa]
                 [--depths 1 2 3 4 8 16 32 64] [--spp 16] [--resolution 512x512]
                 [--repeats 3] [--device pocl] ...
    pyclpt bench --from-json bench-report/results.json   # rewrite the report, no re-run
    pyclpt bench --versus mitsuba [...]                  # against Mitsuba 3 (bench/report/versus.py)

Runs every scene x method (megakernel, wavefront AoS, wavefront SoA) x max depth, then writes
a folder with ``report.md``, a self-contained ``report.html``, the raw results
(``results.json``, ``results.csv``) and the PNG plots. See docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import shlex
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from . import analysis as A
from .document import Bullets, Document, Heading, Image, Para, Table, to_html, to_markdown
from .document import number as _n
from .options import positive as _positive
from .options import resolution as _resolution

FORMAT = 1
DEFAULTS = {
    "scenes": ["builtin", "shared"],
    "integrators": ["megakernel", "wavefront"],
    "layouts": ["aos", "soa"],
    "depths": [1, 2, 3, 4, 8, 16, 32, 64],
    "table_depth": 3,
    "spp": 16,
    "spp_depth": 64,
    "resolution": "512x512",
    "repeats": 3,
    "warmup": 1,
    "embree_repeats": 3,
    "embree_rays": 1 << 18,
}
# --quick: the built-in scenes (and the 12-triangle real Cornell box when it loads), small images.
QUICK = {
    "scenes": ["cornell-box", "cornell-bunny", "cornell-dragon", "shared/cornell-box"],
    "depths": [1, 3, 8, 64],
    "spp": 4,
    "spp_depth": 64,
    "resolution": "96x96",
    "repeats": 2,
    "embree_repeats": 2,
    "embree_rays": 1 << 16,
}
PAPER = ("The paper (Table 1, Fig. 6, on a GPU) measured the wavefront (\"streaming\") at 2-3x the "
         "megakernel's FPS at max depth 3 and 1 spp, SoA a little above AoS, and at max depth 64 with "
         "1024 spp SoA 1.5-3.5x faster than AoS and 5.8-8.6x faster than the megakernel; Fig. 7: the "
         "wavefront's lead grows with depth.")


# -- command line ------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pyclpt bench",
                                description="The streaming paper's tables and plots, measured on this OpenCL "
                                "device (docs/benchmarks.md).",
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="Defaults: " + ", ".join(f"{k}={v}" for k, v in DEFAULTS.items()) +
                                "; --quick: " + ", ".join(f"{k}={v}" for k, v in QUICK.items()))
    p.add_argument("-o", "--output", default=None,
                   help="report folder (default bench-report, or the folder of --from-json)")
    p.add_argument("--quick", action="store_true", help="small settings (a run of 43 s on 2 CPU cores: "
                   "docs/benchmarks.md); options given explicitly still apply")
    p.add_argument("--scenes", nargs="+", default=None,
                   help="'builtin', 'shared', built-in scene names, shared scene folders (living-room) "
                        "or scene files")
    p.add_argument("--integrators", nargs="+", choices=("megakernel", "wavefront"), default=None)
    p.add_argument("--layouts", nargs="+", choices=("aos", "soa"), default=None,
                   help="wavefront path-state layouts")
    p.add_argument("--depths", nargs="+", type=_positive, default=None, help="max depths of the sweep")
    p.add_argument("--table-depth", type=_positive, default=None, help="max depth of the Table 1 analog")
    p.add_argument("--spp", type=_positive, default=None, help="samples per pixel of the Fig. 6 analog")
    p.add_argument("--spp-depth", type=_positive, default=None, help="max depth of the Fig. 6 analog")
    p.add_argument("--resolution", type=_resolution, default=None,
                   help="WIDTHxHEIGHT of every scene, or 'scene' for each scene's own film")
    p.add_argument("--repeats", type=_positive, default=None, help="timed frames per configuration")
    p.add_argument("--warmup", type=int, default=None, help="untimed frames before them")
    p.add_argument("--device", default=None, help="OpenCL device: pocl, gpu, cpu, P:D or a name substring")
    p.add_argument("--no-embree", action="store_true", help="skip the Embree ceiling")
    p.add_argument("--embree-threads", type=_positive, default=None,
                   help="host threads for Embree (default: all cores)")
    p.add_argument("--embree-repeats", type=_positive, default=None)
    p.add_argument("--embree-rays", type=_positive, default=None,
                   help="at least this many camera rays for Embree (several per pixel on small images)")
    p.add_argument("--from-json", default=None, metavar="RESULTS",
                   help="regenerate the report from a saved results.json without running anything")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--isa", action="store_true",
                   help="also compile every kernel of the scenes for NVIDIA sm_90 and AMD gfx1030/gfx90a after the "
                        "timings: registers, stack, spills, occupancy (pyclpt gpu-isa; docs/gpu.md)")
    p.add_argument("--versus", choices=("mitsuba",), default=None,
                   help="instead: pyclpt against Mitsuba 3 on the same scene files, its own options "
                        "(`pyclpt bench --versus mitsuba --help`)")
    return p


def settings_from(a: argparse.Namespace) -> dict:
    s = dict(DEFAULTS)
    if a.quick:
        s.update(QUICK)
    for key in list(DEFAULTS):
        v = getattr(a, key, None)
        if v is not None:
            s[key] = v
    from .runner import methods_for

    s["methods"] = methods_for(s["integrators"], s["layouts"])
    if not s["methods"]:
        raise ValueError("no method to run: --integrators wavefront needs at least one --layouts")
    # the Table 1 and Fig. 6 depths are part of the sweep
    s["depths"] = sorted(set(s["depths"]) | {s["table_depth"], s["spp_depth"]})
    s["quick"] = bool(a.quick)
    s["device"] = a.device
    s["embree"] = not a.no_embree
    s["embree_threads"] = a.embree_threads
    s["isa"] = bool(getattr(a, "isa", False))
    s["resolution_label"] = "each scene's film" if s["resolution"] == "scene" else s["resolution"]
    if s["warmup"] < 0:
        raise ValueError(f"--warmup must be >= 0, got {s['warmup']}")
    return s


# -- running -------------------------------------------------------------------------------------
def run(settings: dict, out_dir: Path, progress: bool = True) -> dict:
    """Measure everything ``settings`` asks for; checkpoints results.json after each scene."""
    from tqdm.auto import tqdm

    import pyclpt

    from . import embree_ceiling, machine, runner, scenes

    t_start = time.perf_counter()
    device = pyclpt.get_device(settings["device"])
    entries = scenes.resolve(settings["scenes"])
    methods, depths = settings["methods"], settings["depths"]
    per_scene = 1 + len(depths) * len(methods) + (1 if settings["embree"] else 0)
    res = {"format": FORMAT, "meta": machine.describe(device), "settings": settings, "scenes": [],
           "runs": [], "embree": {}}
    bar = tqdm(total=per_scene * len(entries), desc="pyclpt bench", unit="step", disable=not progress,
               dynamic_ncols=True)
    isa_programs: dict = {}  # the GPU ISA check's programs, gathered scene by scene (--isa)
    with bar:
        for entry in entries:
            bar.set_postfix_str(f"{entry.label}: loading")
            scenes.load(entry)
            bar.update(1)
            done = 1
            if entry.scene is not None:
                scene = entry.scene
                if settings["resolution"] == "scene":
                    w, h = scene.film.width, scene.film.height
                else:
                    w, h = (int(x) for x in settings["resolution"].split("x"))
                entry.info["resolution"] = f"{w}x{h}"
                runs: list[dict] = []
                try:
                    for depth in depths:
                        bar.set_postfix_str(f"{entry.label}: max depth {depth}, {', '.join(methods)}")
                        runs += runner.measure_depth(
                            scene, methods, depth, w, h, repeats=settings["repeats"], warmup=settings["warmup"],
                            device=device, spp=settings["spp"] if depth == settings["spp_depth"] else None)
                        bar.update(len(methods))
                        done += len(methods)
                        _fill_counts(runs, depth, scene, w, h, device)
                    first = runs[0]
                    entry.info.update(setup_s=first["setup_s"], bvh_build_s=first.get("bvh_build_s"),
                                      compile_s=sum(r["compile_s"] for r in runs))
                    res["runs"] += runs
                except Exception as exc:  # noqa: BLE001 - recorded, and the report goes on
                    entry.skipped = f"failed while rendering: {scenes.reason(exc)}"
                if settings["embree"] and not entry.skipped:
                    bar.set_postfix_str(f"{entry.label}: Embree")
                    try:
                        res["embree"][entry.label] = embree_ceiling.measure(
                            scene, w, h, threads=settings["embree_threads"], repeats=settings["embree_repeats"],
                            min_rays=settings["embree_rays"])
                    except Exception as exc:  # noqa: BLE001
                        res["embree"][entry.label] = {"error": scenes.reason(exc)}
                    bar.update(1)
                    done += 1
                if settings.get("isa") and not entry.skipped:
                    bar.set_postfix_str(f"{entry.label}: GPU programs")
                    _gather_isa(isa_programs, scene, settings["device"])
                entry.scene = None  # free the meshes
            bar.update(per_scene - done)
            res["scenes"].append(entry.record())
            res["meta"]["elapsed_s"] = time.perf_counter() - t_start
            write_json(res, out_dir)
    res["meta"]["load_average_end"] = machine.load_average()
    if settings.get("isa"):
        res["isa"] = _isa(isa_programs)
    res["meta"]["elapsed_s"] = time.perf_counter() - t_start
    return res


def _gather_isa(programs: dict, scene, device: str | None) -> None:
    """Add the scene's programs, as a GPU builds them, to ``programs`` (keyed as collect_programs keys)."""
    from pyclpt.gpu.collect import collect_programs

    for p, names in collect_programs([scene], device=device):
        entry = programs.setdefault(p.key, (p, []))
        entry[1].extend(n for n in names if n not in entry[1])


def _isa(programs: dict) -> dict:
    """The GPU ISA check of the gathered programs (IsaReport.to_json), or {"error": why} without the tools."""
    from pyclpt.gpu.check import check_programs
    from pyclpt.gpu.isa import ToolchainMissing

    try:
        return check_programs(list(programs.values())).to_json()
    except ToolchainMissing as exc:
        return {"error": str(exc)}


COUNTING_RUN = "wavefront-soa counting run of the same seeds (every bounce through the queues)"


def _fill_counts(runs: list[dict], depth: int, scene, w: int, h: int, device) -> None:
    """Every method traces the same rays (same estimator, same random numbers). The megakernel counts
    none, and a wavefront run counts them only when its queues ran every bounce (no finish_paths
    tail): fill the others' counts from a run that counted the same seeds, or from one counting run."""
    from .runner import count_rays

    at = [r for r in runs if r["depth"] == depth]
    missing = [r for r in at if not r.get("counts")]
    if not missing:
        return
    counted = None
    for r in missing:
        src = next((o for m in ("wavefront-soa", "wavefront-aos") for o in at if o["method"] == m
                    and o.get("counts_source") == "measured" and o["seeds"] == r["seeds"]), None)
        if src is not None:
            r["counts"] = dict(src["counts"])
            r["bounces"] = r.get("bounces") or src["bounces"]  # a wavefront run keeps its own rows (its tail)
            r["counts_source"] = f"{src['method']} run of the same seeds"
            continue
        if counted is None or counted[0] != r["seeds"]:
            rows: list[dict] = []
            counted = (r["seeds"], count_rays(scene, depth, w, h, r["seeds"], device, rows), rows)
        r["counts"] = dict(counted[1])
        r["bounces"] = r.get("bounces") or counted[2]
        r["counts_source"] = COUNTING_RUN


# -- writing -------------------------------------------------------------------------------------
def write_json(res: dict, out_dir: Path) -> Path:
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "results.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(res, indent=1))
    tmp.replace(path)
    return path


CSV_FIELDS = ["scene", "triangles", "method", "integrator", "layout", "depth", "width", "height", "repeats",
              "ms_median", "ms_min", "ms_max", "device_ms_median", "cpu_ms_median", "fps", "samples_per_s",
              "camera_rays",
              "extension_rays", "shadow_rays", "total_rays", "mrays_per_s", "speedup_vs_megakernel",
              "cpu_speedup_vs_megakernel",
              "compile_s", "setup_s", "spp", "spp_seconds", "spp_speedup_vs_megakernel", "counts_source"]


def write_csv(res: dict, path: Path) -> None:
    tris = {s["scene"]: s.get("triangles") for s in res["scenes"]}
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        for r in res["runs"]:
            d = A.derived(res, r)
            c = r.get("counts") or {}
            spp = r.get("spp_run") or {}
            w.writerow({
                "scene": r["scene"], "triangles": tris.get(r["scene"]), "method": r["method"],
                "integrator": r["integrator"], "layout": r["layout"] or "", "depth": r["depth"],
                "width": r["width"], "height": r["height"], "repeats": r["repeats"],
                "ms_median": r["ms"]["median"], "ms_min": r["ms"]["min"], "ms_max": r["ms"]["max"],
                "device_ms_median": r["device_ms"]["median"], "cpu_ms_median": d["cpu_ms"], "fps": d["fps"],
                "samples_per_s": d["samples_per_s"],
                "camera_rays": c.get("camera"), "extension_rays": c.get("extension"),
                "shadow_rays": c.get("shadow"), "total_rays": c.get("total"), "mrays_per_s": d["mrays_per_s"],
                "speedup_vs_megakernel": d["speedup"], "cpu_speedup_vs_megakernel": d["cpu_speedup"],
                "compile_s": r["compile_s"], "setup_s": r["setup_s"],
                "spp": spp.get("spp"), "spp_seconds": spp.get("seconds"),
                "spp_speedup_vs_megakernel": A.spp_speedup(res, r), "counts_source": r.get("counts_source"),
            })


def write_report(res: dict, out_dir: Path) -> Path:
    """Plots, report.md, report.html and results.csv from raw results (results.json is not touched)."""
    from . import plots

    out_dir.mkdir(parents=True, exist_ok=True)
    figures = plots.make_all(res, out_dir)
    doc = build_document(res, figures)
    (out_dir / "report.md").write_text(to_markdown(doc))
    (out_dir / "report.html").write_text(to_html(doc, out_dir))
    write_csv(res, out_dir / "results.csv")
    return out_dir / "report.md"


# -- the document --------------------------------------------------------------------------------
def _x(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}x"


def _label(m: str) -> str:
    return {"megakernel": "megakernel", "wavefront-aos": "wavefront AoS", "wavefront-soa": "wavefront SoA"}.get(m, m)


def _geomean(values: list[float]) -> float | None:
    values = [v for v in values if v and v > 0]
    return math.exp(sum(math.log(v) for v in values) / len(values)) if values else None


def build_document(res: dict, figures: dict[str, str]) -> Document:
    st, meta = res["settings"], res["meta"]
    ms = A.methods(res)
    scenes = A.scenes(res)
    deep = max(A.depths(res))
    td = st["table_depth"]
    doc = Document("pyclpt timing report")
    doc.add(Para(f"Megakernel against wavefront (AoS and SoA path state) on **{meta['opencl']['device']}** "
                 f"({meta['opencl']['platform']}), {meta['date']}. "
                 f"{len(scenes)} scene(s) measured, {len(A.skipped(res))} skipped; "
                 f"{len(res['runs'])} configurations in {_n(meta.get('elapsed_s'), 3)} s"
                 f"{' (quick mode)' if st.get('quick') else ''}."))

    # summary
    doc.add(Heading(1, "Summary"))
    items = []
    for d in sorted({td, deep}):
        for m in ms[1:] if "megakernel" in ms else []:
            sp = [A.derived(res, r)["speedup"] for s in scenes if (r := A.find(res, s["scene"], m, d))]
            g = _geomean([x for x in sp if x])
            if g is not None:
                cpu = _geomean([A.derived(res, r)["cpu_speedup"] for s in scenes
                                if (r := A.find(res, s["scene"], m, d))])
                items.append(f"max depth {d}: {_label(m)} runs at {_x(g)} the megakernel's speed "
                             f"(geometric mean over {len(sp)} scene(s); range {_x(min(sp))}-{_x(max(sp))}"
                             + (f"; by process CPU time {_x(cpu)}" if cpu else "") + ")")
        winners = [f"{s['scene']}: {_label(A.fastest(res, s['scene'], d) or '-')}" for s in scenes]
        if winners:
            items.append(f"fastest at max depth {d}: " + ", ".join(winners))
    if A.spp_runs(res) and "megakernel" in ms:
        for m in ms[1:]:
            sp = [A.spp_speedup(res, r) for r in A.spp_runs(res) if r["method"] == m]
            g = _geomean([x for x in sp if x])
            if g is not None:
                items.append(f"{st['spp']} spp at max depth {st['spp_depth']}: {_label(m)} at {_x(g)} the "
                             "megakernel's speed (geometric mean)")
    if items:
        doc.add(Bullets(items))
    doc.add(Para(PAPER + " See docs/benchmarks.md for why a CPU device behaves differently."))

    # machine
    doc.add(Heading(1, "Machine and software"))
    o = meta["opencl"]
    rows = [["CPU", f"{meta['cpu']} ({meta['cores']} logical cores, {meta.get('memory_gib')} GiB)"],
            ["OS", meta["os"]], ["host", meta.get("host", "")],
            ["OpenCL platform", f"{o['platform']} ({o['platform_version']})"],
            ["OpenCL device", f"{o['device']} ({o['device_version']}; {o.get('opencl_c_version', '')})"],
            ["driver version", o["driver_version"]],
            ["PoCL / LLVM", f"{o.get('pocl_version') or '-'} / {o.get('llvm_version') or '-'}"],
            ["compute units / clock", f"{o['compute_units']} / {o.get('max_clock_mhz', '-')} MHz"],
            ["pyclpt", f"{meta['pyclpt']} (git {meta.get('git_revision') or 'n/a'})"],
            ["Python / numpy / pyopencl", f"{meta['python']} / {meta['numpy']} / {meta['pyopencl']}"],
            ["pocl-binary-distribution", str(meta.get("pocl_binary_distribution"))],
            ["Embree", f"embreex {meta.get('embreex')} ({meta.get('embree_library') or '-'})"],
            ["load average at start / end", f"{meta.get('load_average_start')} / {meta.get('load_average_end')}"],
            ["date", meta["date"]]]
    doc.add(Table(["", "value"], rows))

    doc.add(Heading(1, "Settings"))
    keys = ["scenes", "methods", "depths", "table_depth", "spp", "spp_depth", "resolution", "repeats", "warmup",
            "device", "embree", "embree_threads", "embree_repeats", "embree_rays", "quick"]
    doc.add(Table(["setting", "value"], [[k, json.dumps(st.get(k))] for k in keys]))
    doc.add(Para("Command to repeat this run: "
                 f"`pyclpt bench {shlex.join(_argv(st))}`"))

    # scenes
    doc.add(Heading(1, "Scenes"))
    rows = []
    for s in scenes:
        e = res["embree"].get(s["scene"]) or {}
        rows.append([s["scene"], f"{s['triangles']:,}", s.get("resolution", ""), _n(s["load_s"]),
                     _n(s.get("setup_s")), _n(s.get("bvh_build_s")), _n(s.get("compile_s")),
                     _n(e.get("build_s"))])
    doc.add(Table(["scene", "triangles", "resolution", "load s", "setup s (BVH + upload)", "BVH build s",
                   "compile s", "Embree build s"], rows))
    doc.add(Para("load: parsing the scene and its meshes; setup: the first renderer's BVH build (or disk-cache "
                 "load) and upload; BVH build: 0 when the BVH came from pyclpt's cache; compile: program "
                 "builds and first-launch compilation summed over the scene's configurations (programs are "
                 "cached per process, so mostly the first scene pays it). None of these are in the frame "
                 "times."))
    notes = [f"`{s['scene']}`: {w}" for s in scenes for w in s.get("load_warnings", [])]
    if notes:
        doc.add(Para("Importer notes (what the scene asks for that pyclpt ignores or approximates):"))
        doc.add(Bullets(notes))
    if A.skipped(res):
        doc.add(Para("Skipped scenes:"))
        doc.add(Bullets([f"`{s['scene']}` ({s['source']}): {s['skipped']}" for s in A.skipped(res)]))

    # Table 1
    doc.add(Heading(1, "Table 1 analog: frames per second"))
    doc.add(Para(f"Mean FPS of 1-spp frames (median frame time) at max depth {td}, as the paper's Table 1; "
                 f"speed-up = megakernel time / method time."))
    headers = ["scene", "triangles", "resolution"] + [f"{_label(m)} FPS" for m in ms] + \
        [f"{_label(m)} speed-up" for m in ms if m != "megakernel" and "megakernel" in ms]
    rows = []
    for s in scenes:
        row = [s["scene"], f"{s['triangles']:,}", s.get("resolution", "")]
        ds = [A.derived(res, r) if (r := A.find(res, s["scene"], m, td)) else None for m in ms]
        row += [_n(d["fps"]) if d else "-" for d in ds]
        if "megakernel" in ms:
            row += [_x(d["speedup"]) if d else "-" for m, d in zip(ms, ds) if m != "megakernel"]
        rows.append(row)
    doc.add(Table(headers, rows))
    if "table1" in figures:
        doc.add(Image(figures["table1"], "Table 1 analog"))

    # Fig 6
    doc.add(Heading(1, "Fig. 6 analog: render time for many samples"))
    doc.add(Para(f"Seconds to render {st['spp']} spp at max depth {st['spp_depth']} after the timed frames (in up "
                 "to 4 render calls per method, interleaved across the methods; the paper used 1024 spp: "
                 f"multiply by {_n(1024 / st['spp'])} for its count)."))
    rows = []
    for s in scenes:
        row = [s["scene"]]
        for m in ms:
            r = A.find(res, s["scene"], m, st["spp_depth"])
            row.append(_n(r["spp_run"]["seconds"]) if r and "spp_run" in r else "-")
        for m in ms:
            if m != "megakernel" and "megakernel" in ms:
                r = A.find(res, s["scene"], m, st["spp_depth"])
                row.append(_x(A.spp_speedup(res, r)) if r else "-")
        rows.append(row)
    doc.add(Table(["scene"] + [f"{_label(m)} s" for m in ms] +
                  [f"{_label(m)} speed-up" for m in ms if m != "megakernel" and "megakernel" in ms], rows))
    if "fig6" in figures:
        doc.add(Image(figures["fig6"], "Fig. 6 analog"))

    # Fig 7
    doc.add(Heading(1, "Fig. 7 analog: time against depth"))
    doc.add(Para("Median ms per 1-spp frame (min-max over the repeats) at each max depth; device ms (sum of "
                 "the kernels' profiling events) in the CSV."))
    for s in scenes:
        rows = []
        for d in A.depths(res):
            row = [str(d)]
            for m in ms:
                r = A.find(res, s["scene"], m, d)
                row.append(f"{_n(r['ms']['median'])} ({_n(r['ms']['min'])}-{_n(r['ms']['max'])})" if r else "-")
            rows.append(row)
        doc.add(Para(f"`{s['scene']}`:"))
        doc.add(Table(["max depth"] + [f"{_label(m)} ms" for m in ms], rows))
    if "fig7" in figures:
        doc.add(Image(figures["fig7"], "Fig. 7 analog"))

    # throughput
    doc.add(Heading(1, "Throughput: samples/s and rays/s"))
    agree = A.counts_agree(res)
    doc.add(Para("Rays per frame = camera rays + extension rays (bounces 1, 2, ...) + shadow rays, from the "
                 "wavefront's queue counters. The megakernel runs the identical estimator with identical random "
                 "numbers, so for the same seeds it traces exactly these rays; its counts are the wavefront's of "
                 "the same frames." + ("" if agree is None else
                                       f" AoS and SoA runs counted identical rays: {'yes' if agree else 'NO'}.")))
    rows = []
    for s in scenes:
        e = A.embree(res, s["scene"])
        ceiling = A.ceiling_mrays(e) if e else None
        for d in sorted({td, deep}):
            base = next((r for m in ms if (r := A.find(res, s["scene"], m, d))), None)
            if base is None:
                continue
            c = base.get("counts") or {}
            row = [s["scene"], str(d), _n(c.get("camera")), _n(c.get("extension")), _n(c.get("shadow"))]
            best = None
            for m in ms:
                r = A.find(res, s["scene"], m, d)
                dd = A.derived(res, r) if r else None
                row.append(f"{_n(dd['samples_per_s'] / 1e6)} / {_n(dd['mrays_per_s'])}" if dd and dd["mrays_per_s"]
                           else "-")
                if dd and dd["mrays_per_s"]:
                    best = max(best or 0.0, dd["mrays_per_s"])
            row += [_n(ceiling), f"{100 * best / ceiling:.0f}%" if best and ceiling else "-"]
            rows.append(row)
    doc.add(Table(["scene", "max depth", "camera rays", "extension rays", "shadow rays"] +
                  [f"{_label(m)} Msamples/s / Mrays/s" for m in ms] + ["Embree Mrays/s", "best / Embree"], rows))
    if "rays" in figures:
        doc.add(Image(figures["rays"], "rays per second"))

    # kernels
    doc.add(Heading(1, "Per-kernel time"))
    doc.add(Para("Device ms per frame of each kernel (mean over the timed frames, OpenCL profiling events) at "
                 f"max depth {td} and {deep}; share of the method's device time in brackets."))
    rows = []
    for s in scenes:
        for d in sorted({td, deep}):
            for m, ks in A.kernel_breakdown(res, s["scene"], d).items():
                total = sum(k["ms"] for k in ks) or 1.0
                rows.append([s["scene"], str(d), _label(m),
                             ", ".join(f"{k['kernel']} {_n(k['ms'])} ({100 * k['ms'] / total:.0f}%)" for k in ks)])
    doc.add(Table(["scene", "max depth", "method", "kernels: ms per frame (share)"], rows))
    if "kernels" in figures:
        doc.add(Image(figures["kernels"], "per-kernel time"))

    # occupancy
    doc.add(Heading(1, "Occupancy: paths alive per bounce"))
    doc.add(Para(f"Paths alive at each bounce of one frame at max depth {deep} (the ray queue's size): the "
                 "work a wavefront's compaction keeps dense while a megakernel's lanes go idle. Columns: "
                 "bounces 0-7, then every 8th."))
    rows = []
    width = 0
    for s in scenes:
        b = A.occupancy(res, s["scene"], deep)
        if not b:
            continue
        pick = [r for r in b if r["bounce"] < 8 or r["bounce"] % 8 == 0]
        width = max(width, len(pick))
        rows.append([s["scene"], str(len(b) - 1)] + [f"{r['rays']:,}" for r in pick])
    if rows:
        idx = sorted({r["bounce"] for s in scenes for r in A.occupancy(res, s["scene"], deep)
                      if r["bounce"] < 8 or r["bounce"] % 8 == 0})
        rows = [r + [""] * (2 + len(idx) - len(r)) for r in rows]
        doc.add(Table(["scene", "last bounce"] + [f"b{i}" for i in idx], rows))
    if "occupancy" in figures:
        doc.add(Image(figures["occupancy"], "occupancy"))

    # triangles
    doc.add(Heading(1, "Cost against triangle count"))
    rows = []
    for s in sorted(scenes, key=lambda s: s["triangles"]):
        row = [s["scene"], f"{s['triangles']:,}"]
        for m in ms:
            r = A.find(res, s["scene"], m, td)
            row.append(_n(r["ms"]["median"]) if r else "-")
        rows.append(row)
    doc.add(Para(f"Median ms per 1-spp frame at max depth {td}, scenes by triangle count (the BVH makes the "
                 "cost grow roughly with the log of the triangle count, plus memory effects once the BVH "
                 "outgrows the caches)."))
    doc.add(Table(["scene", "triangles"] + [f"{_label(m)} ms" for m in ms], rows))
    if "triangles" in figures:
        doc.add(Image(figures["triangles"], "cost against triangles"))

    if res.get("isa"):
        _isa_section(doc, res["isa"], figures)

    # embree
    doc.add(Heading(1, "Embree ceiling"))
    doc.add(Para("Embree (embreex, one `rtcIntersect1`/`rtcOccluded1` call per ray, the rays split over host "
                 "threads) on the same triangles and resolution: camera rays (closest hit; several per pixel on "
                 f"small images, at least {st.get('embree_rays')}), cosine-distributed "
                 "secondary rays from their hit points (closest hit) and shadow rays to random points on the "
                 "emitters (any hit); best of the repeats. This is the ray throughput this machine's CPU gets "
                 "from a tuned host ray tracer, without shading."))
    rows = []
    for s in scenes:
        e = res["embree"].get(s["scene"])
        if not e:
            continue
        if "error" in e:
            rows.append([s["scene"], "-", "-", "-", "-", "-", e["error"]])
            continue
        k = [e.get(x) for x in ("primary", "secondary", "shadow")]
        rows.append([s["scene"], str(e["threads"]), *[_n(x["mrays_per_s"]) if x else "-" for x in k],
                     _n(A.ceiling_mrays(e)), f"primary hit {100 * e['primary'].get('hit_fraction', 0):.0f}%"])
    if rows:
        doc.add(Table(["scene", "threads", "primary Mrays/s", "secondary Mrays/s", "shadow Mrays/s",
                       "mix Mrays/s", "note"], rows))
    else:
        doc.add(Para("Not measured (`--no-embree`)."))

    # method
    doc.add(Heading(1, "How this was measured"))
    doc.add(Bullets([
        f"Each configuration (scene x method x max depth) makes a new renderer (scene setup and compilation "
        f"timed apart), renders {st['warmup']} untimed warm-up frame(s), then {st['repeats']} timed frames, each "
        "1 spp of every pixel with its own seed; reported: median, min and max.",
        "Frame time: host wall clock around `Renderer.render(1)` (which reads the frame back) and a queue "
        "`finish()`: what a user waits. Device time: the sum of the frame's kernels' OpenCL profiling events "
        "(in the CSV and the per-kernel table).",
        "Frames of the methods are interleaved: per max depth, all methods' renderers are made and warmed "
        "up, then each round renders one frame with every method (rotating the order), so load changes on "
        "a shared machine hit all methods alike.",
        "Process CPU time per frame (all the driver's threads; in the CSV and the summary) is steadier than "
        "wall time when other processes compete for the cores: on a CPU device, compare speed-ups by both.",
        "FPS = 1000 / median ms; samples/s = pixels / median s; rays/s = rays per frame / median s.",
        "The Fig. 6 analog renders the spp count with each method after its frames, as up to 4 render calls "
        "(consecutive sample ranges, together the same samples as one call) interleaved across the methods; "
        "the calls' times are summed.",
        "Wavefront: the device's default wave size and the `readback` schedule; megakernel: one work-item per "
        "path. Both use work-groups of 64.",
        "On a shared machine the load average above says how noisy the run was.",
    ]))
    doc.add(Heading(1, "Raw results"))
    doc.add(Para("`results.json` holds every measured frame, kernel table and queue count (this report is "
                 "regenerated from it with `pyclpt bench --from-json results.json`); `results.csv` has one row "
                 "per configuration."))
    return doc


def _isa_section(doc: Document, isa: dict, figures: dict[str, str]) -> None:
    """The GPU ISA check (--isa): per kernel and target, registers, stack, spills and occupancy."""
    doc.add(Heading(1, "GPU instruction sets"))
    if "error" in isa:
        doc.add(Para(f"Not checked: {isa['error']}."))
        return
    from pyclpt.gpu.check import IsaReport
    from pyclpt.gpu.report import budgets, header, rows

    report = IsaReport.from_json(isa)
    doc.add(Para(f"Every program the renderer builds for these scenes, with the GPU BVH layout, compiled for "
                 f"NVIDIA sm_90 and AMD gfx1030 and gfx90a without a GPU ({report.toolchain}; docs/gpu.md): per "
                 "kernel, the variant with the most registers; occupancy is the resident warps (waves) over the "
                 f"hardware's. {report.programs} distinct programs, {len(report.failures)} failures."))
    doc.add(Table(header(), rows(report)))
    doc.add(Bullets(budgets(report) + [f"FAILED: {f.program} for {f.target}: {f.message.splitlines()[0]}"
                                       for f in report.failures]))
    if "isa_occupancy" in figures:
        doc.add(Image(figures["isa_occupancy"], "theoretical occupancy per kernel and GPU target"))


def _argv(st: dict) -> list[str]:
    out = ["--scenes", *st["scenes"]]
    integ = sorted({m.split("-")[0] for m in st["methods"]}, key=["megakernel", "wavefront"].index)
    out += ["--integrators", *integ]
    layouts = [m.split("-")[1] for m in st["methods"] if "-" in m]
    if layouts:
        out += ["--layouts", *layouts]
    out += ["--depths", *map(str, st["depths"]), "--table-depth", str(st["table_depth"]), "--spp", str(st["spp"]),
            "--spp-depth", str(st["spp_depth"]), "--resolution", st["resolution"], "--repeats", str(st["repeats"]),
            "--warmup", str(st["warmup"])]
    if st.get("device"):
        out += ["--device", st["device"]]
    if not st.get("embree", True):
        out.append("--no-embree")
    else:
        out += ["--embree-repeats", str(st["embree_repeats"]), "--embree-rays", str(st["embree_rays"])]
        if st.get("embree_threads"):
            out += ["--embree-threads", str(st["embree_threads"])]
    return out


# -- entry point -----------------------------------------------------------------------------------
class NothingMeasured(RuntimeError):
    """A run (or a results file) without a single measurement: no report, a non-zero exit."""


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if any(x == "--versus" or x.startswith("--versus=") for x in argv):
        from . import versus

        return versus.main(argv)
    a = build_parser().parse_args(argv)
    try:
        if a.from_json:
            src = Path(a.from_json)
            res = json.loads(src.read_text())
            if res.get("format") != FORMAT:
                raise ValueError(f"{src}: not a pyclpt bench results file of format {FORMAT}")
            if not res.get("runs"):
                raise NothingMeasured(f"{src} holds no measurement (every scene was skipped): no report to write")
            out_dir = Path(a.output) if a.output else src.parent
            if out_dir.resolve() != src.parent.resolve():
                write_json(res, out_dir)
            report = write_report(res, out_dir)
            print(f"{report}: regenerated from {src}")
            return 0
        settings = settings_from(a)
        out_dir = Path(a.output or "bench-report")
        res = run(settings, out_dir, progress=not a.no_progress)
        write_json(res, out_dir)
        if not res["runs"]:
            for s in A.skipped(res):
                print(f"skipped {s['scene']}: {s['skipped']}", file=sys.stderr)
            raise NothingMeasured(f"nothing was measured: every scene was skipped (reasons above and in "
                                  f"{out_dir / 'results.json'}); no report written")
        report = write_report(res, out_dir)
        print(f"{report}: {len(A.scenes(res))} scene(s), {len(res['runs'])} configurations, "
              f"{res['meta']['elapsed_s']:.0f} s; also report.html, results.json, results.csv and the plots in "
              f"{out_dir}")
        for s in A.skipped(res):
            print(f"skipped {s['scene']}: {s['skipped']}", file=sys.stderr)
        return 0
    except (OSError, ValueError, RuntimeError, MemoryError) as exc:
        print(f"pyclpt bench: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
