"""Scene model -> flat arrays -> device buffers.

All meshes are concatenated, the BVH is built over every triangle (Embree,
:mod:`pyclpt.accel.bvh`) and the per-triangle arrays are put into the BVH's leaf
order so that kernels index everything by the triangle a traversal returns. A scene with instances
(Mitsuba ``shapegroup`` + ``instance``) packs each instanced group's triangles once after the plain
meshes (:func:`scene_meshes`) and gets the two-level BVH of :mod:`pyclpt.accel.instances` and its
``-DSCENE_HAS_INSTANCES`` defines; the per-triangle arrays are the same.
The layout of each array is documented in ``cl/scene/scene.h``, ``cl/scene/bsdf.h`` and
``cl/scene/lights.h``; the offsets below mirror those headers.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from pyclpt.accel.bvh import (
    REBUILD_GROWTH,
    STACK_DISTANCES,
    BuildSettings,
    FlatBVH,
    box_area_ratio,
    build_bvh,
    layout_settings,
    leaf_packet_buffer,
    refit_bvh,
)
from pyclpt.accel.instances import build_instanced, instanced_node_buffer
from pyclpt.buffers.lights import LightArrays, camera_consts, camera_kind, pack_lights
from pyclpt.buffers.materials import (  # noqa: F401
    MAT_STRIDE,
    MaterialArrays,
    TextureTable,
    pack_material,
    pack_materials,
)
from pyclpt.buffers.rfilter import filter_kind
from pyclpt.device.context import Device, upload
from pyclpt.scene.model import Camera, Mesh, Scene

log = logging.getLogger("pyclpt.buffers.scene")

#: Test an 8-wide BVH's leaf triangles 8 at a time (cl/scene/bvh.h BVH_LEAF_PACKETS, docs/bvh.md);
#: the same hits as the scalar loop, faster on PoCL and Intel's runtime (measured for width 8 only).
LEAF_PACKETS = True

TRI_HAS_NORMALS = 1 << 24
TRI_HAS_UVS = 1 << 25
TRI_MASKED = 1 << 26


@dataclass
class SceneArrays:
    """The scene as the flat arrays the kernels read (host copies)."""

    bvh: FlatBVH
    tri_info: np.ndarray  # (T, 2) int32: material | TRI_* flags, light index
    tri_vidx: np.ndarray  # (T, 3) int32
    vnormals: np.ndarray  # (V, 3) float32
    vuvs: np.ndarray  # (V, 2) float32
    materials: np.ndarray  # (M, MAT_STRIDE) float32
    lights: LightArrays
    textures: TextureTable
    bounds: np.ndarray  # (2, 3) scene bounding box
    defines: dict  # -D specialisations: SCENE_HAS_MASKS, SCENE_HAS_BUMPMAPS, SCENE_HAS_TEXTURES, SCENE_MATERIALS,
    # SCENE_HAS_ANISOTROPY, SCENE_HAS_BACK_MATERIALS, SCENE_LIGHTS, BVH_WIDTH, BVH_LEAF_PACKETS, SCENE_CAMERA,
    # SCENE_FILTER, SCENE_HAS_EMITTER_TEXTURES, SCENE_HAS_INSTANCES, BVH_STACK_DISTANCES (0 in the GPU layout),
    # DEVICE_CLASS_GPU (the GPU class's code shapes: cl/integrators/wavefront/sample_bsdf.cl)
    node_buffer: np.ndarray  # bvh.nodes, or with BVH_LEAF_PACKETS the nodes and leaf packets (leaf_packet_buffer);
    # instanced scenes: then the top level and the instance records (pyclpt.accel.instances)
    geometry_defines: dict | None = None  # the instancing -D (SCENE_HAS_INSTANCES), None without instances
    instance_tri_bits: int | None = None  # instanced scenes: the packed hit id's triangle bits (AOV ids)
    instance_order: np.ndarray | None = None  # instanced scenes: record -> index in scene.instances (the plain
    # meshes' record: len(scene.instances))
    device_class: str = "cpu"  # the BVH layout's device class (pyclpt.accel.bvh.layout_settings)

    @property
    def triangle_count(self) -> int:
        return int(self.tri_info.shape[0])

    @property
    def env_light(self) -> int:
        return self.lights.env_light

    def device_arrays(self) -> list[tuple[str, np.ndarray]]:
        """(name, array) of every scene buffer but the constants, in SCENE_PARAMS order."""
        return [("BVH nodes", self.node_buffer), ("triangles", self.bvh.tris), ("triangle info", self.tri_info),
                ("triangle vertices", self.tri_vidx), ("vertex normals", self.vnormals),
                ("vertex uvs", self.vuvs), ("materials", self.materials), ("lights", self.lights.lights),
                ("light data", self.lights.light_data), ("texture records", self.textures.info()),
                ("8-bit texels", self.textures.texels8()), ("float texels", self.textures.texels32())]

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for _, a in self.device_arrays())


def instanced_groups(scene: Scene) -> list[str]:
    """The shapegroups the scene's instances use, in order of first use."""
    return list(dict.fromkeys(i.group for i in scene.instances))


def scene_meshes(scene: Scene) -> list[Mesh]:
    """Every mesh whose triangles are packed, in packing order: the plain meshes, then the meshes of each
    instanced shapegroup (once, however many instances)."""
    if not scene.instances:
        return scene.meshes
    return [*scene.meshes, *(m for g in instanced_groups(scene) for m in scene.groups[g].meshes)]


def triangle_emission(scene: Scene) -> np.ndarray:
    """(T, 3) float32: the emitted radiance of every triangle of the scene, in mesh order (scene_meshes)."""
    parts = []
    for mesh in scene_meshes(scene):
        em = mesh.emission if mesh.emission is not None and max(mesh.emission) > 0 else (0.0, 0.0, 0.0)
        parts.append(np.tile(np.asarray(em, np.float32), (mesh.triangle_count, 1)))
    return np.concatenate(parts)


def pack_appearance(scene: Scene, bvh: FlatBVH, bounds: np.ndarray) -> tuple[MaterialArrays, LightArrays]:
    """The materials, textures and emitters of ``scene`` for its BVH: everything but the geometry."""
    mats = pack_materials(scene.materials)
    meshes = scene_meshes(scene)  # the plain meshes first (emitters are never in a shapegroup)
    tri_mesh = np.repeat(np.arange(len(meshes)), [m.triangle_count for m in meshes])
    lights = pack_lights(scene, bvh.tris.reshape(-1, 9), triangle_emission(scene)[bvh.tri_order], bounds,
                         mats.textures, tri_mesh[bvh.tri_order])
    return mats, lights


#: Every -D name :func:`scene_defines` gives (SCENE_HAS_INSTANCES only for instanced scenes): the integrators' stages
#: each take the ones their code reads (pyclpt.integrators.wavefront.STAGE_DEFINES).
SCENE_DEFINES = ("SCENE_HAS_INSTANCES", "SCENE_HAS_MASKS", "SCENE_HAS_BUMPMAPS", "SCENE_HAS_TEXTURES",
                 "SCENE_MATERIALS", "SCENE_HAS_ANISOTROPY", "SCENE_HAS_BACK_MATERIALS", "SCENE_LIGHTS", "BVH_WIDTH",
                 "BVH_LEAF_PACKETS", "BVH_STACK_DISTANCES", "DEVICE_CLASS_GPU", "SCENE_CAMERA", "SCENE_FILTER",
                 "SCENE_HAS_EMITTER_TEXTURES")


def scene_defines(mats: MaterialArrays, lights: LightArrays, bvh: FlatBVH, packets: bool, scene: Scene,
                  geometry: dict | None = None, device_class: str = "cpu") -> dict:
    # BVH_STACK_DISTANCES, DEVICE_CLASS_GPU: passed for the GPU class only, so CPU programs keep their options
    return {**(geometry or {}), "SCENE_HAS_MASKS": bool(mats.masked.any()), "SCENE_HAS_BUMPMAPS": mats.has_bumpmaps,
            "SCENE_HAS_TEXTURES": mats.has_textures, "SCENE_MATERIALS": mats.kinds,
            "SCENE_HAS_ANISOTROPY": mats.has_anisotropy, "SCENE_HAS_BACK_MATERIALS": mats.has_back_materials,
            "SCENE_LIGHTS": lights.kinds, "BVH_WIDTH": bvh.width, "BVH_LEAF_PACKETS": packets,
            "BVH_STACK_DISTANCES": None if STACK_DISTANCES[device_class] else 0,
            "DEVICE_CLASS_GPU": device_class == "gpu" or None,
            "SCENE_CAMERA": camera_kind(scene.camera) or None, "SCENE_FILTER": filter_kind(scene.film.rfilter) or None,
            "SCENE_HAS_EMITTER_TEXTURES": lights.has_textures}


def triangle_info(scene: Scene, mats: MaterialArrays, lights: LightArrays, order: np.ndarray) -> np.ndarray:
    """(T, 2) int32 in leaf order: material | TRI_* flags, light index."""
    info = []
    for mesh in scene_meshes(scene):
        flags = ((TRI_HAS_NORMALS if mesh.normals is not None else 0) | (TRI_HAS_UVS if mesh.uvs is not None else 0)
                 | (TRI_MASKED if mats.masked[mesh.material] else 0))
        info.append(np.full(mesh.triangle_count, mesh.material | flags, np.int32))
    tri_info = np.empty((len(order), 2), np.int32)
    tri_info[:, 0] = np.concatenate(info)[order]
    tri_info[:, 1] = lights.tri_light
    return tri_info


def concat_meshes(meshes: list[Mesh]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Positions, indices (offset), normals and uvs of the meshes, concatenated."""
    positions, indices, normals, uvs = [], [], [], []
    offset = 0
    for mesh in meshes:
        positions.append(mesh.positions)
        indices.append(mesh.indices + offset)
        nv = mesh.positions.shape[0]
        normals.append(mesh.normals if mesh.normals is not None else np.zeros((nv, 3), np.float32))
        uvs.append(mesh.uvs if mesh.uvs is not None else np.zeros((nv, 2), np.float32))
        offset += nv
    return np.concatenate(positions), np.concatenate(indices), np.concatenate(normals), np.concatenate(uvs)


def _instanced_bvh(scene: Scene, settings: BuildSettings,
                   device_class: str) -> tuple[FlatBVH, np.ndarray, np.ndarray, bool, int, np.ndarray]:
    """Instanced scenes: one bottom-level BVH per instanced shapegroup (built once, cached) and one for the
    plain meshes (an instance with the identity transform), the top level over the instances
    (pyclpt.accel.instances). Returns the merged bottom levels, the bounds, the node buffer (with its
    header), whether it has leaf packets, the packed hit id's triangle bits and each record's instance (the plain
    meshes': len(scene.instances))."""
    groups = instanced_groups(scene)
    blocks = [scene.groups[g].meshes for g in groups]
    which = [groups.index(i.group) for i in scene.instances]
    to_world = [i.to_world for i in scene.instances]
    if scene.meshes:  # the plain meshes are packed first (scene_meshes), as one more bottom level
        blocks.insert(0, scene.meshes)
        which = [w + 1 for w in which] + [0]
        to_world.append(np.eye(4))
    bvhs = []
    for meshes in blocks:
        P, tris, _, _ = concat_meshes(meshes)
        bvhs.append(build_bvh(P, tris, settings=settings))
    inst = build_instanced(bvhs, np.array(which), np.array(to_world))
    # The merged tri_order indexes the blocks' triangles concatenated, which is scene_meshes' order.
    packets = _leaf_packets(inst.width, device_class)
    buf, _, _ = instanced_node_buffer(inst, packets)
    bounds = inst.bounds
    return inst.blas, bounds, buf, packets, inst.tri_bits, inst.order


def _leaf_packets(width: int, device_class: str) -> bool:
    """Whether the node buffer gets leaf packets: 8-wide CPU layouts only (on GPUs the packet loop's
    floatW registers alone would exceed the intersect stage's register budget: docs/bvh.md)."""
    return LEAF_PACKETS and width == 8 and device_class == "cpu"


def pack_scene(scene: Scene, device_class: str = "cpu", refit: FlatBVH | None = None) -> SceneArrays:
    """The scene's arrays with the BVH layout of ``device_class`` (``"cpu"`` or ``"gpu"``: a device's
    :attr:`~pyclpt.device.context.Device.device_class`; pyclpt.accel.bvh.layout_settings). ``refit``: a
    BVH of this scene's triangles (same count and order) whose tree is kept, its boxes refitted to the
    positions now (pyclpt.accel.bvh.refit_bvh), instead of a build; not for instanced scenes."""
    settings = layout_settings(device_class)  # also checks device_class
    scene.validate()  # every value, again: arrays changed in place, list items replaced since loading
    P, tris, vnormals, vuvs = concat_meshes(scene_meshes(scene))
    geometry, tri_bits, records = None, None, None
    if scene.instances:
        bvh, bounds, node_buffer, packets, tri_bits, records = _instanced_bvh(scene, settings, device_class)
        geometry = {"SCENE_HAS_INSTANCES": True}
    else:
        bvh = build_bvh(P, tris, settings=settings) if refit is None else refit_bvh(refit, P, tris)
        packets = _leaf_packets(bvh.width, device_class)
        bounds = np.stack([P.min(0), P.max(0)])
        node_buffer = leaf_packet_buffer(bvh) if packets else bvh.nodes
    order = bvh.tri_order
    mats, lights = pack_appearance(scene, bvh, bounds)
    return SceneArrays(
        bvh=bvh,
        tri_info=triangle_info(scene, mats, lights, order),
        tri_vidx=np.ascontiguousarray(tris[order]),
        vnormals=vnormals.astype(np.float32),
        vuvs=vuvs.astype(np.float32),
        materials=mats.materials,
        lights=lights,
        textures=mats.textures,
        bounds=bounds,
        defines=scene_defines(mats, lights, bvh, packets, scene, geometry, device_class),
        node_buffer=node_buffer,
        geometry_defines=geometry,
        instance_tri_bits=tri_bits,
        instance_order=records,
        device_class=device_class,
    )


class SceneBuffers:
    """The scene's arrays on one device, plus the per-render constants (camera, film)."""

    def __init__(self, scene: Scene, device: Device) -> None:
        start = time.perf_counter()
        self.scene = scene
        self.device = device
        # the BVH layout of the device's class (PYCLPT_DEVICE_CLASS overrides it)
        self.arrays = arrays = pack_scene(scene, device.device_class)
        self.pack_seconds = time.perf_counter() - start
        self.built_area_ratio: float | None = None  # box_area_ratio of the last build (refresh_geometry)
        self._buffers = [upload(device, a, f"scene {scene.name!r} {n}") for n, a in arrays.device_arrays()]
        self._consts: dict[tuple, cl.Buffer] = {}
        self.previous_camera: Camera | None = None  # the previous frame's, for motion vectors (None: no motion)
        self.film_pad = scene.film.rfilter.splat_reach  # a splatting film's margin (CONST_FILM_PAD)

    @property
    def defines(self) -> dict:
        """-D specialisations the kernels need for this scene."""
        return self.arrays.defines

    def refresh_appearance(self) -> list[str]:
        """Re-read the scene's materials, textures and emitters (after their values changed) and upload
        the buffers whose contents changed; the geometry and its BVH are kept. Returns the names of the
        buffers uploaded. ValueError when the change needs other kernels (a material kind or an emitter
        kind appears or disappears, texturing is switched on or off): then make a new renderer."""
        self.scene.validate()
        old = self.arrays
        mats, lights = pack_appearance(self.scene, old.bvh, old.bounds)
        packets = old.defines["BVH_LEAF_PACKETS"]
        defines = scene_defines(mats, lights, old.bvh, packets, self.scene, old.geometry_defines, old.device_class)
        new = SceneArrays(bvh=old.bvh, tri_info=triangle_info(self.scene, mats, lights, old.bvh.tri_order),
                          tri_vidx=old.tri_vidx, vnormals=old.vnormals, vuvs=old.vuvs, materials=mats.materials,
                          lights=lights, textures=mats.textures, bounds=old.bounds, defines=defines,
                          node_buffer=old.node_buffer, geometry_defines=old.geometry_defines,
                          instance_tri_bits=old.instance_tri_bits, instance_order=old.instance_order,
                          device_class=old.device_class)
        return self._adopt(new, "values")

    def _adopt(self, new: SceneArrays, what: str) -> list[str]:
        """Make ``new`` the scene's arrays, uploading the buffers whose contents changed (their names are
        returned); ValueError, with nothing changed, when the kernels were compiled for other defines."""
        old = self.arrays
        changed = {k: (old.defines.get(k), v) for k, v in new.defines.items() if old.defines.get(k) != v}
        if changed or set(old.defines) != set(new.defines):
            diff = ", ".join(f"{k} {a} -> {b}" for k, (a, b) in changed.items()) or "the defines' names"
            raise ValueError(f"scene {self.scene.name!r}: the new {what} change what the kernels are compiled "
                             f"for ({diff}); render it with a new renderer")
        uploaded = []
        for k, ((name, before), (_, after)) in enumerate(zip(old.device_arrays(), new.device_arrays())):
            if before is not after and (before.dtype != after.dtype or before.shape != after.shape
                                        or before.tobytes() != after.tobytes()):
                self._buffers[k] = upload(self.device, after, f"scene {self.scene.name!r} {name}")
                uploaded.append(name)
        self.arrays = new
        self._consts.clear()  # the bounds, the environment's light index and the emitters live there
        return uploaded

    def refresh_geometry(self) -> list[str]:
        """Re-read everything, the geometry included (after vertices, a mesh's pose or an instance's
        transform moved) and upload the buffers whose contents changed; the kernels stay as they are. The
        BVH is refitted (its tree kept, its boxes recomputed: pyclpt.accel.bvh.refit_bvh) while the
        triangles are the same ones and the tree's box areas (box_area_ratio) have grown less than
        REBUILD_GROWTH times since it was built, else built again (Embree); instanced scenes build their
        top level again (their groups' BVHs come from the cache). Returns the names of the buffers
        uploaded. ValueError when the change needs other kernels (the BVH layout or a scene feature
        changes): then make a new renderer."""
        start = time.perf_counter()
        old = self.arrays
        if self.built_area_ratio is None:
            self.built_area_ratio = box_area_ratio(old.bvh)
        built = self.built_area_ratio
        same = not self.scene.instances and not old.geometry_defines and \
            sum(m.triangle_count for m in self.scene.meshes) == old.bvh.triangle_count
        new = pack_scene(self.scene, old.device_class, refit=old.bvh if same else None)
        grown = box_area_ratio(new.bvh) / built if same else 1.0
        if grown > REBUILD_GROWTH:  # the refitted tree got too loose for where things are now
            log.info("scene %r: the refitted BVH's boxes grew %.2fx; building it again", self.scene.name, grown)
            new = pack_scene(self.scene, old.device_class)
        if not same or grown > REBUILD_GROWTH:
            built = box_area_ratio(new.bvh)
        uploaded = self._adopt(new, "geometry and values")
        self.built_area_ratio = built
        self.pack_seconds = time.perf_counter() - start
        return uploaded

    def refresh_camera(self, previous: Camera | None = None) -> None:
        """Re-read the scene's camera and its film's filter parameters: the constants are rebuilt on the next
        args() call (a filter of another kind is a ValueError, as a camera of another kind). ``previous``:
        the camera of the frame before, whose view the motion vectors point back to (None: none moved)."""
        kind = camera_kind(self.scene.camera) or None
        if kind != self.arrays.defines.get("SCENE_CAMERA"):
            raise ValueError(f"scene {self.scene.name!r}: the camera changed kind (now {self.scene.camera.kind!r}, "
                             f"aperture {self.scene.camera.aperture_radius}); the kernels are compiled for one kind: "
                             f"render it with a new renderer")
        rfilter = filter_kind(self.scene.film.rfilter) or None
        if rfilter != self.arrays.defines.get("SCENE_FILTER") or self.scene.film.rfilter.splat_reach != self.film_pad:
            raise ValueError(f"scene {self.scene.name!r}: the film's reconstruction filter changed kind (now "
                             f"{self.scene.film.rfilter.kind!r}); the kernels are compiled for one: render it with "
                             f"a new renderer")
        self.previous_camera = previous
        self._consts.clear()

    def args(self, width: int, height: int, crop: tuple[int, int, int, int] | None = None) -> tuple[cl.Buffer, ...]:
        """The SCENE_PARAMS kernel arguments for an image of width x height (``crop``: the film's window
        of it, x, y, width, height; None: all of it)."""
        key = (width, height, None if crop is None else tuple(crop), self.scene.film.rfilter.splat_reach)
        if key not in self._consts:
            consts = camera_consts(self.scene, self.arrays.lights, width, height, self.previous_camera, key[2])
            self._consts[key] = upload(self.device, consts, "camera constants")
        b = self._buffers
        return (*b[:9], self._consts[key], *b[9:])
