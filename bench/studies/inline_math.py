"""What does inlining cl/core/math.h change on PoCL? Little: megakernel 1.05x, wavefront 1.08x, stages 1.00-1.27x,
and no kernel's work-item loop vectorized before or after (docs/wavefront.md, "Inline math on PoCL").

Vectorizer remarks per kernel, per-stage throughput, compile time.

Runs against whichever pyclpt the interpreter imports, so the same script measures two checkouts (each with
its own virtual environment) for a before/after comparison (docs/wavefront.md, "Inline math on PoCL"):

    python -m bench.studies.inline_math speed    # megakernel Msamples/s and wavefront per-stage Mitems/s, one JSON line
    python -m bench.studies.inline_math compile  # seconds to build all kernels (POCL_KERNEL_CACHE=0: cold)
    POCL_VECTORIZER_REMARKS=1 POCL_KERNEL_CACHE=0 python -m bench.studies.inline_math remarks   # vectorizer verdicts

Setting: cornell-box, 256x256, 64 spp, max depth 8 (remarks: 64x64, 1 spp). A stage's items are what it
processes: path_init the paths, intersect the rays, miss the misses, process_hit and sample_bsdf the hits,
shadow_test and light_contribution the shadow rays.
"""
from __future__ import annotations

import json
import os
import sys
import time

import pyclpt
from bench.timing.vectorizer_remarks import collect

SIZE, SPP, DEPTH = 256, 64, 8
ITEMS = {"path_init": "paths", "intersect": "rays", "miss": "misses", "process_hit": "hits", "sample_bsdf": "hits",
         "shadow_test": "shadow_rays", "light_contribution": "shadow_rays"}


def renderer(integrator: str, size: int = SIZE) -> pyclpt.Renderer:
    return pyclpt.Renderer(pyclpt.load("cornell-box"), integrator=integrator, max_depth=DEPTH,
                           width=size, height=size)


def speed() -> dict:
    out: dict = {}
    r = renderer("megakernel")
    r.render(SPP, seed=1)
    out["megakernel_msamples_s"] = SIZE * SIZE * SPP / r.stats.seconds / 1e6
    w = renderer("wavefront")
    w.render(SPP, seed=1)
    totals = {k: sum(b.get(k, 0) for b in w.stats.bounces) for k in ("rays", "hits", "misses", "shadow_rays")}
    totals["paths"] = SIZE * SIZE * SPP
    out["wavefront_msamples_s"] = SIZE * SIZE * SPP / w.stats.seconds / 1e6
    out["stages_mitems_s"] = {k["kernel"]: totals[ITEMS[k["kernel"]]] / (k["total_ms"] * 1e3)
                              for k in w.stats.kernels if k["kernel"] in ITEMS}
    return out


def compile_seconds() -> dict:
    """build_s: clBuildProgram; wall_s: everything until both integrators have rendered a 16x16 frame, which
    includes PoCL's code generation of each kernel at its first launch (and a few ms of scene setup)."""
    from pyclpt.device.program import compile_seconds as total
    start = time.perf_counter()
    renderer("megakernel", 16).render(1)
    renderer("wavefront", 16).render(1)
    return {"build_s": total(), "wall_s": time.perf_counter() - start}


def remarks() -> dict:
    """Every kernel's vectorizer remarks, from one render with each integrator (POCL_KERNEL_CACHE=0)."""
    def render() -> None:
        renderer("megakernel", 64).render(1)
        renderer("wavefront", 64).render(1)
    return collect(render)


if __name__ == "__main__":
    mode = sys.argv[1] if len(sys.argv) > 1 else "speed"
    run = {"speed": speed, "compile": compile_seconds, "remarks": remarks}[mode]
    print(json.dumps({"pyclpt": os.path.dirname(pyclpt.__file__), **run()}))
