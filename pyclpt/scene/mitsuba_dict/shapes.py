"""Mitsuba shape plug-ins: analytic shapes, mesh files and inline meshes, as model meshes.

:data:`SHAPES` maps a plug-in name to a loader that reads the shape's own parameters and returns its
:class:`Geometry` in object space; :func:`load_shape` does what every shape shares (``to_world``,
``flip_normals``, ``face_normals``, the nested or referenced BSDF and area emitter) and adds the
:class:`~pyclpt.scene.model.Mesh` to the scene. :data:`UNSUPPORTED` names the Mitsuba shapes pyclpt
skips with a note. ``shapegroup`` and ``instance`` are :func:`load_shapegroup` and :func:`load_instance`
(the group's meshes in object space, stored once; instances place them, docs/bvh.md "Instances").
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pyclpt.scene import shapes as shape_lib
from pyclpt.scene import transform as tf
from pyclpt.scene.mitsuba_dict import bsdfs, emitters
from pyclpt.scene.mitsuba_dict.context import META_KEYS, VERSION, LoadContext, is_dict
from pyclpt.scene.model import Instance, Mesh, ShapeGroup


@dataclass
class Geometry:
    """A shape's triangles before ``to_world``: arrays as given (any array-likes), the final object-to-world
    matrix, whether to flip v of the uvs (pyclpt's v is up, the image's top at v = 1; Mitsuba reads rows at
    v) and the parameters the shape used."""

    positions: Any
    indices: Any
    normals: Any
    uvs: Any
    to_world: np.ndarray
    flip_v: bool = True
    used: set[str] = field(default_factory=set)


ShapeLoader = Callable[[LoadContext, Mapping[str, Any], str, np.ndarray], Geometry]

#: Mitsuba shapes pyclpt does not have: reported, and skipped.
UNSUPPORTED = frozenset({"hair", "heightfield", "bsplinecurve",
                         "linearcurve", "sdfgrid", "ellipsoids", "ellipsoidsmesh"})


def mitsuba_frame(n: np.ndarray) -> np.ndarray:
    """Mitsuba's ``Frame3f(n)`` as a 4x4 matrix (columns s, t, n): its ``coordinate_system`` (Duff et al.
    2017), so that a cylinder's u starts where Mitsuba's does."""
    sign = np.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    m = np.eye(4)
    m[:3, 0] = [1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]]
    m[:3, 1] = [b, sign + n[1] * n[1] * a, -n[1]]
    m[:3, 2] = n
    return m


def load_analytic(ctx: LoadContext, d: Mapping[str, Any], where: str, to_world: np.ndarray) -> Geometry:
    """``rectangle``, ``cube``, ``disk``, ``sphere`` (``center``, ``radius``), ``cylinder`` (``p0``, ``p1``,
    ``radius``) as meshes (see :mod:`pyclpt.scene.shapes`)."""
    kind = d.get("type")
    base = shape_lib.SHAPES[kind]()
    used: set[str] = set()
    if kind == "sphere":
        used |= {"center", "radius"}
        r = ctx.number(d, "radius", 1.0, where)
        try:
            to_world = to_world @ tf.translate(d.get("center", (0.0, 0.0, 0.0))) @ tf.scale(r)
        except (ValueError, TypeError) as exc:
            raise ctx.fail(f"{where}.center", str(exc), d) from None
    if kind == "cylinder":  # Mitsuba: to_world * translate(p0) * to_frame(Frame(d / |d|)) * scale(r, r, |d|)
        used |= {"p0", "p1", "radius"}
        r = ctx.number(d, "radius", 1.0, where)
        p0 = ctx.vector(d, "p0", where) if "p0" in d else np.zeros(3)
        p1 = ctx.vector(d, "p1", where) if "p1" in d else np.array([0.0, 0.0, 1.0])
        length = float(np.linalg.norm(p1 - p0))
        if not (length > 0 and r > 0):
            raise ctx.fail(where, f"a cylinder needs p0 != p1 and radius > 0, got p0 {p0.tolist()}, "
                                  f"p1 {p1.tolist()}, radius {r}", d)
        to_world = to_world @ tf.translate(p0) @ mitsuba_frame((p1 - p0) / length) @ tf.scale((r, r, length))
    return Geometry(base.positions, base.indices, base.normals, base.uvs, to_world, used=used)


def load_mesh_file(ctx: LoadContext, d: Mapping[str, Any], where: str, to_world: np.ndarray) -> Geometry:
    """``obj``, ``ply`` (see :mod:`pyclpt.scene.mesh_io`) and ``serialized`` (:mod:`pyclpt.scene.serialized`)."""
    kind = d.get("type")
    used = {"filename", "flip_tex_coords", "shape_index", "max_smooth_angle"}
    if "filename" not in d:
        raise ctx.fail(where, f"{kind} shape needs a filename", d)
    mesh_path = ctx.path(d["filename"], f"{where}.filename", d)
    try:
        if kind == "serialized":
            from pyclpt.scene.serialized import read_serialized

            data = read_serialized(mesh_path, int(ctx.number(d, "shape_index", 0, where)))
        else:
            from pyclpt.scene.mesh_io import load_mesh

            data = load_mesh(mesh_path)
    except (OSError, ValueError) as exc:
        raise ctx.fail(where, str(exc), d) from None
    flip_v = True
    if kind == "obj":
        # Mitsuba flips OBJ texture coordinates by default (flip_tex_coords), which
        # already is pyclpt's convention.
        flip_v = not ctx.flag(d, "flip_tex_coords", True, where)
    if "max_smooth_angle" in d:
        ctx.note(d, where, "max_smooth_angle ignored: the file's normals (or face normals) used")
    return Geometry(data.positions, data.indices, data.normals, data.uvs, to_world, flip_v, used)


def load_inline_mesh(ctx: LoadContext, d: Mapping[str, Any], where: str, to_world: np.ndarray) -> Geometry:
    """``mesh``: ``positions`` and ``indices`` (and optional ``normals``, ``uvs``) given in the dictionary."""
    if "positions" not in d or "indices" not in d:
        raise ctx.fail(where, "a mesh shape needs positions and indices", d)
    return Geometry(d["positions"], d["indices"], d.get("normals"), d.get("uvs"), to_world,
                    used={"positions", "indices", "normals", "uvs"})


#: Mitsuba shape plug-ins pyclpt loads, by name.
SHAPES: dict[str, ShapeLoader] = {
    **{name: load_analytic for name in shape_lib.SHAPES},
    "obj": load_mesh_file,
    "ply": load_mesh_file,
    "serialized": load_mesh_file,
    "mesh": load_inline_mesh,
}


#: The shape plug-ins of instancing, loaded by :func:`load_shape` itself.
INSTANCING = frozenset({"shapegroup", "instance"})


def load_shapegroup(ctx: LoadContext, name: str, d: Mapping[str, Any]) -> ShapeGroup:
    """The :class:`ShapeGroup` of ``shapegroup`` object ``d`` (its id, else ``name``), loaded once: its nested
    shapes (with their BSDFs) as object-space meshes. Nested groups, instances and emitters are errors."""
    gid = str(d.get("id", name))
    if gid in ctx.groups:
        return ctx.groups[gid]
    outer = ctx.meshes
    ctx.meshes = []
    try:
        for k, v in d.items():
            if k in META_KEYS:
                continue
            if not is_dict(v):
                raise ctx.fail(f"{name}.{k}", f"a shapegroup holds shapes only, got {v!r}", d)
            child = ctx.deref(v, f"{name}.{k}")
            kind = child.get("type")
            if kind in INSTANCING:
                raise ctx.fail(f"{name}.{k}", f"a {kind} inside shapegroup {gid!r}: nested instancing is not "
                                              "supported (nor by Mitsuba 3)", child)
            if kind not in SHAPES and kind not in UNSUPPORTED:
                raise ctx.fail(f"{name}.{k}", f"a shapegroup holds shapes only, got type {kind!r}", child)
            load_shape(ctx, f"{name}.{k}", child)
        meshes = ctx.meshes
    finally:
        ctx.meshes = outer
    for m in meshes:
        if m.emission is not None:
            raise ctx.fail(m.name, f"an area emitter inside shapegroup {gid!r}: emitters cannot be instanced "
                                   "(Mitsuba 3 refuses them too); put the emitter outside the group", d)
    if not meshes:
        raise ctx.fail(name, f"shapegroup {gid!r} has no shapes pyclpt can load", d)
    ctx.groups[gid] = group = ShapeGroup(gid, meshes)
    return group


def load_instance(ctx: LoadContext, name: str, d: Mapping[str, Any]) -> None:
    """Add the :class:`Instance` of ``instance`` object ``d``: its one nested shapegroup (a reference or an
    inline group) placed by ``to_world``."""
    refs = [(k, v) for k, v in d.items() if k not in META_KEYS and is_dict(v)]
    if len(refs) != 1:
        raise ctx.fail(name, f"an instance needs exactly one shapegroup (a <ref id=.../>), got {len(refs)} "
                             "nested objects", d)
    key, ref = refs[0]
    if ref.get("type") == "ref" and ref.get("id") not in ctx.named:
        raise ctx.fail(f"{name}.{key}", f"instance of unknown shapegroup {ref.get('id')!r}", d)
    target = ctx.deref(ref, f"{name}.{key}")
    if target.get("type") != "shapegroup":
        raise ctx.fail(f"{name}.{key}", f"an instance must refer to a shapegroup, got type {target.get('type')!r}",
                       d)
    group = load_shapegroup(ctx, str(ref.get("id", key)), target)
    ctx.note_unused(name, d, {"to_world", key})
    to_world = ctx.transform(d, "to_world", name)
    try:
        ctx.instances.append(Instance(group.name, to_world, name))
    except ValueError as exc:
        raise ctx.fail(name, str(exc), d) from None


def load_shape(ctx: LoadContext, name: str, d: Mapping[str, Any]) -> None:
    """Add shape ``d`` (keyed ``name`` in the scene) to ``ctx.meshes``, with its material and emission; a
    ``shapegroup`` to ``ctx.groups``, an ``instance`` to ``ctx.instances``."""
    kind = d.get("type")
    where = name
    if kind == "shapegroup":
        load_shapegroup(ctx, name, d)
        return
    if kind == "instance":
        load_instance(ctx, name, d)
        return
    if kind in UNSUPPORTED:
        ctx.note(d, where, f"shape type {kind!r} not supported, shape skipped")
        return
    to_world = ctx.transform(d, "to_world", where)
    loader = SHAPES.get(kind)
    if loader is None:
        raise ctx.fail(where, f"unsupported shape type {kind!r} (supported: {', '.join(sorted(SHAPES))})", d)
    geo = loader(ctx, d, where, to_world)
    used = {"to_world", "flip_normals", "face_normals"} | geo.used
    for k, v in d.items():
        if k.split("_")[0] in ("bsdf", "emitter") and not is_dict(v):
            raise ctx.fail(f"{where}.{k}", f"expected a {k.split('_')[0]} dict or ref, got {v!r}", d)
    # nested objects keyed bsdf*/emitter* are that (an unknown type is then an error)
    materials = [(k, v) for k, v in d.items() if is_dict(v) and k not in META_KEYS and (
        k.startswith("bsdf") or ctx.deref(v, f"{where}.{k}").get("type") in bsdfs.BSDFS.keys() | bsdfs.UNSUPPORTED)]
    lights = [(k, v) for k, v in d.items() if is_dict(v) and k not in META_KEYS and (
        k.startswith("emitter") or ctx.deref(v, f"{where}.{k}").get("type") in emitters.KNOWN)]
    others = [k for k, v in d.items() if k not in META_KEYS and is_dict(v)
              and k not in {b for b, _ in materials} | {e for e, _ in lights} and k not in used]
    for k in others:
        ctx.note(d[k] if is_dict(d[k]) else d, f"{where}.{k}",
                 f"{d[k].get('type')!r} inside a shape not supported, ignored")
    ctx.note_unused(where, {k: v for k, v in d.items() if k not in others}, used | {b for b, _ in materials}
                    | {e for e, _ in lights})
    m = geo.to_world
    normals, uvs = geo.normals, geo.uvs
    try:
        positions = tf.apply_points(m, np.asarray(geo.positions, np.float64).reshape(-1, 3))
        face_normals = ctx.flag(d, "face_normals", False, where)
        if normals is not None and not face_normals:
            normals = tf.apply_normals(m, np.asarray(normals, np.float64).reshape(-1, 3))
        else:
            normals = None
        indices = np.asarray(geo.indices, np.int32).reshape(-1, 3)
        if uvs is not None:
            uvs = np.array(uvs, np.float32).reshape(-1, 2)
            if geo.flip_v:
                uvs[:, 1] = 1.0 - uvs[:, 1]
    except (ValueError, TypeError) as exc:
        raise ctx.fail(where, f"bad mesh data: {exc}", d) from None
    if np.linalg.det(m[:3, :3]) < 0:
        indices = indices[:, ::-1].copy()  # a mirroring transform keeps the outward side
    if ctx.flag(d, "flip_normals", False, where):
        indices = indices[:, ::-1].copy()
        if normals is not None:
            normals = -normals
    if len(materials) > 1:
        ctx.note(d, where, f"{len(materials)} BSDFs given, the first used")
    # no BSDF: grey diffuse, but black for an area emitter's shape in Mitsuba 3 (not in 0.5: old files' shapes
    # carry their version)
    material = bsdfs.material_index(ctx, materials[0][1] if materials else None,
                                    f"{where}.{materials[0][0]}" if materials else where,
                                    black=bool(lights) and VERSION not in d)
    emission = texture = None
    for key, em in lights:
        emission, texture = emitters.area_radiance(ctx, ctx.deref(em, f"{where}.{key}"), f"{where}.{key}")
    try:
        ctx.meshes.append(Mesh(name, positions, indices, material, normals, uvs, emission, texture))
    except ValueError as exc:
        raise ctx.fail(where, str(exc), d) from None
