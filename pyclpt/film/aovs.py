"""The G-buffer (arbitrary output variables) of a film: what the integrators record beside the
radiance when a program is built with ``-DAOVS`` (``cl/integrators/gbuffer.h``), averaged per pixel
(``cl/film/aov_accumulate.cl``).

Channels (``cl/film/aovs.h`` has the same layout): the first non-specular vertex's albedo (times
the throughput of the specular chain before it), the first hit's world-space shading normal, linear
roughness, view-space depth (viewZ, 0 where the camera ray leaves the scene), the second ray's hit
distance, the screen-space motion vector to the previous frame (pixels, x right, y down), and the
first hit's emitted radiance (an emitter or the environment seen directly: the part of the radiance a
denoiser must not filter), triangle and material. A pixel's channels are the mean over its samples, in sample
order (so the megakernel and the wavefront give the same G-buffer for a seed); its ids are those of
its first sample. :class:`AovFilm` keeps one record per film slot on the device and the per-pixel
sums and means; the mean buffer is what a denoiser reads (planar floats: channel c of pixel p at
``c * pixels + p``, ids as int bits).
"""
from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import pyopencl as cl

from pyclpt.device.context import Device, alloc, fill_buffer
from pyclpt.device.program import build_program

# The channel layout of cl/film/aovs.h: name -> (first channel, EXR channel names).
AOV_LAYOUT: dict[str, tuple[int, tuple[str, ...]]] = {
    "albedo": (0, ("R", "G", "B")),
    "normal": (3, ("X", "Y", "Z")),
    "roughness": (6, ("Y",)),
    "depth": (7, ("Z",)),
    "hitdist": (8, ("Y",)),
    "motion": (9, ("X", "Y")),
    "emission": (11, ("R", "G", "B")),
    "prim_id": (14, ("Y",)),
    "material_id": (15, ("Y",)),
}
# The first channel of each, as AOV_* in cl/film/aovs.h (tests/test_aovs.py checks them against it).
AOV_ALBEDO, AOV_NORMAL, AOV_ROUGHNESS, AOV_DEPTH, AOV_HITDIST, AOV_MOTION, AOV_EMISSION, AOV_PRIM, AOV_MATERIAL = (
    AOV_LAYOUT[name][0] for name in ("albedo", "normal", "roughness", "depth", "hitdist", "motion", "emission",
                                     "prim_id", "material_id"))
AOV_COUNT = 16  # channels of a record
AOV_FLOATS = 14  # channels averaged; the rest (prim, material) are int bits
#: What a render can return: the channels above, plus the mesh a triangle belongs to (from prim_id).
AOV_NAMES = ("albedo", "normal", "roughness", "depth", "hitdist", "motion", "emission", "prim_id", "mesh_id",
             "material_id")
#: EXR channel names of every AOV (``NAME.X`` ...).
AOV_CHANNELS = {**{name: chans for name, (_, chans) in AOV_LAYOUT.items()}, "mesh_id": ("Y",)}
#: AOV_OFFSCREEN of cl/film/aovs.h: the motion of a point the previous camera did not see.
OFFSCREEN = 1.0e6


def check_aovs(aovs: object) -> tuple[str, ...]:
    """The AOV names asked for: None or False -> (), True -> every AOV, a comma-separated string or an
    iterable of names -> those, in order, without repeats; ValueError names an unknown one."""
    if aovs is None or aovs is False:
        return ()
    if aovs is True:
        return AOV_NAMES
    names = aovs.split(",") if isinstance(aovs, str) else list(aovs) if isinstance(aovs, Iterable) else None
    if names is None:
        raise TypeError(f"aovs must be a list of AOV names or True, got {type(aovs).__name__} {aovs!r}")
    out: list[str] = []
    for name in names:
        if not isinstance(name, str):
            raise TypeError(f"AOV names are strings, got {type(name).__name__} {name!r}")
        name = name.strip()
        if name not in AOV_NAMES:
            raise ValueError(f"unknown AOV {name!r}; the AOVs are {', '.join(AOV_NAMES)}")
        if name not in out:
            out.append(name)
    if not out:
        raise ValueError(f"no AOV named in {aovs!r}; the AOVs are {', '.join(AOV_NAMES)}")
    return tuple(out)


class AovFilm:
    """The G-buffer of a film of ``pixels`` pixels and ``batch`` frames a batch, on the device. ``pad``: the
    integrators render (and record) a margin of that many pixels around the film's width x height (a
    splatting film's, :mod:`pyclpt.film.splat`); the G-buffer is the window's, each pixel the mean over its
    own samples, the margin's records unused (why not splatted: docs/architecture.md, "Pixel
    filters")."""

    def __init__(self, device: Device, width: int, height: int, batch: int, pad: int = 0) -> None:
        self.device = device
        self.width, self.height = width, height
        self.pixels = width * height
        self.pad = pad
        self.traced_width = width + 2 * pad
        self.frame_pixels = self.traced_width * (height + 2 * pad)  # the records of a frame
        self.batch = batch
        self.slot_count = self.frame_pixels * batch
        self.slots = alloc(device, 4 * AOV_COUNT * self.slot_count, f"G-buffer records {width}x{height}x{batch}")
        self.sum = alloc(device, 4 * AOV_COUNT * self.pixels, f"G-buffer sums {width}x{height}")
        self.mean = alloc(device, 4 * AOV_COUNT * self.pixels, f"G-buffer {width}x{height}")
        program = build_program(device, ["film/aov_accumulate.cl"])
        self._kernel = cl.Kernel(program, "aov_accumulate")
        self.frames = 0  # frames summed since the last restart
        self.clear()

    def clear(self) -> None:
        """Start the sums over and clear the records (0; ids -1) and the per-pixel G-buffer."""
        self.frames = 0
        self.clear_slots()
        q = self.device.queue
        for buf in (self.sum, self.mean):
            fill_buffer(q, buf, np.float32(0), 0, 4 * AOV_FLOATS * self.pixels)
            fill_buffer(q, buf, np.int32(-1), 4 * AOV_FLOATS * self.pixels,
                        4 * (AOV_COUNT - AOV_FLOATS) * self.pixels)

    def clear_slots(self) -> None:
        """The records before a batch: 0, ids -1 (a path writes only what its events give)."""
        q, n = self.device.queue, self.slot_count
        fill_buffer(q, self.slots, np.float32(0), 0, 4 * AOV_FLOATS * n)
        fill_buffer(q, self.slots, np.int32(-1), 4 * AOV_FLOATS * n, 4 * (AOV_COUNT - AOV_FLOATS) * n)

    def restart(self) -> None:
        """The next batch's frames start the sums over (its records are kept): the G-buffer of one frame."""
        self.frames = 0

    def args(self) -> tuple[cl.Buffer, np.int32]:
        """The kernels' (aovs, aov_n) arguments: the records of a batch of ``batch`` frames."""
        return self.slots, np.int32(self.slot_count)

    def add_frames(self, count: int) -> cl.Event:
        """Add the records of the batch's first ``count`` frames to the sums (in frame order), update the
        means, and clear the records for the next batch."""
        total = self.frames + count
        ev = self._kernel(self.device.queue, (self.pixels,), None, self.slots, np.int32(self.slot_count),
                          np.int32(self.pixels),
                          np.int32(count), np.int32(self.frames == 0), np.int32(total), self.sum, self.mean,
                          np.int32(self.frame_pixels), np.int32(self.width), np.int32(self.traced_width),
                          np.int32(self.pad))
        self.frames = total
        self.clear_slots()
        return ev

    def read(self) -> np.ndarray:
        """The per-pixel G-buffer, (AOV_COUNT, H, W) float32 (ids as int bits: ``.view(np.int32)``)."""
        out = np.empty((AOV_COUNT, self.height, self.width), np.float32)
        cl.enqueue_copy(self.device.queue, out, self.mean)
        return out


def unpack(planes: np.ndarray, names: Iterable[str], tri_order: np.ndarray | None = None,
           mesh_starts: np.ndarray | None = None, tri_bits: int | None = None) -> dict[str, np.ndarray]:
    """Named arrays from :meth:`AovFilm.read`'s planes: (H, W, C) float32 for the vector AOVs, (H, W)
    float32 for roughness/depth/hitdist, (H, W) int32 for the ids (-1: no hit). ``tri_order`` maps the
    kernels' triangle (BVH leaf order) to the scene's (meshes concatenated), ``mesh_starts`` the first
    triangle of every mesh (for ``mesh_id``). ``tri_bits``: instanced scenes' kernels record a packed id
    (cl/scene/instances.h) whose low ``tri_bits`` bits are the triangle; the ids are then those of the
    shapegroup's triangle and mesh, the same for every instance."""
    ints = planes.view(np.int32)
    out: dict[str, np.ndarray] = {}
    for name in names:
        if name in ("prim_id", "mesh_id"):
            prim = ints[AOV_LAYOUT["prim_id"][0]]
            if tri_bits is not None:
                prim = np.where(prim >= 0, prim & ((1 << tri_bits) - 1), -1)
            if tri_order is not None:
                prim = np.where(prim >= 0, tri_order[np.clip(prim, 0, None)], -1).astype(np.int32)
            if name == "mesh_id":
                if mesh_starts is None:
                    raise ValueError("mesh_id needs the meshes' first triangles (mesh_starts)")
                prim = np.where(prim >= 0, np.searchsorted(mesh_starts, prim, side="right") - 1, -1)
            out[name] = np.ascontiguousarray(prim, np.int32)
        elif name == "material_id":
            out[name] = np.ascontiguousarray(ints[AOV_LAYOUT[name][0]])
        else:
            first, chans = AOV_LAYOUT[name]
            block = planes[first:first + len(chans)]
            out[name] = np.ascontiguousarray(block[0] if len(chans) == 1 else np.moveaxis(block, 0, -1))
    return out
