"""Every OpenCL program the renderer builds for a scene, collected without compiling it for the CPU.

For each scene, the objects a user can make are made on a device of their own inside
:func:`pyclpt.device.program.record_programs` (``dry``): the megakernel and the wavefront in both
path-state layouts, with and without the G-buffer, the film in each accumulation precision, the
progressive renderer with each denoiser (SVGF's passes, the blend), and the gradient kernels (reverse
and forward mode, every parameter kind at once). Their programs are recorded as they would be built,
with the defines of the device class the check is for (``device_class="gpu"``: the BVH layout a
GPU gets), and deduplicated by text and options across scenes.
"""
from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterable

from pyclpt.device.context import Device, open_device
from pyclpt.device.program import ProgramSource, record_programs
from pyclpt.film.accumulator import PRECISIONS
from pyclpt.gradients.replay import GRAD_DEFINES, PathReplay
from pyclpt.rendering.progressive import ProgressiveRenderer
from pyclpt.rendering.renderer import Renderer
from pyclpt.scene.library import load
from pyclpt.scene.model import ReconstructionFilter, Scene

log = logging.getLogger("pyclpt.gpu.collect")

#: The image the objects are made for: small, since nothing is rendered.
SIZE = 8


def _scene(item: Scene | str) -> Scene:
    return item if isinstance(item, Scene) else load(item)


def scene_programs(scene: Scene, device: Device, every_variant: bool = True, wavefront: bool = True) -> None:
    """Make every kind of object that builds programs for ``scene`` on ``device`` (inside a dry
    record_programs block: nothing is rendered). ``every_variant`` False leaves out the variants whose
    code another one holds (the integrators without the G-buffer: -DAOVS only adds code) and those whose
    code does not depend on the scene (the AoS path state, the other accumulation precisions, the
    progressive renderer's denoisers). ``wavefront`` False leaves out the wavefront's stages (their shading
    and traversal code is the megakernel's, with the same defines)."""
    kw = dict(width=SIZE, height=SIZE, device=device, max_depth=4)
    layouts = ("soa", "aos") if every_variant else ("soa",)  # the path-state accessors: no scene defines
    for integrator, layout in (("megakernel", "soa"), *(("wavefront", lay) for lay in layouts if wavefront)):
        for aovs in (None, True) if every_variant else (True,):
            Renderer(scene, integrator=integrator, layout=layout, aovs=aovs, **kw)
    for precision in PRECISIONS if every_variant else ():
        Renderer(scene, precision=precision, **kw)
    for kind in ("tent", "gaussian") if every_variant else ():
        # the splatting film's kernels (film/splat.cl) and the camera's filter importance sampling (film/rfilter.h)
        for estimator in ("splat", "importance"):
            rfilter = ReconstructionFilter(kind, estimator=estimator)
            Renderer(dataclasses.replace(scene, film=dataclasses.replace(scene.film, rfilter=rfilter)), **kw)
    for denoiser in ("svgf", "blend") if every_variant else ():
        ProgressiveRenderer(scene, denoiser=denoiser, **kw)
    r = Renderer(scene, **kw)
    replay = PathReplay(device, r.scene_buffers, SIZE, SIZE, 4)
    # where things are, instances' to_world (-DGRAD_INSTANCES) in instanced scenes (pyclpt.gradients.parameters)
    kinds = [k for k in GRAD_DEFINES if k != "instance" or scene.instances]
    for name in ("backward", "forward"):
        replay.kernel(name, kinds)
    replay.kernel("edge_radiance")  # the boundary term of primary visibility (pyclpt.gradients.edges)
    replay.kernel("path_vertices")  # ... of soft shadows (pyclpt.gradients.shadows): the shading points
    replay.kernel("vertex_radiance")  # ... their silhouette search and the radiance either side
    replay.kernel("delta_shadow_sides")  # ... hard shadows' outlines after a bounce


def collect_programs(scenes: Iterable[Scene | str], *, device_class: str | None = "gpu",
                     device: str | None = None, every_variant: bool = True, first_every: bool = True,
                     wavefront: bool = True) -> list[tuple[ProgramSource, list[str]]]:
    """The distinct programs the renderer builds for ``scenes`` (Scenes, built-in names or files), each
    with the names of the scenes that build it, in the order first met. ``device_class``: the class the
    programs are shaped for (None: the device's own). ``every_variant`` False: after the first scene, only
    the variants that hold the most code (with the G-buffer; one precision; see scene_programs), and from
    the first scene on with ``first_every`` False;
    ``wavefront`` False: without the wavefront's stages."""
    found: dict[tuple, tuple[ProgramSource, list[str]]] = {}
    dev = open_device(device)  # its own device: the dry programs never meet a renderer's
    dev.class_override = device_class
    for k, item in enumerate(scenes):
        scene = _scene(item)
        with record_programs(dry=True) as programs:
            scene_programs(scene, dev, every_variant=every_variant or (first_every and k == 0),
                           wavefront=wavefront)
        for p in programs:
            entry = found.setdefault(p.key, (p, []))
            if scene.name not in entry[1]:
                entry[1].append(scene.name)
        log.info("%s: %d programs, %d distinct so far", scene.name, len(programs), len(found))
    return list(found.values())


#: The defines that say which kinds a scene has, as bit masks (cl/scene/lights.h, cl/scene/bsdf.h): a program
#: built with the OR of two scenes' masks holds the code of both.
MASK_DEFINES = ("SCENE_LIGHTS", "SCENE_MATERIALS")
#: The defines that switch one feature's code on: the scene's ``SCENE_HAS_*`` (pyclpt/buffers/scene.py) and the
#: gradients' kinds, ``GRAD_*`` (pyclpt.gradients.replay.GRAD_DEFINES).
FLAG_PREFIXES = ("SCENE_HAS_", "GRAD_")


def _define(option: str) -> tuple[str, str | None] | None:
    if not option.startswith("-D"):
        return None
    name, _, value = option[2:].partition("=")
    return name, value or None


def merge_specialisations(programs: Iterable[tuple[ProgramSource, list[str]]]) -> list[tuple[ProgramSource, list[str]]]:
    """``programs`` (collect_programs' list) with each kernel's scene specialisations switched on together:
    the programs of the same source whose options differ only in the kind masks (``MASK_DEFINES``: OR-ed) and
    the feature flags (``FLAG_PREFIXES``: the scene's features, the gradients' kinds; their union) become one program,
    which holds the code of every one of them and names all their scenes. Every other option (the camera kind, the
    G-buffer, the rigid-geometry switch, the BVH layout) still tells programs apart. What is compiled is a superset of
    each merged program's code but for code that a define turns *off* (the texture-free or environment-free paths),
    which a scene without the feature among the unmerged programs keeps compiled (the GPU ISA test: the Cornell box's
    every variant).
    The GPU ISA test compiles the scenes beyond the box this way, in half the programs."""
    programs = list(programs)
    # (label, text, the other options, the mask names) -> (the masks OR-ed, the flags, the scenes)
    groups: dict[tuple, tuple[dict[str, int], list[str], list[str]]] = {}
    for p, names in programs:
        rest: list[str] = []
        masks: dict[str, int] = {}
        flags: list[str] = []
        for o in p.options:
            d = _define(o)
            if d and d[0] in MASK_DEFINES and d[1] is not None:
                masks[d[0]] = int(d[1], 0)
            elif d and d[0].startswith(FLAG_PREFIXES):
                flags.append(o)
            else:
                rest.append(o)
        key = (p.label, p.text, tuple(rest), tuple(sorted(masks)))
        merged, all_flags, scenes = groups.setdefault(key, ({}, [], []))
        for k, v in masks.items():
            merged[k] = merged.get(k, 0) | v
        all_flags.extend(f for f in flags if f not in all_flags)
        scenes.extend(n for n in names if n not in scenes)
    out = []
    for (label, text, rest, _), (masks, flags, names) in groups.items():
        options = (*rest, *sorted(flags), *(f"-D{k}={v}" for k, v in sorted(masks.items())))
        out.append((ProgramSource(label, text, options), names))
    log.info("%d programs merged into %d by their scene specialisations", len(programs), len(out))
    return out
