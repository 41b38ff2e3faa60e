"""Where each differentiable parameter lives in the device buffers that the gradient kernels read
and write (``cl/gradients/params.h``): a gradient or a tangent has the layout of the scene buffers.

:func:`parameter_slots` gives, for a parameter, the buffer (``mats``, ``lights``, ``tex8``, ``tex32``,
``verts``, ``lightpos``, ``camera``, ``vnormals``) and an index array of shape (K, *value shape): the K device
slots that hold each element of the value (an area light's radiance is in the record of each of its triangles, a
grey texel in the three colour channels of its RGBA texel; -1: no slot). A gradient sums the K slots; a tangent
writes all K. The slots are recomputed after every update, since texture formats and offsets can change. Where
things are (``-DGRAD_GEOMETRY``): ``verts``, 3 floats per vertex of the packed vertex arrays (a mesh's
``vertex_positions``), ``lightpos``, 6 floats per light record (a point or spot light's position, a spot light's
axis: :func:`spot_gradient`), ``camera``, the camera's origin and basis (12 floats; ``-DGRAD_CAMERA``: the
sensor's ``to_world`` and ``x_fov``, chained on the host), and ``vnormals``, 3 floats per vertex as ``verts``:
its vertex normal (a smooth-shaded mesh's; chained on the host to the positions through the normals ``update()``
computes, :mod:`pyclpt.gradients.normals`), and ``inst``, 12 floats per instance record of an instanced scene
(``-DGRAD_INSTANCES``: an instance's ``to_world``, :func:`instance_gradient`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pyclpt.buffers.lights import (
    ENV_TEXTURE,
    LIGHT_CONSTANT,
    LIGHT_ENVMAP,
    LIGHT_PRIM,
    LIGHT_RADIANCE,
    LIGHT_STRIDE,
    LIGHT_TRIANGLE,
    LIGHT_TYPE,
)
from pyclpt.buffers.materials import MAT_ALPHA, MAT_COLOR, MAT_SPEC, MAT_STRIDE, TEXF_FLOAT
from pyclpt.buffers.scene import SceneArrays, scene_meshes
from pyclpt.gradients.parameters import Parameter
from pyclpt.gradients.placement import spot_pose
from pyclpt.scene.model import Bitmap, Envmap, Mesh, PointLight, Scene, SpotLight

#: Floats per light record in ``lightpos`` (geometry.h's GEO_LIGHT_STRIDE): its position, a spot light's axis.
LIGHTPOS_STRIDE = 6

BUFFERS = ("mats", "lights", "tex8", "tex32", "verts", "lightpos", "camera", "vnormals", "inst")

#: Floats per instance record in ``inst`` (geometry.h's GEO_INST_STRIDE): its to_world's 3x3 by columns, then its
#: translation.
INST_STRIDE = 12


@dataclass
class Slots:
    buffer: str  # one of BUFFERS
    index: np.ndarray  # (K, *value shape) int64 indices into the buffer (floats), -1 for none

    def gather(self, buffers: dict[str, np.ndarray]) -> np.ndarray:
        """The value's gradient: the sum over its K slots."""
        data = buffers[self.buffer]
        return np.where(self.index >= 0, data[np.maximum(self.index, 0)], 0.0).sum(axis=0, dtype=np.float64)

    def scatter(self, buffers: dict[str, np.ndarray], value: np.ndarray) -> None:
        """Write a tangent: every slot of each element gets the element's value."""
        full = np.broadcast_to(np.asarray(value, np.float32), self.index.shape)
        ok = self.index >= 0
        buffers[self.buffer][self.index[ok]] = full[ok]


def texture_slots(arrays: SceneArrays, tex_id: int, channels: int) -> Slots:
    rec = arrays.textures.info()[tex_id]
    width, height = int(rec[2]), int(rec[3])
    offset = int(np.float32(rec[4]).view(np.int32))
    base = 4 * (offset + np.arange(width * height, dtype=np.int64)).reshape(height, width)
    rgba = {1: [[0, 1, 2]], 2: [[0, 1, 2], []], 3: [[0], [1], [2]], 4: [[0], [1], [2], []]}[channels]
    k = max(len(c) for c in rgba)
    index = np.full((k, height, width, channels), -1, np.int64)
    for c, sources in enumerate(rgba):
        for j, src in enumerate(sources):
            index[j, :, :, c] = base + src
    return Slots("tex32" if int(rec[1]) == TEXF_FLOAT else "tex8", index)


def mesh_light_records(scene: Scene, arrays: SceneArrays, mesh: Mesh) -> np.ndarray:
    """The light records of a mesh's emissive triangles."""
    start = 0
    for m in scene.meshes:
        if m is mesh:
            break
        start += m.triangle_count
    order = arrays.bvh.tri_order
    leaf = np.flatnonzero((order >= start) & (order < start + mesh.triangle_count))
    lights = arrays.lights.tri_light[leaf]
    return lights[lights >= 0].astype(np.int64)


def vertex_offset(scene: Scene, mesh: Mesh) -> int:
    """The index of a mesh's first vertex in the packed vertex arrays (the ``verts`` buffer's order)."""
    offset = 0
    for m in scene_meshes(scene):
        if m is mesh:
            return offset
        offset += m.positions.shape[0]
    raise ValueError(f"mesh {mesh.name!r} is not in scene {scene.name!r}")


def light_record(scene: Scene, arrays: SceneArrays, light: object) -> int:
    """The record in ``lights`` of one of ``scene.lights`` (-1: none, it emits nothing): the emitters after the
    triangles, in the scene's order, those with no power left out (pyclpt/buffers/lights.py)."""
    types = arrays.lights.lights[:, LIGHT_TYPE].astype(np.int64)
    records = np.flatnonzero((types != LIGHT_TRIANGLE) & (types != LIGHT_CONSTANT) & (types != LIGHT_ENVMAP))
    j = 0
    for other in scene.lights:
        value = other.irradiance if hasattr(other, "irradiance") else other.intensity
        if not max(value) > 0:
            if other is light:
                return -1
            continue
        if other is light:
            return int(records[j])
        j += 1
    raise ValueError("the light is not in the scene")


def parameter_slots(scene: Scene, arrays: SceneArrays, p: Parameter) -> Slots:
    """The device slots of differentiable parameter ``p`` in ``arrays`` (packed from ``scene``)."""
    rgb = np.arange(3, dtype=np.int64)
    if p.kind in ("color", "spec") and isinstance(p.target, Bitmap):
        tex_id = arrays.textures.index(p.target)
        if tex_id is None:
            raise ValueError(f"{p.name}: the texture is not on the device")
        return texture_slots(arrays, tex_id, p.target.pixels.shape[2])
    if p.kind in ("color", "spec"):
        slot = MAT_COLOR if p.kind == "color" else MAT_SPEC
        return Slots("mats", (MAT_STRIDE * p.material + slot + rgb)[None])
    if p.kind == "alpha":
        return Slots("mats", np.array([[MAT_STRIDE * p.material + MAT_ALPHA]], np.int64))
    if p.kind == "emission":
        assert isinstance(p.target, Mesh)
        records = mesh_light_records(scene, arrays, p.target)
        return Slots("lights", LIGHT_STRIDE * records[:, None] + LIGHT_RADIANCE + rgb[None, :])
    if p.kind == "env":
        env = arrays.lights.env_light
        if isinstance(p.target, Envmap):
            if env < 0:  # a black map is no emitter
                return Slots("tex32", np.full((1, *p.target.pixels.shape), -1, np.int64))
            at = int(arrays.lights.lights[env, LIGHT_PRIM:LIGHT_PRIM + 1].view(np.int32)[0])
            tex_id = int(arrays.lights.light_data[at + ENV_TEXTURE])
            return texture_slots(arrays, tex_id, 3)
        if env < 0:
            return Slots("lights", np.full((1, 3), -1, np.int64))
        return Slots("lights", (LIGHT_STRIDE * env + LIGHT_RADIANCE + rgb)[None])
    if p.kind == "geometry" and isinstance(p.target, Mesh) and p.name.endswith(".vertex_positions"):
        first = 3 * vertex_offset(scene, p.target)
        return Slots("verts", (first + np.arange(p.target.positions.size, dtype=np.int64))[None])
    if p.kind == "geometry" and isinstance(p.target, PointLight):
        record = light_record(scene, arrays, p.target)
        return Slots("lightpos", (LIGHTPOS_STRIDE * record + rgb if record >= 0 else np.full(3, -1, np.int64))[None])
    if p.kind == "geometry":
        raise ValueError(f"{p.name}: a pose's gradient is its vertices' (pyclpt.gradients.differentiate chains it)")
    raise ValueError(f"{p.name} is not differentiable: {p.reason}")


def buffer_sizes(arrays: SceneArrays) -> dict[str, int]:
    """Floats in each gradient buffer (the layout of the scene buffers)."""
    return {"mats": arrays.materials.size, "lights": arrays.lights.lights.size,
            "tex8": arrays.textures.texels8().size, "tex32": arrays.textures.texels32().size,
            "verts": arrays.vnormals.size, "lightpos": LIGHTPOS_STRIDE * arrays.lights.lights.shape[0], "camera": 12,
            "vnormals": arrays.vnormals.size,
            "inst": 0 if arrays.instance_order is None else INST_STRIDE * len(arrays.instance_order)}


def instance_record(arrays: SceneArrays, k: int) -> int:
    """The record (top-level leaf order) of ``scene.instances[k]`` in ``arrays`` (packed again at every update)."""
    order = arrays.instance_order
    if order is None:
        raise ValueError("the scene has no instances")
    return int(np.flatnonzero(np.asarray(order) == k)[0])


def instance_gradient(arrays: SceneArrays, k: int, inst: np.ndarray) -> np.ndarray:
    """(4, 4) float64: the gradient of ``scene.instances[k].to_world`` from its record's 12 floats in ``inst`` (the
    3x3's columns, then the translation); the bottom row moves nothing."""
    r = instance_record(arrays, k)
    g = np.asarray(inst[INST_STRIDE * r:INST_STRIDE * (r + 1)], np.float64).reshape(4, 3)
    out = np.zeros((4, 4))
    out[:3, :4] = g.T
    return out


def instance_tangent(arrays: SceneArrays, k: int, tangent: np.ndarray, inst: np.ndarray) -> None:
    """Writes into ``inst`` (the tangent buffer) a tangent (4, 4) of ``scene.instances[k].to_world``:
    :func:`instance_gradient`'s forward mode."""
    r = instance_record(arrays, k)
    t = np.asarray(tangent, np.float64).reshape(4, 4)
    inst[INST_STRIDE * r:INST_STRIDE * (r + 1)] = t[:3, :4].T.reshape(-1)


def spot_gradient(scene: Scene, arrays: SceneArrays, light: SpotLight, lightpos: np.ndarray) -> np.ndarray:
    """(4, 4) float64: the gradient of a spot light's ``to_world`` from its record's adjoints in ``lightpos`` (the
    position's, the axis's): the translation column, and the third column (the axis is its direction) through the
    normalisation; the other columns move nothing the kernels see (untextured)."""
    out = np.zeros((4, 4))
    record = light_record(scene, arrays, light)
    if record < 0:
        return out
    g = np.asarray(lightpos[LIGHTPOS_STRIDE * record:LIGHTPOS_STRIDE * record + 6], np.float64)
    z = spot_pose(light)[:3, 2]
    a = z / np.linalg.norm(z)
    out[:3, 3] = g[:3]
    out[:3, 2] = (g[3:] - a * (a @ g[3:])) / np.linalg.norm(z)
    return out


def spot_tangent(scene: Scene, arrays: SceneArrays, light: SpotLight, tangent: np.ndarray, lightpos: np.ndarray
                 ) -> None:
    """Writes into ``lightpos`` (the tangent buffer) the motion of a spot light's position and axis along a tangent
    (4, 4) of its ``to_world``: :func:`spot_gradient`'s forward mode."""
    record = light_record(scene, arrays, light)
    if record < 0:
        return
    t = np.asarray(tangent, np.float64).reshape(4, 4)
    z = spot_pose(light)[:3, 2]
    a = z / np.linalg.norm(z)
    dz = t[:3, 2]
    lightpos[LIGHTPOS_STRIDE * record:LIGHTPOS_STRIDE * record + 3] = t[:3, 3]
    lightpos[LIGHTPOS_STRIDE * record + 3:LIGHTPOS_STRIDE * record + 6] = (dz - a * (a @ dz)) / np.linalg.norm(z)
