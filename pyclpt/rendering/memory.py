"""The memory a render needs, estimated before anything is allocated.

Every device buffer is checked on its own against CL_DEVICE_MAX_MEM_ALLOC_SIZE when it is made
(:func:`pyclpt.device.context.check_alloc`), but buffers that each pass that limit can together
exceed the device's memory, and a CPU driver (PoCL) then crashes the process or a render of many
minutes fails when its image is read back. :func:`check_render_memory` adds up what a
:class:`~pyclpt.rendering.renderer.Renderer` will allocate and checks the total first
(:func:`pyclpt.device.context.check_memory`).

Film, accumulation and path state are counted exactly (they grow with the resolution and the wave
size); the scene buffers are estimated from the scene model (triangles, vertices, textures),
without building the BVH.
"""
from __future__ import annotations

from dataclasses import fields, is_dataclass

from pyclpt.buffers.lights import guide_size
from pyclpt.device.context import Device, check_alloc, check_memory
from pyclpt.film.aovs import AOV_COUNT
from pyclpt.film.film import frames_per_batch
from pyclpt.scene.model import Bitmap, Checkerboard, Envmap, Scene

# Bytes of one value of the accumulation sum (pyclpt.film.accumulator): a float, or two words.
SUM_VALUE_BYTES = {"single": 4, "compensated": 8, "double": 8}
# Scene buffers per triangle: BVH triangle (36), info (8), vertex indices (12), BVH nodes (about
# one 64-byte binary node per 4 triangles, counted twice; 8-wide trees need less), an emitter record (32)
# and the 8-wide BVH's leaf packets in the node buffer (pyclpt.accel.bvh.leaf_packet_buffer: 320-byte
# records of 8 triangle slots; 73-91 bytes per triangle on the shared scenes, counted as 128).
LEAF_PACKET_BYTES_PER_TRIANGLE = 128
BYTES_PER_TRIANGLE = 36 + 8 + 12 + 32 + 32 + LEAF_PACKET_BYTES_PER_TRIANGLE
BYTES_PER_VERTEX = 12 + 8  # shading normal, uv
BYTES_PER_MATERIAL = 4 * 32
# An instance: its record (pyclpt.accel.instances.INST_STRIDE words) and about two top-level 8-wide nodes.
BYTES_PER_INSTANCE = 4 * 36 + 2 * 256
# The parts of render_memory() that are one buffer each (the others add up several).
FILM_BUFFERS = ("frame buffer", "accumulation sum", "accumulated image")


def _texture_bytes(tex: object) -> int:
    if isinstance(tex, Bitmap):
        return tex.width * tex.height * (4 if tex.srgb else 16)  # 8-bit RGBA, or float RGBA
    return 0


def scene_bytes(scene: Scene) -> int:
    """An estimate (from above) of the scene's device buffers."""
    groups = {i.group for i in scene.instances}  # instanced shapegroups: stored once
    meshes = [*scene.meshes, *(m for g in groups for m in scene.groups[g].meshes)]
    total = BYTES_PER_TRIANGLE * sum(m.triangle_count for m in meshes)
    total += BYTES_PER_VERTEX * sum(int(m.positions.shape[0]) for m in meshes)
    total += BYTES_PER_INSTANCE * (len(scene.instances) + 1)
    total += BYTES_PER_MATERIAL * len(scene.materials) + 64 * (len(scene.lights) + 1)
    seen: set[int] = set()
    stack: list[object] = list(scene.materials)
    while stack:  # textures reachable from the materials (through masks and bump maps), each once
        obj = stack.pop()
        if id(obj) in seen or not is_dataclass(obj):
            continue
        seen.add(id(obj))
        if isinstance(obj, (Bitmap, Checkerboard)):
            total += _texture_bytes(obj) + 80
            continue
        stack.extend(getattr(obj, f.name) for f in fields(obj))
    env = scene.environment
    if isinstance(env, Envmap):
        h, w = env.pixels.shape[:2]
        # float RGBA texels, the rows' 16-byte alias entries, the marginal CDF, cell solid angles and row cosines,
        # the marginal's guide table and the block's alignment (buffers/lights.py)
        total += 32 * h * w + 16 * (h + 16) + 4 * (guide_size(h - 1) + 1) + 64
    return total


def batch_frames(pixels: int, wave_size: int | None) -> int:
    """Frames a render's film batches (pyclpt/film/film.py): as many as the wave size (the
    wavefront's default for both integrators) holds, so that small images fill a wave."""
    from pyclpt.integrators.wavefront import DEFAULT_WAVE_SIZE

    return frames_per_batch(pixels, wave_size or DEFAULT_WAVE_SIZE)


def render_memory(scene: Scene, width: int, height: int, *, precision: str, integrator: str,
                  wave_size: int | None = None, max_depth: int = 0, aovs: bool = False,
                  scene_buffers: bool = True) -> dict[str, int]:
    """{what: bytes} of the device buffers of a render of a film of width x height (see the module
    docstring); ``scene_buffers`` False: the scene's buffers are there already (another renderer's)."""
    pixels = width * height
    batch = batch_frames(pixels, wave_size)
    # a splatting film (pyclpt/film/splat.py) renders a margin of pad pixels around its window
    pad = scene.film.rfilter.splat_reach
    tw, th = width + 2 * pad, height + 2 * pad
    traced = tw * th
    value = SUM_VALUE_BYTES.get(precision, 8)
    parts = {
        f"frame buffer {tw}x{th}" + (f", {batch} frames" if batch > 1 else ""): 12 * traced * batch,
        "dropped-sample marks": traced * batch,
        f"accumulation sum ({precision})": value * 3 * pixels,
        "accumulated image": 12 * pixels,
        "scene buffers (estimate)": scene_bytes(scene) if scene_buffers else 0,
    }
    if pad:  # its gathered frames, their weights, the per-axis weights, the weights' accumulator
        parts["splatting film"] = (16 * pixels + 8 * (2 * pad + 1) * traced) * batch + (value + 4) * pixels
    if aovs:  # pyclpt/film/aovs.py: a record per film slot, the per-pixel sums and means
        parts["G-buffer"] = 4 * AOV_COUNT * (traced * batch + 2 * pixels)
        if pad:  # the denoisers' frames (the window's own samples) and their accumulator
            parts["denoiser frames"] = 12 * pixels * batch + (3 * value + 12) * pixels
    if integrator == "wavefront":
        from pyclpt.integrators.path_state import bytes_per_path
        from pyclpt.integrators.wavefront import DEFAULT_WAVE_SIZE, Q_COUNT, QUEUE_BYTES_PER_PATH

        capacity = min(wave_size or DEFAULT_WAVE_SIZE, traced * batch)
        parts[f"path state and queues ({capacity} paths)"] = (capacity * (bytes_per_path() + QUEUE_BYTES_PER_PATH)
                                                              + 4 * (Q_COUNT + 1) * (max_depth + 2))
    return parts


def check_render_memory(device: Device, scene: Scene, width: int, height: int, *, precision: str,
                        integrator: str, wave_size: int | None = None, max_depth: int = 0,
                        aovs: bool = False, scene_buffers: bool = True) -> dict[str, int]:
    """Raise :class:`~pyclpt.device.context.DeviceMemoryError` (a MemoryError) naming what is needed,
    what is available and what to lower, unless the render fits; returns the parts counted."""
    parts = render_memory(scene, width, height, precision=precision, integrator=integrator,
                          wave_size=wave_size, max_depth=max_depth, aovs=aovs, scene_buffers=scene_buffers)
    host = {f"image read back {width}x{height}": 12 * width * height,
            "scene arrays on the host (estimate)": parts["scene buffers (estimate)"]}
    lower = ["lower the resolution (width, height)"]
    if precision != "single":
        lower.append("sum in single precision (precision='single', --precision single)")
    if integrator == "wavefront" or batch_frames(width * height, wave_size) > 1:
        lower.append("use a smaller wave_size")
    hint = "to fit, " + " or ".join(lower)
    for what in FILM_BUFFERS:  # single buffers: refused before anything is allocated, as later by alloc()
        name = next(k for k in parts if k.startswith(what))
        check_alloc(device, parts[name], name, hint)
    check_memory(device, parts, host=host, hint=hint)
    return parts
