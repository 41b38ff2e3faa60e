"""Scene model -> flat arrays -> device buffers.

All meshes are concatenated, the BVH is built over every triangle (Embree,
:mod:`pyclpt.bvh`) and the per-triangle arrays are put into the BVH's leaf
order so that kernels index everything by the triangle a traversal returns.
The layout of each array is documented in ``cl/scene.h``, ``cl/bsdf.h`` and
``cl/lights.h``; the offsets below mirror those headers.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from .bvh import FlatBVH, build_bvh
from .device import Device, upload
from .scene import Conductor, Dielectric, Diffuse, Material, Scene

MAT_STRIDE = 16
MAT_TYPES = {"diffuse": 0, "conductor": 1, "roughconductor": 2, "dielectric": 3}
LIGHT_STRIDE = 8
CONST_COUNT = 20
TRI_HAS_NORMALS = 1 << 24
TRI_HAS_UVS = 1 << 25


def luminance(c) -> float:
    r, g, b = (float(x) for x in c)  # in double: radiance near FLT_MAX must not overflow
    return 0.212671 * r + 0.715160 * g + 0.072169 * b


def pack_material(mat: Material) -> np.ndarray:
    rec = np.zeros(MAT_STRIDE, np.float32)
    if isinstance(mat, Diffuse):
        rec[0] = MAT_TYPES["diffuse"]
        rec[2:5] = mat.reflectance
    elif isinstance(mat, Conductor):
        rec[0] = MAT_TYPES["roughconductor" if mat.alpha > 0 else "conductor"]
        rec[2:5] = mat.specular_reflectance
        rec[5:8] = mat.eta
        rec[8:11] = mat.k
        rec[11] = mat.alpha
    elif isinstance(mat, Dielectric):
        rec[0] = MAT_TYPES["dielectric"]
        rec[2:5] = mat.specular_reflectance
        rec[5] = mat.int_ior / mat.ext_ior
        rec[12:15] = mat.specular_transmittance
    else:
        raise TypeError(f"unsupported material {mat!r}")
    rec[1] = 1.0 if getattr(mat, "twosided", False) else 0.0
    return rec


@dataclass
class SceneArrays:
    """The scene as the flat arrays the kernels read (host copies)."""

    bvh: FlatBVH
    tri_info: np.ndarray  # (T, 2) int32
    tri_vidx: np.ndarray  # (T, 3) int32
    vnormals: np.ndarray  # (V, 3) float32
    vuvs: np.ndarray  # (V, 2) float32
    materials: np.ndarray  # (M, MAT_STRIDE) float32
    lights: np.ndarray  # (L, LIGHT_STRIDE) float32
    env_light: int  # index of the environment in lights, or -1
    bounds: np.ndarray  # (2, 3) scene bounding box

    @property
    def triangle_count(self) -> int:
        return int(self.tri_info.shape[0])

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.bvh.nodes, self.bvh.tris, self.tri_info, self.tri_vidx,
                                      self.vnormals, self.vuvs, self.materials, self.lights))


def pack_scene(scene: Scene) -> SceneArrays:
    positions, indices, normals, uvs, info, emission = [], [], [], [], [], []
    offset = 0
    for mesh in scene.meshes:
        positions.append(mesh.positions)
        indices.append(mesh.indices + offset)
        nv = mesh.positions.shape[0]
        normals.append(mesh.normals if mesh.normals is not None else np.zeros((nv, 3), np.float32))
        uvs.append(mesh.uvs if mesh.uvs is not None else np.zeros((nv, 2), np.float32))
        flags = (TRI_HAS_NORMALS if mesh.normals is not None else 0) | (TRI_HAS_UVS if mesh.uvs is not None else 0)
        info.append(np.full(mesh.triangle_count, mesh.material | flags, np.int32))
        em = mesh.emission if mesh.emission is not None and max(mesh.emission) > 0 else (0.0, 0.0, 0.0)
        emission.append(np.tile(np.asarray(em, np.float32), (mesh.triangle_count, 1)))
        offset += nv
    P = np.concatenate(positions)
    I = np.concatenate(indices)
    bvh = build_bvh(P, I)
    order = bvh.tri_order
    tri_emission = np.concatenate(emission)[order]
    tri_info = np.empty((len(order), 2), np.int32)
    tri_info[:, 0] = np.concatenate(info)[order]
    tri_info[:, 1] = -1

    # Emitters: emissive triangles (leaf order) then the environment, chosen by power.
    emissive = np.flatnonzero(tri_emission.max(axis=1) > 0)
    tris = bvh.tris.reshape(-1, 9)
    area = 0.5 * np.linalg.norm(np.cross(tris[emissive, 3:6], tris[emissive, 6:9]), axis=1)
    keep = area > 0
    emissive, area = emissive[keep], area[keep]
    em64 = tri_emission[emissive].astype(np.float64)  # double: radiance near FLT_MAX must not overflow
    lum = np.maximum(em64 @ np.array([0.212671, 0.715160, 0.072169]), em64.mean(axis=1))
    power = list(area * lum)
    bounds = np.stack([P.min(0), P.max(0)])
    env_light = -1
    if scene.environment is not None and max(scene.environment) > 0:
        radius = 0.5 * float(np.linalg.norm(bounds[1] - bounds[0]))
        env_light = len(emissive)
        power.append(np.pi * np.pi * max(radius, 1e-3) ** 2 *
                     max(luminance(scene.environment), float(np.mean(scene.environment, dtype=np.float64))))
    power_arr = np.asarray(power, np.float64)
    lights = np.zeros((len(power_arr), LIGHT_STRIDE), np.float32)
    if len(power_arr):
        pmf = power_arr / power_arr.sum()
        cdf = np.cumsum(pmf)
        cdf[-1] = 1.0
        lights[:, 1] = pmf
        lights[:, 6] = cdf
        prim = np.full(len(power_arr), -1, np.int32)
        prim[: len(emissive)] = emissive
        lights[:, 0] = prim.view(np.float32)
        lights[: len(emissive), 2] = area
        lights[: len(emissive), 3:6] = tri_emission[emissive]
        if env_light >= 0:
            lights[env_light, 3:6] = scene.environment
        tri_info[emissive, 1] = np.arange(len(emissive), dtype=np.int32)
    return SceneArrays(
        bvh=bvh,
        tri_info=tri_info,
        tri_vidx=np.ascontiguousarray(I[order]),
        vnormals=np.concatenate(normals).astype(np.float32),
        vuvs=np.concatenate(uvs).astype(np.float32),
        materials=np.stack([pack_material(m) for m in scene.materials]),
        lights=lights,
        env_light=env_light,
        bounds=bounds,
    )


def camera_consts(scene: Scene, arrays: SceneArrays, width: int, height: int) -> np.ndarray:
    c = np.zeros(CONST_COUNT, np.float32)
    origin, forward, right, up = scene.camera.basis(width, height)
    c[0:3], c[3:6], c[6:9], c[9:12] = origin, forward, right, up
    c[12], c[13] = width, height
    if scene.environment is not None:
        c[14:17] = scene.environment
    c[17] = arrays.env_light
    c[18] = arrays.lights.shape[0]
    return c


class SceneBuffers:
    """The scene's arrays on one device, plus the per-render constants (camera, film)."""

    def __init__(self, scene: Scene, device: Device) -> None:
        start = time.perf_counter()
        self.scene = scene
        self.device = device
        self.arrays = arrays = pack_scene(scene)
        self.pack_seconds = time.perf_counter() - start
        names = ("BVH nodes", "triangles", "triangle info", "triangle vertices", "vertex normals",
                 "vertex uvs", "materials", "lights")
        data = (arrays.bvh.nodes, arrays.bvh.tris, arrays.tri_info, arrays.tri_vidx, arrays.vnormals,
                arrays.vuvs, arrays.materials, arrays.lights)
        self._buffers = [upload(device, a, f"scene {scene.name!r} {n}") for n, a in zip(names, data)]
        self._consts: dict[tuple[int, int], cl.Buffer] = {}

    def args(self, width: int, height: int) -> tuple[cl.Buffer, ...]:
        """The SCENE_PARAMS kernel arguments for a film of width x height."""
        key = (width, height)
        if key not in self._consts:
            self._consts[key] = upload(self.device, camera_consts(self.scene, self.arrays, width, height),
                                       "camera constants")
        return (*self._buffers, self._consts[key])
