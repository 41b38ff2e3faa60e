"""Figures derived from a report's raw results (``results.json``): FPS, samples/s, rays/s,
speed-ups over the megakernel, the tables behind each plot. Pure functions of the results, so a
report regenerated from saved results is the same report."""
from __future__ import annotations

from typing import Any

Results = dict[str, Any]


def scenes(res: Results) -> list[dict]:
    """Scenes that were measured (not skipped), in run order."""
    return [s for s in res["scenes"] if not s.get("skipped")]


def skipped(res: Results) -> list[dict]:
    return [s for s in res["scenes"] if s.get("skipped")]


def methods(res: Results) -> list[str]:
    return list(res["settings"]["methods"])


def depths(res: Results) -> list[int]:
    return list(res["settings"]["depths"])


def find(res: Results, scene: str, method: str, depth: int) -> dict | None:
    for r in res["runs"]:
        if r["scene"] == scene and r["method"] == method and r["depth"] == depth:
            return r
    return None


def derived(res: Results, run: dict) -> dict[str, float | None]:
    """ms per frame (median, min, max; wall), device ms, FPS, samples/s, rays per frame and per
    second, and the speed-up over the megakernel of the same scene and depth."""
    ms = run["ms"]["median"]
    out: dict[str, float | None] = {
        "ms": ms, "ms_min": run["ms"]["min"], "ms_max": run["ms"]["max"],
        "device_ms": run["device_ms"]["median"], "fps": 1e3 / ms, "samples_per_s": run["pixels"] / (ms / 1e3),
        "rays_per_frame": None, "mrays_per_s": None, "speedup": None,
        "cpu_ms": run["cpu_ms"]["median"] if "cpu_ms" in run else None, "cpu_speedup": None,
    }
    counts = run.get("counts")
    if counts:
        out["rays_per_frame"] = counts["total"]
        out["mrays_per_s"] = counts["total"] / (ms / 1e3) / 1e6
    base = find(res, run["scene"], "megakernel", run["depth"])
    if base is not None:
        out["speedup"] = base["ms"]["median"] / ms
        if out["cpu_ms"] and "cpu_ms" in base:
            out["cpu_speedup"] = base["cpu_ms"]["median"] / out["cpu_ms"]
    return out


def spp_speedup(res: Results, run: dict) -> float | None:
    base = find(res, run["scene"], "megakernel", run["depth"])
    if base is None or "spp_run" not in base or "spp_run" not in run:
        return None
    return base["spp_run"]["seconds"] / run["spp_run"]["seconds"]


def spp_runs(res: Results) -> list[dict]:
    """Runs that rendered the Fig. 6 spp count."""
    return [r for r in res["runs"] if "spp_run" in r]


def depth_curve(res: Results, scene: str, method: str) -> list[tuple[int, float, float, float]]:
    """(depth, median ms, min ms, max ms) of one scene and method, by depth."""
    rows = []
    for d in depths(res):
        r = find(res, scene, method, d)
        if r is not None:
            rows.append((d, r["ms"]["median"], r["ms"]["min"], r["ms"]["max"]))
    return rows


def kernel_breakdown(res: Results, scene: str, depth: int) -> dict[str, list[dict]]:
    """Per method, the mean ms per frame of each kernel (OpenCL profiling events)."""
    out = {}
    for m in methods(res):
        r = find(res, scene, m, depth)
        if r is not None:
            out[m] = r["kernels"]
    return out


def kernel_names(res: Results) -> list[str]:
    names: list[str] = []
    for r in res["runs"]:
        for k in r["kernels"]:
            if k["kernel"] not in names:
                names.append(k["kernel"])
    return names


def occupancy(res: Results, scene: str, depth: int) -> list[dict]:
    """Per bounce of the first timed frame at this depth: paths alive (rays), hits, misses, shadow
    rays, unoccluded (the wavefront's queue counts; the AoS and SoA runs count the same)."""
    for m in methods(res):
        r = find(res, scene, m, depth)
        if r is not None and r.get("bounces"):
            return r["bounces"]
    return []


def embree(res: Results, scene: str) -> dict | None:
    e = res.get("embree", {}).get(scene)
    return e if e and "primary" in e else None


def ceiling_mrays(e: dict) -> float | None:
    """Embree's rays/s over the mix of ray kinds it traced (total rays / total best time)."""
    kinds = [e[k] for k in ("primary", "secondary", "shadow") if k in e]
    if not kinds:
        return None
    return sum(k["rays"] for k in kinds) / sum(k["best_s"] for k in kinds) / 1e6


def counts_agree(res: Results) -> bool | None:
    """Whether the wavefront AoS and SoA runs of the same configuration counted the same rays
    (they must: same estimator, same random numbers); None when only one layout ran."""
    seen = False
    for r in res["runs"]:
        if r["method"] != "wavefront-aos":
            continue
        other = find(res, r["scene"], "wavefront-soa", r["depth"])
        if other is None or not r.get("counts") or not other.get("counts"):
            continue
        seen = True
        if r["counts"] != other["counts"]:
            return False
    return True if seen else None


def fastest(res: Results, scene: str, depth: int) -> str | None:
    best = None
    for m in methods(res):
        r = find(res, scene, m, depth)
        if r is not None and (best is None or r["ms"]["median"] < best[1]):
            best = (m, r["ms"]["median"])
    return best[0] if best else None
