"""Compiling the kernels of the built-in scenes before their first render (``pyclpt warmup``).

A render's programs are specialised for its scene (``-D`` options: the material and light kinds, the
camera, the filter, the BVH layout; pyclpt/buffers/scene.py) and built through
:func:`pyclpt.device.program.build_program`. The OpenCL drivers keep what they compile on disk, keyed
by the program's text and options: PoCL in its kernel cache (``$XDG_CACHE_HOME/pocl/kcache``, or
``POCL_CACHE_DIR``), NVIDIA's in its own, the others (Intel's CPU runtime) through pyopencl's binary
cache (``$XDG_CACHE_HOME/pyopencl``).
PoCL also compiles each kernel again at its first launch for the work-group size and for a small or a
large grid, so warming up *renders* one sample per pixel of each scene at the scene's own resolution,
exactly as ``pyclpt render`` would make it: a later first render of the scene, in any process, then
finds every program and every launch variant in those caches.

:func:`warm_up` makes a :class:`~pyclpt.rendering.progressive.ProgressiveRenderer` per scene and
variant (``megakernel``; ``wavefront``; with ``aovs``, the G-buffer and the SVGF denoiser that
``--aov`` and ``--denoise`` use) and returns what each built and how long it took.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from pyclpt.device.context import Device, get_device
from pyclpt.device.program import record_programs
from pyclpt.rendering.progressive import ProgressiveRenderer
from pyclpt.scene.library import builtin_scenes, load

#: The variants :func:`warm_up` knows: (integrator, with the G-buffer and the SVGF denoiser).
VARIANTS: dict[str, tuple[str, bool]] = {
    "megakernel": ("megakernel", False),
    "wavefront": ("wavefront", False),
    "megakernel+aovs": ("megakernel", True),
    "wavefront+aovs": ("wavefront", True),
}


@dataclass(frozen=True)
class Warmed:
    """One scene and variant warmed up: ``programs`` the distinct programs its renderer asked
    :func:`~pyclpt.device.program.build_program` for, ``built`` those of them that no scene or variant
    warmed before it in this process had built (the others are the same programs: same text and options);
    ``compile_seconds`` what ``pyclpt render`` reports as compile (the builds and the first launches:
    a fraction of a second once the drivers' caches hold them); ``render_seconds`` the one-sample
    render (on PoCL, the large-grid variant of each kernel compiles there); ``seconds`` all of it,
    scene loading included."""

    scene: str
    variant: str
    programs: int
    built: int
    compile_seconds: float
    render_seconds: float
    seconds: float


@dataclass(frozen=True)
class Skipped:
    """A built-in scene that could not be loaded here (its meshes live in the shared scene folder)."""

    scene: str
    reason: str


def variants(wavefront: bool = False, all_variants: bool = False) -> list[str]:
    """The variants to warm up: the megakernel (what ``pyclpt render`` uses by default); with
    ``wavefront`` the wavefront too; with ``all_variants`` both, each also with the G-buffer and the
    SVGF denoiser."""
    if all_variants:
        return list(VARIANTS)
    return ["megakernel", "wavefront"] if wavefront else ["megakernel"]


def warm_up(scenes: Sequence[str] | None = None, *, device: Device | str | None = None,
            variant_names: Iterable[str] = ("megakernel",),
            on_result: Callable[[Warmed | Skipped], None] | None = None) -> list[Warmed | Skipped]:
    """Render one sample per pixel of each scene (built-in names or scene files; None: every built-in
    scene, those whose meshes are missing skipped) in each variant (:data:`VARIANTS`) on ``device``,
    so that the drivers' disk caches hold their programs. ``on_result`` is called with each result as
    it comes. A scene named in ``scenes`` that cannot be loaded raises."""
    names = list(variant_names)
    unknown = [v for v in names if v not in VARIANTS]
    if unknown:
        raise ValueError(f"unknown warm-up variant {unknown[0]!r}: expected one of {', '.join(VARIANTS)}")
    dev = get_device(device)
    results: list[Warmed | Skipped] = []

    def report(item: Warmed | Skipped) -> None:
        results.append(item)
        if on_result is not None:
            on_result(item)

    for name in scenes if scenes is not None else list(builtin_scenes()):
        start = time.perf_counter()
        try:
            scene = load(name)
        except FileNotFoundError as exc:
            if scenes is not None:
                raise
            report(Skipped(name, str(exc).splitlines()[0].split(", but ")[0]))
            continue
        for variant in names:
            integrator, aovs = VARIANTS[variant]
            known = set(dev.programs)
            with record_programs() as programs:
                pr = ProgressiveRenderer(scene, integrator=integrator, device=dev,
                                         denoiser="svgf" if aovs else None)
                pr.run(1, progress=False)
            report(Warmed(scene.name, variant, len(programs), len(set(dev.programs) - known),
                          pr.stats.compile_seconds, pr.stats.seconds, time.perf_counter() - start))
            start = time.perf_counter()
    return results
