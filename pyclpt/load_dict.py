"""Build a :class:`~pyclpt.scene.Scene` from a Mitsuba-3-style dictionary.

The dictionary format is Mitsuba 3's ``load_dict`` (``{"type": "scene", ...}``
with ``sensor``, ``integrator``, BSDFs, shapes and emitters as nested dicts and
``{"type": "ref", "id": ...}`` references), with transforms given as 4x4
matrices, Mitsuba ``ScalarTransform4f`` objects, or lists of operations (see
:func:`pyclpt.transform.from_spec`). Built-in scenes in ``scenes/*.json`` use it.
Parameters pyclpt does not use are reported in one warning per load.
"""
from __future__ import annotations

import os
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from . import shapes as shape_lib
from . import transform as tf
from .scene import RGB, Camera, Conductor, Dielectric, Diffuse, Film, Material, Mesh, Scene, rgb

# RGB complex IORs of common metals (Mitsuba's `material` names).
METALS: dict[str, tuple[RGB, RGB]] = {
    "none": ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)),
    "Ag": ((0.155265, 0.116723, 0.138342), (4.82835, 3.12225, 2.14696)),
    "Al": ((1.65746, 0.880369, 0.521229), (9.22387, 6.26952, 4.837)),
    "Au": ((0.143119, 0.374957, 1.44248), (3.98316, 2.38572, 1.60322)),
    "Cu": ((0.200438, 0.924033, 1.10221), (3.91295, 2.45285, 2.14219)),
    "Cr": ((4.36968, 2.9167, 1.6547), (5.20637, 4.23132, 3.75487)),
}

IORS = {"vacuum": 1.0, "air": 1.000277, "water": 1.333, "acrylic glass": 1.49, "bk7": 1.5046,
        "glass": 1.5046, "diamond": 2.419, "polypropylene": 1.49, "fused quartz": 1.458}

_META_KEYS = {"type", "id"}


class SceneDictError(ValueError):
    """A scene dictionary (or scene file) that cannot be loaded; the message names the element."""


class _Loader:
    def __init__(self, base_dir: Path | None, origin: str) -> None:
        self.base_dir = base_dir
        self.origin = origin
        self.materials: list[Material] = []
        self.material_ids: dict[str, int] = {}
        self.named_bsdfs: dict[str, Mapping[str, Any]] = {}
        self.meshes: list[Mesh] = []
        self.unused: list[str] = []

    # -- helpers --------------------------------------------------------
    def fail(self, where: str, msg: str) -> SceneDictError:
        return SceneDictError(f"{self.origin}: {where}: {msg}")

    def note_unused(self, where: str, d: Mapping[str, Any], used: set[str]) -> None:
        for key in d:
            if key not in used and key not in _META_KEYS:
                self.unused.append(f"{where}.{key}")

    def color(self, value: Any, where: str) -> RGB:
        if isinstance(value, Mapping):
            kind = value.get("type")
            if kind in ("rgb", "spectrum", "srgb") and "value" in value:
                value = value["value"]
            else:
                raise self.fail(where, f"unsupported color/texture {dict(value)!r} (rgb or a number)")
        try:
            return rgb(value, where)
        except ValueError as exc:
            raise self.fail(where, str(exc)) from None

    def number(self, d: Mapping[str, Any], key: str, default: float, where: str) -> float:
        v = d.get(key, default)
        if isinstance(v, str):
            v = IORS.get(v.lower(), v)
        try:
            out = float(v)
        except (TypeError, ValueError):
            raise self.fail(f"{where}.{key}", f"expected a number, got {v!r}") from None
        if not np.isfinite(out):
            raise self.fail(f"{where}.{key}", f"expected a finite number, got {v!r}")
        return out

    def path(self, name: str, where: str) -> Path:
        expanded = os.path.expandvars(str(name))
        if "$" in expanded:
            raise self.fail(where, f"{name!r} names an unset environment variable")
        p = Path(expanded)
        if not p.is_absolute() and self.base_dir is not None:
            p = self.base_dir / p
        if not p.exists():
            raise self.fail(where, f"file not found: {p}")
        return p

    # -- BSDFs ------------------------------------------------------------
    def bsdf(self, d: Mapping[str, Any], where: str) -> Material:
        kind = d.get("type")
        if kind == "twosided":
            inner = [v for k, v in d.items() if isinstance(v, Mapping)]
            if len(inner) != 1:
                raise self.fail(where, "twosided needs exactly one nested BSDF")
            mat = self.resolve_bsdf(inner[0], f"{where}.bsdf")
            if isinstance(mat, Dielectric):
                return mat
            return type(mat)(**{**mat.__dict__, "twosided": True})
        if kind == "diffuse":
            self.note_unused(where, d, {"reflectance"})
            return Diffuse(self.color(d.get("reflectance", 0.5), f"{where}.reflectance"))
        if kind in ("conductor", "roughconductor"):
            used = {"material", "eta", "k", "specular_reflectance", "alpha", "distribution"}
            self.note_unused(where, d, used)
            metal = d.get("material", "none")
            if "eta" in d or "k" in d:
                eta = self.color(d.get("eta", 0.0), f"{where}.eta")
                k = self.color(d.get("k", 1.0), f"{where}.k")
            elif metal in METALS:
                eta, k = METALS[metal]
            else:
                raise self.fail(f"{where}.material", f"unknown metal {metal!r} (known: {', '.join(METALS)})")
            alpha = self.number(d, "alpha", 0.1, where) if kind == "roughconductor" else 0.0
            if kind == "roughconductor" and d.get("distribution", "ggx") != "ggx":
                self.unused.append(f"{where}.distribution={d['distribution']} (GGX used)")
            if not 0.0 <= alpha <= 1.0:
                raise self.fail(f"{where}.alpha", f"roughness must be in [0, 1], got {alpha}")
            spec = self.color(d.get("specular_reflectance", 1.0), f"{where}.specular_reflectance")
            return Conductor(eta, k, alpha, spec)
        if kind == "dielectric":
            self.note_unused(where, d, {"int_ior", "ext_ior", "specular_reflectance", "specular_transmittance"})
            int_ior = self.number(d, "int_ior", 1.5046, where)
            ext_ior = self.number(d, "ext_ior", 1.000277, where)
            if int_ior <= 0 or ext_ior <= 0:
                raise self.fail(where, f"IORs must be positive, got {int_ior}, {ext_ior}")
            return Dielectric(int_ior, ext_ior,
                              self.color(d.get("specular_reflectance", 1.0), f"{where}.specular_reflectance"),
                              self.color(d.get("specular_transmittance", 1.0), f"{where}.specular_transmittance"))
        raise self.fail(where, f"unsupported BSDF type {kind!r} (diffuse, conductor, roughconductor, "
                               "dielectric, twosided)")

    def resolve_bsdf(self, d: Mapping[str, Any], where: str) -> Material:
        if d.get("type") == "ref":
            ref = d.get("id")
            if ref not in self.named_bsdfs:
                raise self.fail(where, f"reference to unknown BSDF id {ref!r}")
            return self.bsdf(self.named_bsdfs[ref], ref)
        return self.bsdf(d, where)

    def material_index(self, d: Mapping[str, Any] | None, where: str) -> int:
        key = None
        if d is None:
            key = "<default>"
            mat: Material = Diffuse()
        elif d.get("type") == "ref":
            key = f"id:{d.get('id')}"
            if key in self.material_ids:
                return self.material_ids[key]
            mat = self.resolve_bsdf(d, where)
        else:
            mat = self.resolve_bsdf(d, where)
        if key is not None and key in self.material_ids:
            return self.material_ids[key]
        self.materials.append(mat)
        idx = len(self.materials) - 1
        if key is not None:
            self.material_ids[key] = idx
        return idx

    # -- shapes -------------------------------------------------------------
    def shape(self, name: str, d: Mapping[str, Any]) -> None:
        from .mesh_io import load_mesh

        kind = d.get("type")
        where = name
        used = {"to_world", "bsdf", "emitter", "flip_normals", "face_normals"}
        try:
            m = tf.from_spec(d.get("to_world"))
        except (ValueError, KeyError, TypeError) as exc:
            raise self.fail(f"{where}.to_world", f"bad transform: {exc}") from None
        if kind in shape_lib.SHAPES:
            base = shape_lib.SHAPES[kind]()
            positions, indices, normals, uvs = base.positions, base.indices, base.normals, base.uvs
            if kind == "sphere":
                used |= {"center", "radius"}
                r = self.number(d, "radius", 1.0, where)
                try:
                    m = m @ tf.translate(d.get("center", (0.0, 0.0, 0.0))) @ tf.scale(r)
                except (ValueError, TypeError) as exc:
                    raise self.fail(f"{where}.center", str(exc)) from None
        elif kind in ("obj", "ply"):
            used |= {"filename"}
            if "filename" not in d:
                raise self.fail(where, f"{kind} shape needs a filename")
            mesh_path = self.path(d["filename"], f"{where}.filename")
            try:
                data = load_mesh(mesh_path)
            except (OSError, ValueError) as exc:
                raise self.fail(where, str(exc)) from None
            positions, indices, normals, uvs = data.positions, data.indices, data.normals, data.uvs
        elif kind == "mesh":
            used |= {"positions", "indices", "normals", "uvs"}
            if "positions" not in d or "indices" not in d:
                raise self.fail(where, "a mesh shape needs positions and indices")
            positions, indices = d["positions"], d["indices"]
            normals, uvs = d.get("normals"), d.get("uvs")
        else:
            raise self.fail(where, f"unsupported shape type {kind!r} (rectangle, cube, disk, sphere, obj, ply, mesh)")
        self.note_unused(where, d, used)
        try:
            positions = tf.apply_points(m, np.asarray(positions, np.float64).reshape(-1, 3))
            if normals is not None and not d.get("face_normals", False):
                normals = tf.apply_normals(m, np.asarray(normals, np.float64).reshape(-1, 3))
            else:
                normals = None
            indices = np.asarray(indices, np.int32).reshape(-1, 3)
        except (ValueError, TypeError) as exc:
            raise self.fail(where, f"bad mesh data: {exc}") from None
        if d.get("flip_normals", False):
            indices = indices[:, ::-1].copy()
            if normals is not None:
                normals = -normals
        bsdf = d.get("bsdf")
        if bsdf is not None and not isinstance(bsdf, Mapping):
            raise self.fail(f"{where}.bsdf", f"expected a BSDF dict or ref, got {bsdf!r}")
        material = self.material_index(bsdf, f"{where}.bsdf")
        emission = None
        em = d.get("emitter")
        if em is not None:
            if not isinstance(em, Mapping) or em.get("type") != "area":
                raise self.fail(f"{where}.emitter", f"only 'area' emitters attach to shapes, got {em!r}")
            self.note_unused(f"{where}.emitter", em, {"radiance"})
            emission = self.color(em.get("radiance", 1.0), f"{where}.emitter.radiance")
        try:
            self.meshes.append(Mesh(name, positions, indices, material, normals, uvs, emission))
        except ValueError as exc:
            raise self.fail(where, str(exc)) from None

    # -- the whole scene ------------------------------------------------------
    def scene(self, d: Mapping[str, Any], name: str) -> Scene:
        if d.get("type") != "scene":
            raise self.fail("<root>", "the top-level dict must have type 'scene'")
        camera, film, spp, max_depth, env = Camera(), Film(), 64, -1, None
        # BSDFs first, so shapes may reference them whatever the dict order.
        for key, value in d.items():
            if isinstance(value, Mapping) and value.get("type") in (
                    "diffuse", "conductor", "roughconductor", "dielectric", "twosided"):
                self.named_bsdfs[value.get("id", key)] = value
        for key, value in d.items():
            if key in _META_KEYS:
                continue
            if not isinstance(value, Mapping):
                raise self.fail(key, f"expected a dict, got {value!r}")
            kind = value.get("type")
            if key == "sensor" or kind == "perspective":
                camera, film, spp = self.sensor(value, key)
            elif key == "integrator" or kind in ("path", "direct", "volpath", "prb"):
                if kind not in ("path",):
                    self.unused.append(f"{key}.type={kind} (pyclpt's path tracer used)")
                max_depth = int(self.number(value, "max_depth", -1, key))
                self.note_unused(key, value, {"max_depth"})
            elif kind == "constant":
                self.note_unused(key, value, {"radiance"})
                env = self.color(value.get("radiance", 1.0), f"{key}.radiance")
            elif key in self.named_bsdfs or value.get("id") in self.named_bsdfs:
                continue
            elif kind in ("rectangle", "cube", "disk", "sphere", "obj", "ply", "mesh"):
                self.shape(key, value)
            else:
                raise self.fail(key, f"unsupported element type {kind!r}")
        if not self.meshes:
            raise self.fail("<root>", "the scene has no shapes")
        if self.unused:
            warnings.warn(f"{self.origin}: not used by pyclpt: {', '.join(self.unused)}", stacklevel=3)
        return Scene(self.meshes, self.materials, camera, film, env, spp, max_depth, name)

    def sensor(self, d: Mapping[str, Any], where: str) -> tuple[Camera, Film, int]:
        if d.get("type", "perspective") != "perspective":
            raise self.fail(where, f"unsupported sensor type {d.get('type')!r} (perspective)")
        self.note_unused(where, d, {"fov", "fov_axis", "to_world", "film", "sampler", "near_clip",
                                    "far_clip", "focus_distance"})
        try:
            camera = Camera(tf.from_spec(d.get("to_world")), self.number(d, "fov", 45.0, where),
                            str(d.get("fov_axis", "x")))
        except ValueError as exc:
            raise self.fail(where, str(exc)) from None
        f = d.get("film", {})
        self.note_unused(f"{where}.film", f, {"width", "height", "rfilter", "pixel_format", "component_format"})
        try:
            film = Film(int(f.get("width", 768)), int(f.get("height", 576)))
        except (TypeError, ValueError) as exc:
            raise self.fail(f"{where}.film", str(exc)) from None
        spp = int(self.number(d.get("sampler", {}), "sample_count", 64, f"{where}.sampler"))
        return camera, film, spp


def load_dict(d: Mapping[str, Any], *, base_dir: str | os.PathLike | None = None,
              name: str = "scene", origin: str | None = None) -> Scene:
    """A Scene from a Mitsuba-3-style dict; relative file names resolve against ``base_dir``."""
    loader = _Loader(Path(base_dir) if base_dir is not None else None, origin or name)
    return loader.scene(d, name)
