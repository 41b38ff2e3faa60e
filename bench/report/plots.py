"""The report's figures (matplotlib, Agg backend, PNG). Each function takes the raw results and
the output folder, writes one PNG and returns its file name (None when there is nothing to plot)."""
from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from . import analysis as A

COLORS = {"megakernel": "#606060", "wavefront-aos": "#1f77b4", "wavefront-soa": "#ff7f0e"}
LABELS = {"megakernel": "megakernel", "wavefront-aos": "wavefront AoS", "wavefront-soa": "wavefront SoA"}
DPI = 110


def save_figure(fig, folder: Path, name: str, dpi: int = DPI, software: str = "pyclpt bench") -> str:
    """Lay out, write folder/name (PNG, tagged with the program that made it), close; returns name."""
    fig.tight_layout()
    fig.savefig(folder / name, dpi=dpi, metadata={"Software": software})
    plt.close(fig)
    return name


def _grid(n: int, width: float = 4.2, height: float = 3.2):
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(width * cols, height * rows), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    return fig, list(axes.flat)


def _grouped_bars(ax, groups: list[str], series: dict[str, list[float | None]], log: bool = False) -> None:
    n = max(len(series), 1)
    width = 0.8 / n
    for i, (m, values) in enumerate(series.items()):
        xs = [g + (i - (n - 1) / 2) * width for g in range(len(groups))]
        vals = [v if v is not None else 0.0 for v in values]
        bars = ax.bar(xs, vals, width, label=LABELS.get(m, m), color=COLORS.get(m))
        for b, v in zip(bars, values):
            if v is not None:
                ax.annotate(f"{v:.3g}", (b.get_x() + b.get_width() / 2, b.get_height()), ha="center",
                            va="bottom", fontsize=7)
    ax.set_xticks(range(len(groups)))
    ax.set_xticklabels(groups, rotation=20, ha="right")
    if log:
        ax.set_yscale("log")
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)


def table1(res: dict, folder: Path) -> str | None:
    depth = res["settings"]["table_depth"]
    scenes = [s["scene"] for s in A.scenes(res)]
    if not scenes:
        return None
    series = {}
    for m in A.methods(res):
        series[m] = [A.derived(res, r)["fps"] if (r := A.find(res, s, m, depth)) else None for s in scenes]
    fig, ax = plt.subplots(figsize=(max(6.0, 1.6 * len(scenes) + 2), 4))
    _grouped_bars(ax, scenes, series)
    ax.set_ylabel("frames per second (1 spp)")
    w, h = res["settings"]["resolution_label"], depth
    ax.set_title(f"Table 1 analog: FPS at max depth {h}, 1 spp, {w}")
    return save_figure(fig, folder, "table1_fps.png")


def fig6(res: dict, folder: Path) -> str | None:
    runs = A.spp_runs(res)
    if not runs:
        return None
    st = res["settings"]
    scenes = [s["scene"] for s in A.scenes(res) if any(r["scene"] == s["scene"] for r in runs)]
    series = {}
    for m in A.methods(res):
        series[m] = []
        for s in scenes:
            r = A.find(res, s, m, st["spp_depth"])
            series[m].append(r["spp_run"]["seconds"] if r and "spp_run" in r else None)
    fig, ax = plt.subplots(figsize=(max(6.0, 1.6 * len(scenes) + 2), 4))
    _grouped_bars(ax, scenes, series, log=True)
    ax.set_ylabel(f"seconds for {st['spp']} spp (log)")
    ax.set_title(f"Fig. 6 analog: render time at max depth {st['spp_depth']}, {st['spp']} spp, "
                 f"{st['resolution_label']}")
    return save_figure(fig, folder, "fig6_spp_time.png")


def fig7(res: dict, folder: Path) -> str | None:
    scenes = [s["scene"] for s in A.scenes(res)]
    if not scenes:
        return None
    fig, axes = _grid(len(scenes))
    for ax, s in zip(axes, scenes):
        for m in A.methods(res):
            rows = A.depth_curve(res, s, m)
            if not rows:
                continue
            d, med, lo, hi = zip(*rows)
            ax.plot(d, med, "o-", color=COLORS.get(m), label=LABELS.get(m, m), ms=3)
            ax.fill_between(d, lo, hi, color=COLORS.get(m), alpha=0.2, lw=0)
        ax.set_xscale("log", base=2)
        ax.set_xlabel("max depth")
        ax.set_ylabel("ms per frame (1 spp)")
        ax.set_title(s, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("Fig. 7 analog: time against max depth (median, band: min-max)", fontsize=11)
    return save_figure(fig, folder, "fig7_time_vs_depth.png")


def kernels(res: dict, folder: Path) -> str | None:
    scenes = [s["scene"] for s in A.scenes(res)]
    if not scenes:
        return None
    st = res["settings"]
    pick = sorted({st["table_depth"], max(A.depths(res))})
    names = A.kernel_names(res)
    cmap = plt.get_cmap("tab10")
    colors = {k: ("#606060" if k == "megakernel" else cmap(i % 10)) for i, k in enumerate(names)}
    fig, axes = _grid(len(scenes), width=4.6, height=3.6)
    for ax, s in zip(axes, scenes):
        labels, x = [], 0
        for d in pick:
            for m, ks in A.kernel_breakdown(res, s, d).items():
                bottom = 0.0
                for k in ks:
                    ax.bar(x, k["ms"], 0.7, bottom=bottom, color=colors[k["kernel"]])
                    bottom += k["ms"]
                labels.append(f"{LABELS.get(m, m)}\ndepth {d}")
                x += 1
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels(labels, fontsize=6, rotation=30, ha="right")
        ax.set_ylabel("device ms per frame")
        ax.set_title(s, fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    handles = [plt.Rectangle((0, 0), 1, 1, color=colors[k]) for k in names]
    fig.legend(handles, names, loc="lower center", ncol=min(len(names), 8), fontsize=8,
               bbox_to_anchor=(0.5, 0.0))
    fig.suptitle("Per-kernel device time (OpenCL profiling events), mean per frame", fontsize=11)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.savefig(folder / "kernels.png", dpi=DPI, metadata={"Software": "pyclpt bench"})
    plt.close(fig)
    return "kernels.png"


def occupancy(res: dict, folder: Path) -> str | None:
    depth = max(A.depths(res))
    fig, ax = plt.subplots(figsize=(7, 4))
    any_data = False
    for s in A.scenes(res):
        rows = A.occupancy(res, s["scene"], depth)
        if not rows:
            continue
        pixels = rows[0]["rays"] or 1
        ax.plot([r["bounce"] for r in rows], [r["rays"] / pixels for r in rows], "o-", ms=2, label=s["scene"])
        any_data = True
    if not any_data:
        plt.close(fig)
        return None
    _line_axes(ax, "bounce", "paths alive / pixels (log)",
               f"Occupancy: paths alive per bounce at max depth {depth} (ray queue size)", logy=True)
    return save_figure(fig, folder, "occupancy.png")


def rays(res: dict, folder: Path) -> str | None:
    scenes = [s["scene"] for s in A.scenes(res)]
    if not scenes:
        return None
    pick = sorted({res["settings"]["table_depth"], max(A.depths(res))})
    fig, axes = _grid(len(pick), width=max(5.0, 1.4 * len(scenes) + 2), height=3.8)
    for ax, d in zip(axes, pick):
        series = {}
        for m in A.methods(res):
            series[m] = [A.derived(res, r)["mrays_per_s"] if (r := A.find(res, s, m, d)) else None
                         for s in scenes]
        _grouped_bars(ax, scenes, series)
        ceiling = [A.ceiling_mrays(e) if (e := A.embree(res, s)) else None for s in scenes]
        xs = [i for i, c in enumerate(ceiling) if c is not None]
        if xs:
            ax.scatter(xs, [ceiling[i] for i in xs], marker="_", s=900, color="black", zorder=3,
                       label="Embree (host)")
        ax.set_ylim(0, 1.4 * ax.get_ylim()[1])  # room for the legend above the bars
        ax.legend(fontsize=8, ncol=2, loc="upper left")
        ax.set_ylabel("million rays / s")
        ax.set_title(f"rays/s (camera + extension + shadow), max depth {d}", fontsize=10)
    return save_figure(fig, folder, "rays_per_second.png")


def triangles(res: dict, folder: Path) -> str | None:
    depth = res["settings"]["table_depth"]
    scenes = A.scenes(res)
    if len(scenes) < 2:
        return None
    fig, ax = plt.subplots(figsize=(7, 4))
    for m in A.methods(res):
        pts = sorted((s["triangles"], A.derived(res, r)["ms"]) for s in scenes
                     if (r := A.find(res, s["scene"], m, depth)))
        if pts:
            ax.plot(*zip(*pts), "o-", color=COLORS.get(m), label=LABELS.get(m, m))
    for s in scenes:
        r = A.find(res, s["scene"], A.methods(res)[0], depth)
        if r:
            ax.annotate(s["scene"], (s["triangles"], A.derived(res, r)["ms"]), fontsize=7,
                        textcoords="offset points", xytext=(3, 3))
    _line_axes(ax, "triangles (log)", "ms per frame (1 spp)", f"Cost against triangle count, max depth {depth}",
               logx=True)
    return save_figure(fig, folder, "triangles.png")


def _line_axes(ax, xlabel: str, ylabel: str, title: str, logx: bool = False, logy: bool = False) -> None:
    """Labels, log scales, grid and legend of a line plot."""
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def isa_occupancy(res: dict, folder: Path) -> str | None:
    """The GPU ISA check's occupancy bars (--isa)."""
    isa = res.get("isa")
    if not isa or "error" in isa:
        return None
    from pyclpt.gpu.check import IsaReport
    from pyclpt.gpu.report import plot

    return plot(IsaReport.from_json(isa), folder / "isa_occupancy.png").name


ALL = (table1, fig6, fig7, kernels, occupancy, rays, triangles, isa_occupancy)


def make_all(res: dict, folder: Path) -> dict[str, str]:
    """Every figure; returns {figure function name: file name} for those drawn."""
    out = {}
    for fn in ALL:
        name = fn(res, folder)
        if name:
            out[fn.__name__] = name
    return out
