"""The GPU ISA check's table and plot: per kernel and target, the worst variant's registers, stack or
scratch, spills and theoretical occupancy (docs/gpu.md; ``pyclpt gpu-isa``, ``pyclpt bench --isa``)."""
from __future__ import annotations

from pathlib import Path

from pyclpt.gpu.check import IsaReport
from pyclpt.gpu.isa import KernelCost
from pyclpt.gpu.targets import TARGETS
from pyclpt.scene.model import Scene

#: The kernels in the order of a path's life, then the film, the denoiser and the gradients.
ORDER = ("megakernel", "path_init", "intersect", "miss", "process_hit", "shadow_test", "light_contribution",
         "sample_bsdf", "compact_count", "compact_scatter", "finish_paths", "accumulate_frame", "accumulate_batch",
         "resolve", "aov_accumulate", "count_dropped", "demodulate", "reproject", "clip_history", "antilag",
         "variance", "atrous", "modulate", "blend", "backward", "forward")
#: Budgets of issue 24 on sm_90: registers of the shading stages, and the traversal's stack.
SHADING_STAGES = ("path_init", "miss", "process_hit", "light_contribution", "sample_bsdf")
TRAVERSAL_STAGES = ("intersect", "shadow_test")
#: The wavefront's stages, none of which may spill on gfx1030 (the issue's rule; the megakernel, finish_paths and
#: the gradient kernels are reported without a budget).
WAVEFRONT_STAGES = ("path_init", "intersect", "miss", "process_hit", "shadow_test", "light_contribution",
                    "sample_bsdf", "compact_count", "compact_scatter")
SHADING_REGISTERS = 64
TRAVERSAL_REGISTERS = 96
TRAVERSAL_STACK = 256


def _order(kernel: str) -> tuple[int, str]:
    return (ORDER.index(kernel) if kernel in ORDER else len(ORDER), kernel)


def rows(report: IsaReport) -> list[list[str]]:
    """One row a kernel: per target, registers / stack (B) / spills / resident warps or waves, of the
    variant with the most registers over every scene and option set."""
    worst = report.worst()
    kernels = sorted({k for k, _ in worst}, key=_order)
    out = []
    for k in kernels:
        row = [k]
        for t in TARGETS:
            c = worst.get((k, t))
            if c is None:
                row.append("-")
                continue
            spill = f", spills {c.spill_stores}" if c.spills else ""
            cap = f" (cap {c.register_cap})" if c.register_cap else ""
            row.append(f"{c.registers} r{cap}, {c.stack} B{spill}, {c.slots} ({c.occupancy:.0%})")
        out.append(row)
    return out


def header() -> list[str]:
    return ["kernel", *(f"{t.name}: regs, stack, {t.slot_word} (occupancy)" for t in TARGETS.values())]


def shading_within_budget(c: KernelCost) -> bool:
    """A shading stage's budget on sm_90: at most SHADING_REGISTERS registers without spilling (under the driver's
    register cap, pyclpt.gpu.isa.register_cap, spills are what meeting it would cost). The stack is reported beside
    it: the stages have no private arrays, and under the cap ptxas may keep a few bytes of frame around the call of
    IEEE division's slow path (docs/gpu.md, "The shading stages in steps")."""
    return c.registers <= SHADING_REGISTERS and not c.spills


def budgets(report: IsaReport) -> list[str]:
    """The issue's budgets on sm_90 and the spill rule on gfx1030, each met or not, in words."""
    worst = report.worst()
    lines = []
    for k in SHADING_STAGES:
        c = worst.get((k, "sm_90"))
        if c:
            ok = "met" if shading_within_budget(c) else "missed"
            where = f"; worst in {', '.join(c.scenes)}" if c.scenes else ""
            cap = f", cap {c.register_cap}" if c.register_cap else ""
            lines.append(f"{k}: {c.registers} registers, {c.stack} B stack, {c.spill_stores} B spilled on sm_90{cap} "
                         f"(budget {SHADING_REGISTERS} without spills: {ok}{where})")
    for k in TRAVERSAL_STAGES:
        c = worst.get((k, "sm_90"))
        if c:
            ok = "met" if c.registers <= TRAVERSAL_REGISTERS and c.stack <= TRAVERSAL_STACK else "missed"
            lines.append(f"{k}: {c.registers} registers, {c.stack} B stack on sm_90 (budget {TRAVERSAL_REGISTERS}, "
                         f"{TRAVERSAL_STACK} B: {ok})")
    spilling = sorted({c.kernel for c in report.costs if c.target == "gfx1030" and c.spills}, key=_order)
    stages = [k for k in spilling if k in WAVEFRONT_STAGES]  # the rule: no wavefront stage spills
    lines.append("gfx1030 spills among the wavefront stages: " + (", ".join(stages) if stages else "none"))
    others = [k for k in spilling if k not in WAVEFRONT_STAGES]
    lines.append("gfx1030 spills elsewhere (no budget): " + (", ".join(others) if others else "none"))
    return lines


def markdown(report: IsaReport) -> str:
    """The table, the budgets and the failures, as Markdown."""
    head = header()
    lines = [f"Toolchain: {report.toolchain}. Scenes: {', '.join(report.scenes)}. {report.programs} distinct "
             f"programs; compiled after deduplication: "
             + ", ".join(f"{n} for {t}" for t, n in report.compiled.items()) + ".", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in rows(report)]
    lines += ["", *(f"- {b}" for b in budgets(report))]
    if report.failures:
        lines += ["", f"**{len(report.failures)} failures:**"]
        lines += [f"- {f.program} for {f.target} (scenes {', '.join(f.scenes)}): {f.message.splitlines()[0]}"
                  for f in report.failures]
    return "\n".join(lines) + "\n"


def _matplotlib():
    """matplotlib (not a dependency of pyclpt: the ``gpu`` and ``bench`` extras), or an ImportError naming
    the extra."""
    try:
        import matplotlib
    except ImportError as exc:
        raise ImportError(f"the GPU ISA check's plot (isa.png) needs matplotlib, which is not installed here "
                          f'({exc}): pip install "pyclpt[gpu]"') from None
    return matplotlib


def plot(report: IsaReport, path: str | Path) -> Path:
    """Bars of each kernel's theoretical occupancy per target (the worst variant), saved to ``path``."""
    matplotlib = _matplotlib()
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    worst = report.worst()
    kernels = sorted({k for k, _ in worst}, key=_order)
    fig, ax = plt.subplots(figsize=(max(6.0, 0.45 * len(kernels)), 3.6))
    width = 0.8 / len(TARGETS)
    for j, t in enumerate(TARGETS):
        ys = [worst[(k, t)].occupancy if (k, t) in worst else 0.0 for k in kernels]
        ax.bar([i + j * width for i in range(len(kernels))], ys, width, label=t)
    ax.set_xticks([i + 0.4 - width / 2 for i in range(len(kernels))], kernels, rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("theoretical occupancy")
    ax.set_ylim(0, 1.05)
    ax.legend(fontsize=7)
    ax.set_title("pyclpt kernels on GPU instruction sets (worst variant)", fontsize=9)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def default_scenes() -> list[Scene | str]:
    """The built-in scenes whose files are at hand (loaded) and the shared scenes (``PYCLPT_SCENES``; their
    paths): what ``pyclpt gpu-isa`` checks without arguments."""
    from pyclpt.scene.library import builtin_scenes, load, scenes_root

    scenes: list[Scene | str] = []
    for name in builtin_scenes():
        try:
            scenes.append(load(name))
        except (OSError, ValueError):  # a built-in whose mesh lives in the shared folder, absent here
            continue
    root = scenes_root()
    if root is not None:
        scenes += [str(p) for p in sorted(root.glob("*/scene.xml"))]
    return scenes


def run(scenes: list[Scene | str], out_dir: str | Path, *, targets: list[str] | None = None, every_variant: bool = True,
        device: str | None = None) -> IsaReport:
    """Collect, compile and write ``isa.json``, ``isa.md`` and ``isa.png`` into ``out_dir``."""
    from pyclpt.gpu.check import check_programs
    from pyclpt.gpu.collect import collect_programs
    from pyclpt.gpu.isa import find_toolchain

    toolchain = find_toolchain()  # before the collection: missing tools are named at once
    _matplotlib()  # and so is a missing plotting library
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = check_programs(collect_programs(scenes, device=device, every_variant=every_variant),
                            targets or list(TARGETS), toolchain=toolchain)
    report.save(out / "isa.json")
    (out / "isa.md").write_text(markdown(report))
    plot(report, out / "isa.png")
    return report
