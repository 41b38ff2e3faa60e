"""Build a :class:`~pyclpt.scene.model.Scene` from a Mitsuba-3-style dictionary.

The dictionary format is Mitsuba 3's ``load_dict`` (``{"type": "scene", ...}``
with the sensor, integrator, BSDFs, textures, shapes and emitters as nested
dicts under any keys, and ``{"type": "ref", "id": ...}`` references), with
transforms given as 4x4 matrices, Mitsuba ``ScalarTransform4f`` objects, or
lists of operations (see :func:`pyclpt.scene.transform.from_spec`). Built-in scenes
in ``scenes/*.json`` use it, and :mod:`pyclpt.scene.mitsuba_xml` translates Mitsuba
XML files (0.5 to 3.x) into it, adding ``"__where__": "file:line"`` to every
object so that messages name the line.

Everything pyclpt does not support is reported in one warning per load, each
entry saying what, where, and what was done instead; nothing is dropped
silently. Malformed values raise :class:`SceneDictError` naming the element.
"""
from __future__ import annotations

import os
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from pyclpt.scene import shapes as shape_lib
from pyclpt.scene import transform as tf
from pyclpt.scene.model import (
    RGB,
    Bitmap,
    BumpMap,
    Camera,
    Checkerboard,
    Color,
    Conductor,
    Dielectric,
    Diffuse,
    Envmap,
    Film,
    Mask,
    Material,
    Mesh,
    Plastic,
    PointLight,
    Scene,
    ThinDielectric,
    rgb,
)

# Complex IORs (eta, k) of Mitsuba's named conductors, as RGB: the values Mitsuba 3.9.1's own
# `conductor` reports in its scalar_rgb variant (its tabulated spectra converted to sRGB), so a
# `material` name means the same colour in both renderers. "none" is a perfect mirror.
METALS: dict[str, tuple[RGB, RGB]] = {
    "none": ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)),
    "Ag": ((0.155276, 0.116728, 0.138388), (4.828354, 3.122222, 2.146901)),
    "Al": ((1.657501, 0.880405, 0.521244), (9.223811, 6.269502, 4.837004)),
    "Au": ((0.143036, 0.375307, 1.442045), (3.982997, 2.385556, 1.603359)),
    "Cu": ((0.201005, 0.92375, 1.102215), (3.913262, 2.453045, 2.14209)),
    "Cr": ((4.369668, 2.916505, 1.654905), (5.206547, 4.231306, 3.754699)),
    "Hg": ((2.398939, 1.440028, 0.90957), (6.327587, 4.371925, 3.421764)),
    "W": ((4.370817, 3.300246, 2.998407), (3.500641, 2.604874, 2.273233)),
    "Be": ((4.185012, 3.185029, 2.784061), (3.835466, 3.010122, 2.868994)),
    "Li": ((0.265791, 0.195618, 0.220949), (3.540155, 2.311123, 1.668607)),
    "K": ((0.064043, 0.04641, 0.038185), (2.1042, 1.34894, 0.913126)),
    "CuO": ((3.247541, 2.447805, 2.21022), (0.52109, 0.570031, 0.722179)),
    "Cu2O": ((3.551773, 2.94987, 2.751875), (0.114207, 0.193897, 0.606134)),
    "TiN": ((1.64845, 1.150516, 1.379823), (3.368328, 1.943498, 1.102068)),
    "TiC": ((3.700528, 2.837422, 2.582287), (3.265635, 2.351589, 2.172791)),
    "a-C": ((2.944046, 2.227136, 1.968162), (0.887465, 0.799299, 0.81529)),
    "Ir": ((3.0863, 2.082191, 1.617915), (5.592153, 4.067088, 3.267312)),
    "Mo": ((4.483974, 3.525131, 2.77631), (4.111437, 3.420827, 3.150607)),
    "Ta": ((2.062721, 2.392939, 2.627929), (2.40836, 1.741486, 1.947028)),
    "Te": ((7.390234, 4.482105, 2.637106), (3.256022, 3.527059, 3.292054)),
    "VN": ((2.865602, 2.119189, 1.940091), (3.032243, 2.056116, 1.616306)),
    "ThF4": ((1.830714, 1.442229, 1.387648), (0.0, 0.0, 0.0)),
}

IORS = {"vacuum": 1.0, "helium": 1.000036, "hydrogen": 1.000132, "air": 1.000277, "carbon dioxide": 1.00045,
        "water": 1.333, "acetone": 1.36, "ethanol": 1.361, "carbon tetrachloride": 1.461, "glycerol": 1.4729,
        "benzene": 1.501, "silicone oil": 1.52045, "bromine": 1.661, "water ice": 1.31, "fused quartz": 1.458,
        "pyrex": 1.47, "acrylic glass": 1.49, "polypropylene": 1.49, "bk7": 1.5046, "glass": 1.5046,
        "sodium chloride": 1.544, "amber": 1.55, "pet": 1.575, "diamond": 2.419}

WHERE = "__where__"
_META_KEYS = {"type", "id", WHERE}

BSDF_TYPES = {"diffuse", "conductor", "roughconductor", "dielectric", "roughdielectric", "thindielectric",
              "plastic", "roughplastic", "twosided", "mask", "bumpmap"}
# Mitsuba BSDFs pyclpt does not have: reported, and a grey diffuse used instead.
OTHER_BSDF_TYPES = {"blendbsdf", "coating", "roughcoating", "phong", "ward", "hk", "null", "difftrans",
                    "principled", "principledthin", "measured", "polarizer", "retarder", "pplastic", "irawan",
                    "roughdiffuse", "dipole", "normalmap", "mixturebsdf", "bsdf"}
TEXTURE_TYPES = {"bitmap", "checkerboard", "scale"}
MESH_FILE_TYPES = {"obj", "ply", "serialized"}
SHAPE_TYPES = set(shape_lib.SHAPES) | MESH_FILE_TYPES | {"mesh"}
OTHER_SHAPE_TYPES = {"cylinder", "hair", "heightfield", "shapegroup", "instance", "bsplinecurve",
                     "linearcurve", "sdfgrid", "ellipsoids", "ellipsoidsmesh"}
EMITTER_TYPES = {"area", "point", "constant", "envmap", "sunsky", "sky", "sun"}
OTHER_EMITTER_TYPES = {"spot", "directional", "projector", "collimated", "directionalarea"}
SENSOR_TYPES = {"perspective", "thinlens", "orthographic", "radiancemeter", "irradiancemeter", "spherical",
                "telecentric", "batch"}
INTEGRATOR_TYPES = {"path", "volpath", "volpathmis", "direct", "aov", "sppm", "bdpt", "pssmlt", "mlt", "erpt",
                    "ptracer", "photonmapper", "ppm", "vpl", "ao", "prb", "prb_basic", "direct_projective",
                    "prb_projective", "stokes", "moment", "depth", "field", "adaptive", "irrcache",
                    "multichannel", "volpath_simple"}
OTHER_TOP_TYPES = {"homogeneous", "heterogeneous", "isotropic", "hg", "medium"}
# XML tags of elements pyclpt does not use (mitsuba_xml keys untyped objects by their tag)
OTHER_TAGS = {"medium", "phase", "volume", "subsurface", "film", "sampler", "rfilter"}


class SceneDictError(ValueError):
    """A scene dictionary (or scene file) that cannot be loaded; the message names the element."""


def _is_dict(v: Any) -> bool:
    return isinstance(v, Mapping)


class _Loader:
    def __init__(self, base_dir: Path | None, origin: str) -> None:
        self.base_dir = base_dir
        self.origin = origin
        self.materials: list[Material] = []
        self.material_ids: dict[str, int] = {}
        self.named: dict[str, Mapping[str, Any]] = {}  # objects with an id
        self.referenced: set[str] = set()
        self.meshes: list[Mesh] = []
        self.lights: list[PointLight] = []
        self.environment: RGB | Envmap | None = None
        self.notes: list[str] = []
        self._textures: dict[tuple, Bitmap] = {}
        self._texture_objs: dict[int, Bitmap | Checkerboard] = {}

    # -- messages ------------------------------------------------------------
    @staticmethod
    def loc(d: Mapping[str, Any] | None, where: str) -> str:
        at = d.get(WHERE) if _is_dict(d) else None
        return f"{where} ({at})" if at else where

    def fail(self, where: str, msg: str, d: Mapping[str, Any] | None = None) -> SceneDictError:
        at = d.get(WHERE) if _is_dict(d) else None
        return SceneDictError(f"{at or self.origin}: {where}: {msg}")

    def note(self, d: Mapping[str, Any] | None, where: str, what: str) -> None:
        self.notes.append(f"{self.loc(d, where)}: {what}")

    def note_unused(self, where: str, d: Mapping[str, Any], used: set[str]) -> None:
        extra = [k for k in d if k not in used and k not in _META_KEYS]
        if extra:
            at = d.get(WHERE) if _is_dict(d) else None
            names = ", ".join(f"{where}.{k}" for k in extra)
            self.notes.append(f"{names}{f' ({at})' if at else ''}: ignored")

    # -- values ----------------------------------------------------------------
    def deref(self, v: Any, where: str) -> Any:
        if _is_dict(v) and v.get("type") == "ref":
            ref = v.get("id")
            if ref not in self.named:
                raise self.fail(where, f"reference to unknown id {ref!r}", v)
            self.referenced.add(ref)
            return self.named[ref]
        return v

    def color(self, value: Any, where: str, parent: Mapping[str, Any] | None = None) -> RGB:
        """A constant color: a number, 3 numbers or an rgb/spectrum dict."""
        value = self.deref(value, where)
        if _is_dict(value):
            kind = value.get("type")
            if kind in ("rgb", "spectrum", "srgb") and "value" in value:
                value = value["value"]
            elif kind in TEXTURE_TYPES:
                tex = self.texture(value, where)
                mean = tex.rgba()[..., :3].mean(axis=(0, 1)) if isinstance(tex, Bitmap) else \
                    0.5 * (np.asarray(tex.color0) + np.asarray(tex.color1))
                self.note(value, where, "a texture is not supported here; its mean color used")
                return rgb(mean, where)
            else:
                raise self.fail(where, f"unsupported color {dict(value)!r} (rgb, spectrum or a number)", value)
        try:
            return rgb(value, where)
        except ValueError as exc:
            raise self.fail(where, str(exc), parent) from None

    def color_or_texture(self, value: Any, where: str, parent: Mapping[str, Any] | None = None) -> Color:
        value = self.deref(value, where)
        if _is_dict(value) and value.get("type") in TEXTURE_TYPES:
            return self.texture(value, where)
        if _is_dict(value) and value.get("type") not in ("rgb", "spectrum", "srgb"):
            kind = value.get("type")
            self.note(value, where, f"texture type {kind!r} not supported; grey 0.5 used")
            return (0.5, 0.5, 0.5)
        return self.color(value, where, parent)

    def number(self, d: Mapping[str, Any], key: str, default: float, where: str) -> float:
        v = d.get(key, default)
        if isinstance(v, str):
            v = IORS.get(v.lower(), v)
        if _is_dict(v) and v.get("type") in ("rgb", "spectrum") and "value" in v:
            arr = np.asarray(v["value"], np.float64).reshape(-1)
            v = float(arr.mean())
        try:
            out = float(v)
        except (TypeError, ValueError):
            raise self.fail(f"{where}.{key}", f"expected a number, got {v!r}", d) from None
        if not np.isfinite(out):
            raise self.fail(f"{where}.{key}", f"expected a finite number, got {v!r}", d)
        return out

    def flag(self, d: Mapping[str, Any], key: str, default: bool, where: str) -> bool:
        v = d.get(key, default)
        if isinstance(v, (bool, np.bool_)):
            return bool(v)
        if isinstance(v, str) and v.lower() in ("true", "false"):
            return v.lower() == "true"
        raise self.fail(f"{where}.{key}", f"expected true or false, got {v!r}", d)

    def path(self, name: Any, where: str, d: Mapping[str, Any] | None = None) -> Path:
        expanded = os.path.expandvars(str(name))
        if "$" in expanded:
            raise self.fail(where, f"{name!r} names an unset environment variable", d)
        p = Path(expanded)
        if not p.is_absolute() and self.base_dir is not None:
            p = self.base_dir / p
        if not p.exists():
            raise self.fail(where, f"file not found: {p}", d)
        return p

    def transform(self, d: Mapping[str, Any], key: str, where: str) -> np.ndarray:
        try:
            return tf.from_spec(d.get(key))
        except (ValueError, KeyError, TypeError) as exc:
            raise self.fail(f"{where}.{key}", f"bad transform: {exc}", d) from None

    # -- textures ----------------------------------------------------------------
    def uv_transform(self, d: Mapping[str, Any], where: str) -> tuple[tuple[float, float], tuple[float, float]]:
        su = self.number(d, "uscale", 1.0, where)
        sv = self.number(d, "vscale", 1.0, where)
        ou = self.number(d, "uoffset", 0.0, where)
        ov = self.number(d, "voffset", 0.0, where)
        if "to_uv" in d:
            m = self.transform(d, "to_uv", where)
            if abs(m[0, 1]) > 1e-9 or abs(m[1, 0]) > 1e-9:
                self.note(d, where, "to_uv rotation/shear not supported; its scale and offset used")
            su, sv, ou, ov = su * m[0, 0], sv * m[1, 1], ou + m[0, 3], ov + m[1, 3]
        return (su, sv), (ou, ov)

    def texture(self, d: Mapping[str, Any], where: str, scale: RGB = (1.0, 1.0, 1.0)) -> Bitmap | Checkerboard:
        d = self.deref(d, where)
        kind = d.get("type")
        if kind == "scale":
            inner = [(k, v) for k, v in d.items() if k not in _META_KEYS and _is_dict(v)
                     and self.deref(v, where).get("type") in TEXTURE_TYPES]
            if len(inner) != 1:
                raise self.fail(where, "a scale texture needs exactly one nested texture", d)
            self.note_unused(where, d, {"scale", inner[0][0]})
            s = np.multiply(scale, self.color(d.get("scale", 1.0), f"{where}.scale", d))
            return self.texture(inner[0][1], f"{where}.{inner[0][0]}", tuple(float(x) for x in s))
        uv_scale, uv_offset = self.uv_transform(d, where)
        uv_keys = {"uscale", "vscale", "uoffset", "voffset", "to_uv"}
        if kind == "checkerboard":
            self.note_unused(where, d, {"color0", "color1"} | uv_keys)
            return Checkerboard(self.color(d.get("color0", 0.4), f"{where}.color0", d),
                                self.color(d.get("color1", 0.2), f"{where}.color1", d),
                                uv_scale, uv_offset, scale)
        if kind != "bitmap":
            raise self.fail(where, f"unsupported texture type {kind!r} (bitmap, checkerboard, scale)", d)
        from pyclpt.scene.textures import load_bitmap

        self.note_unused(where, d, {"filename", "filter_type", "wrap_mode", "wrap_mode_u", "wrap_mode_v", "raw",
                                    "gamma", "max_anisotropy", "cache", "channel"} | uv_keys)
        if "filename" not in d:
            raise self.fail(where, "a bitmap texture needs a filename", d)
        path = self.path(d["filename"], f"{where}.filename", d)
        filt = str(d.get("filter_type", "bilinear")).lower()
        if filt not in ("bilinear", "nearest"):
            self.note(d, where, f"filter_type {filt}: bilinear filtering used (no mipmaps)")
            filt = "bilinear"
        wrap = str(d.get("wrap_mode", d.get("wrap_mode_u", "repeat"))).lower()
        wrap = {"zero": "black", "one": "clamp"}.get(wrap, wrap)
        if wrap not in ("repeat", "mirror", "clamp", "black"):
            raise self.fail(f"{where}.wrap_mode", f"unknown wrap mode {wrap!r} (repeat, mirror, clamp, zero)", d)
        if "wrap_mode_v" in d and str(d["wrap_mode_v"]).lower() != wrap:
            self.note(d, where, f"separate wrap_mode_v {d['wrap_mode_v']} not supported; {wrap} used")
        if "gamma" in d:
            self.note(d, where, "gamma ignored: the file's own encoding (sRGB for LDR) used")
        if "channel" in d:
            self.note(d, where, f"channel {d['channel']!r} ignored")
        raw = self.flag(d, "raw", False, where)
        key = (str(path), raw, filt, wrap, uv_scale, uv_offset, tuple(scale))
        if key not in self._textures:
            try:
                self._textures[key] = load_bitmap(path, raw=raw, filter=filt, wrap_mode=wrap, uv_scale=uv_scale,
                                                  uv_offset=uv_offset, scale=scale)
            except (OSError, ValueError) as exc:
                raise self.fail(where, str(exc), d) from None
        return self._textures[key]

    # -- BSDFs ------------------------------------------------------------------
    def nested(self, d: Mapping[str, Any], types: set[str], where: str) -> list[tuple[str, Mapping[str, Any]]]:
        out = []
        for k, v in d.items():
            if k in _META_KEYS or not _is_dict(v):
                continue
            target = self.deref(v, f"{where}.{k}")
            if target.get("type") in types:
                out.append((k, v))
        return out

    def bsdf(self, d: Mapping[str, Any], where: str) -> Material:
        kind = d.get("type")
        if kind == "twosided":
            inner = self.nested(d, BSDF_TYPES | OTHER_BSDF_TYPES, where)
            if not inner:
                raise self.fail(where, "twosided needs a nested BSDF", d)
            if len(inner) > 1:
                self.note(d, where, "a different back-side BSDF is not supported; the front one used on both")
            self.note_unused(where, d, {k for k, _ in inner})
            mat = self.resolve_bsdf(inner[0][1], f"{where}.{inner[0][0]}")
            return _twosided(mat)
        if kind in ("mask", "bumpmap"):
            inner = self.nested(d, BSDF_TYPES | OTHER_BSDF_TYPES, where)
            if len(inner) != 1:
                raise self.fail(where, f"{kind} needs exactly one nested BSDF", d)
            mat = self.resolve_bsdf(inner[0][1], f"{where}.{inner[0][0]}")
            if kind == "mask":
                self.note_unused(where, d, {"opacity", inner[0][0]})
                return Mask(self.color_or_texture(d.get("opacity", 0.5), f"{where}.opacity", d), mat)
            tex = self.nested(d, TEXTURE_TYPES, where)
            if len(tex) != 1:
                raise self.fail(where, "bumpmap needs exactly one nested texture (the height map)", d)
            self.note_unused(where, d, {tex[0][0], inner[0][0], "scale"})
            height = self.texture(tex[0][1], f"{where}.{tex[0][0]}")
            return BumpMap(height, mat, self.number(d, "scale", 1.0, where))
        if kind == "diffuse":
            self.note_unused(where, d, {"reflectance"})
            return Diffuse(self.color_or_texture(d.get("reflectance", 0.5), f"{where}.reflectance", d))
        if kind in ("conductor", "roughconductor"):
            return self.conductor(d, where)
        if kind in ("dielectric", "roughdielectric", "thindielectric"):
            return self.dielectric(d, where)
        if kind in ("plastic", "roughplastic"):
            used = {"diffuse_reflectance", "specular_reflectance", "int_ior", "ext_ior", "nonlinear"}
            alpha, dist = self.roughness(d, where, used) if kind == "roughplastic" else (0.0, "ggx")
            self.note_unused(where, d, used)
            int_ior, ext_ior = self.iors(d, where, 1.49)
            return Plastic(self.color_or_texture(d.get("diffuse_reflectance", 0.5), f"{where}.diffuse_reflectance", d),
                           self.color_or_texture(d.get("specular_reflectance", 1.0),
                                                 f"{where}.specular_reflectance", d),
                           int_ior, ext_ior, alpha, dist, self.flag(d, "nonlinear", False, where))
        if kind in OTHER_BSDF_TYPES:
            self.note(d, where, f"BSDF type {kind!r} not supported; grey diffuse (0.5) used")
            return Diffuse()
        raise self.fail(where, f"unsupported BSDF type {kind!r} (supported: {', '.join(sorted(BSDF_TYPES))})", d)

    def roughness(self, d: Mapping[str, Any], where: str, used: set[str]) -> tuple[float, str]:
        used |= {"alpha", "distribution", "alpha_u", "alpha_v", "sample_visible"}
        dist = str(d.get("distribution", "beckmann")).lower()  # Mitsuba's default
        if dist not in ("ggx", "beckmann"):
            self.note(d, where, f"microfacet distribution {dist!r} not supported; Beckmann used")
            dist = "beckmann"
        if "alpha_u" in d or "alpha_v" in d:
            au = self.number(d, "alpha_u", 0.1, where)
            av = self.number(d, "alpha_v", au, where)
            if au != av:
                self.note(d, where, f"anisotropic roughness ({au}, {av}) not supported; "
                                    f"alpha {np.sqrt(au * av):.4g} used")
            alpha = float(np.sqrt(au * av))
        else:
            alpha = self.number(d, "alpha", 0.1, where)
        if not 0.0 <= alpha <= 4.0:
            raise self.fail(f"{where}.alpha", f"roughness must be in [0, 4], got {alpha}", d)
        return max(alpha, 1e-4), dist

    def iors(self, d: Mapping[str, Any], where: str, default_int: float) -> tuple[float, float]:
        int_ior = self.number(d, "int_ior", default_int, where)
        ext_ior = self.number(d, "ext_ior", 1.000277, where)
        if int_ior <= 0 or ext_ior <= 0:
            raise self.fail(where, f"IORs must be positive, got {int_ior}, {ext_ior}", d)
        return int_ior, ext_ior

    def conductor(self, d: Mapping[str, Any], where: str) -> Conductor:
        used = {"material", "eta", "k", "specular_reflectance", "ext_eta"}
        alpha, dist = self.roughness(d, where, used) if d.get("type") == "roughconductor" else (0.0, "ggx")
        self.note_unused(where, d, used)
        metal = d.get("material", "none")
        if "eta" in d or "k" in d:
            eta = self.color(d.get("eta", 0.0), f"{where}.eta", d)
            k = self.color(d.get("k", 1.0), f"{where}.k", d)
        elif metal in METALS:
            eta, k = METALS[metal]
        else:
            raise self.fail(f"{where}.material", f"unknown metal {metal!r} (known: {', '.join(METALS)})", d)
        ext = self.number(d, "ext_eta", 1.0, where)
        if ext <= 0:
            raise self.fail(f"{where}.ext_eta", f"must be positive, got {ext}", d)
        eta = tuple(e / ext for e in eta)
        k = tuple(x / ext for x in k)
        spec = self.color_or_texture(d.get("specular_reflectance", 1.0), f"{where}.specular_reflectance", d)
        try:
            return Conductor(eta, k, alpha, spec, distribution=dist)
        except ValueError as exc:
            raise self.fail(where, str(exc), d) from None

    def dielectric(self, d: Mapping[str, Any], where: str) -> Dielectric | ThinDielectric:
        kind = d.get("type")
        used = {"int_ior", "ext_ior", "specular_reflectance", "specular_transmittance"}
        alpha, dist = self.roughness(d, where, used) if kind == "roughdielectric" else (0.0, "ggx")
        self.note_unused(where, d, used)
        int_ior, ext_ior = self.iors(d, where, 1.5046)
        spec_r = self.color_or_texture(d.get("specular_reflectance", 1.0), f"{where}.specular_reflectance", d)
        spec_t = self.color_or_texture(d.get("specular_transmittance", 1.0), f"{where}.specular_transmittance", d)
        if kind == "thindielectric":
            return ThinDielectric(int_ior, ext_ior, spec_r, spec_t)
        return Dielectric(int_ior, ext_ior, spec_r, spec_t, alpha, dist)

    def resolve_bsdf(self, d: Mapping[str, Any], where: str) -> Material:
        if d.get("type") == "ref":
            ref = d.get("id")
            if ref not in self.named:
                raise self.fail(where, f"reference to unknown BSDF id {ref!r}", d)
            self.referenced.add(ref)
            return self.bsdf(self.named[ref], ref)
        return self.bsdf(d, where)

    def material_index(self, d: Mapping[str, Any] | None, where: str) -> int:
        if d is None:
            key = "<default>"
        elif d.get("type") == "ref":
            key = f"id:{d.get('id')}"
        elif "id" in d:
            key = f"id:{d['id']}"
        else:
            key = None
        if key is not None and key in self.material_ids:
            return self.material_ids[key]
        mat: Material = Diffuse() if d is None else self.resolve_bsdf(d, where)
        self.materials.append(mat)
        idx = len(self.materials) - 1
        if key is not None:
            self.material_ids[key] = idx
        return idx

    # -- shapes -------------------------------------------------------------------
    def shape(self, name: str, d: Mapping[str, Any]) -> None:
        kind = d.get("type")
        where = name
        used = {"to_world", "flip_normals", "face_normals"}
        if kind in OTHER_SHAPE_TYPES:
            self.note(d, where, f"shape type {kind!r} not supported; shape skipped")
            return
        m = self.transform(d, "to_world", where)
        flip_v = True  # pyclpt's uv has v up with the image's top at v = 1; Mitsuba reads rows at v
        if kind in shape_lib.SHAPES:
            base = shape_lib.SHAPES[kind]()
            positions, indices, normals, uvs = base.positions, base.indices, base.normals, base.uvs
            if kind == "sphere":
                used |= {"center", "radius"}
                r = self.number(d, "radius", 1.0, where)
                try:
                    m = m @ tf.translate(d.get("center", (0.0, 0.0, 0.0))) @ tf.scale(r)
                except (ValueError, TypeError) as exc:
                    raise self.fail(f"{where}.center", str(exc), d) from None
        elif kind in MESH_FILE_TYPES:
            used |= {"filename", "flip_tex_coords", "shape_index", "max_smooth_angle"}
            if "filename" not in d:
                raise self.fail(where, f"{kind} shape needs a filename", d)
            mesh_path = self.path(d["filename"], f"{where}.filename", d)
            try:
                if kind == "serialized":
                    from pyclpt.scene.serialized import read_serialized

                    data = read_serialized(mesh_path, int(self.number(d, "shape_index", 0, where)))
                else:
                    from pyclpt.scene.mesh_io import load_mesh

                    data = load_mesh(mesh_path)
            except (OSError, ValueError) as exc:
                raise self.fail(where, str(exc), d) from None
            positions, indices, normals, uvs = data.positions, data.indices, data.normals, data.uvs
            if kind == "obj":
                # Mitsuba flips OBJ texture coordinates by default (flip_tex_coords), which
                # already is pyclpt's convention.
                flip_v = not self.flag(d, "flip_tex_coords", True, where)
            if "max_smooth_angle" in d:
                self.note(d, where, "max_smooth_angle ignored: the file's normals (or face normals) used")
        elif kind == "mesh":
            used |= {"positions", "indices", "normals", "uvs"}
            if "positions" not in d or "indices" not in d:
                raise self.fail(where, "a mesh shape needs positions and indices", d)
            positions, indices = d["positions"], d["indices"]
            normals, uvs = d.get("normals"), d.get("uvs")
        else:
            raise self.fail(where, f"unsupported shape type {kind!r} "
                                   f"(supported: {', '.join(sorted(SHAPE_TYPES))})", d)
        for k, v in d.items():
            if k.split("_")[0] in ("bsdf", "emitter") and not _is_dict(v):
                raise self.fail(f"{where}.{k}", f"expected a {k.split('_')[0]} dict or ref, got {v!r}", d)
        # nested objects keyed bsdf*/emitter* are that (an unknown type is then an error)
        bsdfs = [(k, v) for k, v in d.items() if _is_dict(v) and k not in _META_KEYS and (
            k.startswith("bsdf") or self.deref(v, f"{where}.{k}").get("type") in BSDF_TYPES | OTHER_BSDF_TYPES)]
        emitters = [(k, v) for k, v in d.items() if _is_dict(v) and k not in _META_KEYS and (
            k.startswith("emitter")
            or self.deref(v, f"{where}.{k}").get("type") in EMITTER_TYPES | OTHER_EMITTER_TYPES)]
        others = [k for k, v in d.items() if k not in _META_KEYS and _is_dict(v)
                  and k not in {b for b, _ in bsdfs} | {e for e, _ in emitters} and k not in used]
        for k in others:
            self.note(d[k] if _is_dict(d[k]) else d, f"{where}.{k}",
                      f"{d[k].get('type')!r} inside a shape not supported; ignored")
        self.note_unused(where, {k: v for k, v in d.items() if k not in others}, used | {b for b, _ in bsdfs}
                         | {e for e, _ in emitters})
        try:
            positions = tf.apply_points(m, np.asarray(positions, np.float64).reshape(-1, 3))
            face_normals = self.flag(d, "face_normals", False, where)
            if normals is not None and not face_normals:
                normals = tf.apply_normals(m, np.asarray(normals, np.float64).reshape(-1, 3))
            else:
                normals = None
            indices = np.asarray(indices, np.int32).reshape(-1, 3)
            if uvs is not None:
                uvs = np.array(uvs, np.float32).reshape(-1, 2)
                if flip_v:
                    uvs[:, 1] = 1.0 - uvs[:, 1]
        except (ValueError, TypeError) as exc:
            raise self.fail(where, f"bad mesh data: {exc}", d) from None
        if np.linalg.det(m[:3, :3]) < 0:
            indices = indices[:, ::-1].copy()  # a mirroring transform keeps the outward side
        if self.flag(d, "flip_normals", False, where):
            indices = indices[:, ::-1].copy()
            if normals is not None:
                normals = -normals
        if len(bsdfs) > 1:
            self.note(d, where, f"{len(bsdfs)} BSDFs given; the first used")
        material = self.material_index(bsdfs[0][1] if bsdfs else None,
                                       f"{where}.{bsdfs[0][0]}" if bsdfs else where)
        emission = None
        for key, em in emitters:
            em = self.deref(em, f"{where}.{key}")
            if em.get("type") != "area":
                raise self.fail(f"{where}.{key}", f"only 'area' emitters attach to shapes, got {em.get('type')!r}", em)
            self.note_unused(f"{where}.{key}", em, {"radiance"})
            emission = self.color(em.get("radiance", 1.0), f"{where}.{key}.radiance", em)
        try:
            self.meshes.append(Mesh(name, positions, indices, material, normals, uvs, emission))
        except ValueError as exc:
            raise self.fail(where, str(exc), d) from None

    # -- emitters -------------------------------------------------------------------
    def emitter(self, name: str, d: Mapping[str, Any]) -> None:
        kind = d.get("type")
        where = name
        if kind == "area":
            self.note(d, where, "an area emitter outside a shape emits nothing; ignored")
            return
        if kind in OTHER_EMITTER_TYPES:
            self.note(d, where, f"emitter type {kind!r} not supported; ignored")
            return
        if kind == "point":
            self.note_unused(where, d, {"position", "intensity", "to_world"})
            pos = np.zeros(3)
            if "to_world" in d:
                pos = self.transform(d, "to_world", where)[:3, 3]
            if "position" in d:
                try:
                    pos = np.asarray(d["position"], np.float64).reshape(3)
                except (ValueError, TypeError):
                    raise self.fail(f"{where}.position", f"expected 3 numbers, got {d['position']!r}", d) from None
            try:
                self.lights.append(PointLight(tuple(pos), self.color(d.get("intensity", 1.0),
                                                                     f"{where}.intensity", d)))
            except ValueError as exc:
                raise self.fail(where, str(exc), d) from None
            return
        if self.environment is not None:
            self.note(d, where, "a second environment emitter is not supported; ignored")
            return
        if kind == "constant":
            self.note_unused(where, d, {"radiance"})
            self.environment = self.color(d.get("radiance", 1.0), f"{where}.radiance", d)
        elif kind == "envmap":
            from pyclpt.scene.textures import read_texture_image

            self.note_unused(where, d, {"filename", "to_world", "scale"})
            if "filename" not in d:
                raise self.fail(where, "an envmap needs a filename", d)
            path = self.path(d["filename"], f"{where}.filename", d)
            try:
                pixels, ldr = read_texture_image(path)
                if ldr:
                    from pyclpt.common.image_io import srgb_to_linear

                    pixels = srgb_to_linear(pixels)
                    self.note(d, where, "an 8-bit environment map, decoded from sRGB")
                if pixels.shape[2] < 3:
                    pixels = np.repeat(pixels[:, :, :1], 3, axis=2)
                self.environment = Envmap(pixels[:, :, :3], self.transform(d, "to_world", where),
                                          self.number(d, "scale", 1.0, where), path.name)
            except (OSError, ValueError) as exc:
                raise self.fail(where, str(exc), d) from None
        elif kind in ("sunsky", "sky", "sun"):
            self.environment = self.sunsky(name, d)
        else:
            raise self.fail(where, f"unsupported emitter type {kind!r} "
                                   f"(supported: {', '.join(sorted(EMITTER_TYPES))})", d)

    def sunsky(self, where: str, d: Mapping[str, Any]) -> Envmap:
        from pyclpt.scene.sunsky import sunsky_envmap

        kind = d.get("type")
        used = {"turbidity", "sun_direction", "sky_scale", "sun_scale", "sun_radius_scale", "resolution",
                "albedo", "to_world", "scale"}
        self.note_unused(where, d, used)
        if "sun_direction" not in d:
            raise self.fail(where, f"{kind} needs sun_direction (latitude/longitude/time are not supported)", d)
        try:
            direction = np.asarray(d["sun_direction"], np.float64).reshape(3)
        except (ValueError, TypeError):
            raise self.fail(f"{where}.sun_direction", f"expected 3 numbers, got {d['sun_direction']!r}", d) from None
        scale = self.number(d, "scale", 1.0, where)
        sky_scale = self.number(d, "sky_scale", scale, where) if kind != "sun" else 0.0
        sun_scale = self.number(d, "sun_scale", scale, where) if kind != "sky" else 0.0
        albedo = self.color(d.get("albedo", 0.15), f"{where}.albedo", d)
        try:
            return sunsky_envmap(direction, turbidity=self.number(d, "turbidity", 3.0, where),
                                 sky_scale=sky_scale, sun_scale=sun_scale,
                                 sun_radius_scale=self.number(d, "sun_radius_scale", 1.0, where),
                                 resolution=int(self.number(d, "resolution", 512, where)),
                                 albedo=float(np.mean(albedo)),
                                 to_world=self.transform(d, "to_world", where) if "to_world" in d else None)
        except ValueError as exc:
            raise self.fail(where, str(exc), d) from None

    # -- the whole scene ------------------------------------------------------------
    def register_nested_ids(self, d: Mapping[str, Any]) -> None:
        """Objects nested anywhere may carry an id that others reference (Mitsuba allows it)."""
        for v in d.values():
            if _is_dict(v) and v.get("type") != "ref":
                if "id" in v:
                    self.named.setdefault(str(v["id"]), v)
                self.register_nested_ids(v)

    def classify(self, key: str, value: Mapping[str, Any]) -> str:
        kind = value.get("type")
        if kind in BSDF_TYPES or kind in OTHER_BSDF_TYPES:
            return "bsdf"
        if kind in TEXTURE_TYPES:
            return "texture"
        if kind in SHAPE_TYPES or kind in OTHER_SHAPE_TYPES:
            return "shape"
        if kind in EMITTER_TYPES or kind in OTHER_EMITTER_TYPES:
            return "emitter"
        if key.startswith("integrator") or kind in INTEGRATOR_TYPES:
            return "integrator"
        if key.startswith("sensor") or kind in SENSOR_TYPES:
            return "sensor"
        return "other"

    def scene(self, d: Mapping[str, Any], name: str) -> Scene:
        if d.get("type") != "scene":
            raise self.fail("<root>", "the top-level dict must have type 'scene'", d)
        camera, film, spp, max_depth = Camera(), Film(), 64, -1
        entries = [(k, v) for k, v in d.items() if k not in _META_KEYS]
        for key, value in entries:
            if not _is_dict(value):
                raise self.fail(key, f"expected a dict, got {value!r}", d)
            self.named[str(value.get("id", key))] = value
            self.register_nested_ids(value)
        have_sensor = have_integrator = False
        for key, value in entries:
            role = self.classify(key, value)
            if role in ("bsdf", "texture"):
                continue  # used through references
            if role == "sensor":
                if have_sensor:
                    self.note(value, key, "a second sensor is not supported; ignored")
                    continue
                have_sensor = True
                camera, film, spp = self.sensor(value, key)
            elif role == "integrator":
                if have_integrator:
                    self.note(value, key, "a second integrator ignored")
                    continue
                have_integrator = True
                max_depth = self.integrator(key, value)
            elif role == "shape":
                self.shape(key, value)
            elif role == "emitter":
                self.emitter(key, value)
            elif value.get("type") in OTHER_TOP_TYPES or key.split("_")[0] in OTHER_TAGS:
                self.note(value, key, f"{value.get('type')!r} not supported; ignored")
            else:
                raise self.fail(key, f"unsupported element type {value.get('type')!r}", value)
        if not self.meshes:
            raise self.fail("<root>", "the scene has no shapes", d)
        for key, value in entries:
            ident = str(value.get("id", key))
            if self.classify(key, value) in ("bsdf", "texture") and ident not in self.referenced:
                self.note(value, key, f"{value.get('type')} defined but never referenced by a shape; unused")
        if self.notes:
            warnings.warn(f"{self.origin}: not used by pyclpt ({len(self.notes)}):\n  "
                          + "\n  ".join(self.notes), stacklevel=3)
        return Scene(self.meshes, self.materials, camera, film, self.environment, spp, max_depth, name,
                     lights=self.lights)

    def integrator(self, key: str, value: Mapping[str, Any]) -> int:
        kind = value.get("type")
        inner = [v for k, v in value.items() if k not in _META_KEYS and _is_dict(v)]
        if kind not in ("path", "volpath", "volpathmis"):
            self.note(value, key, f"integrator {kind!r}: pyclpt's path tracer used")
        elif kind != "path":
            self.note(value, key, f"integrator {kind!r}: pyclpt's path tracer (no media) used")
        if kind in ("adaptive", "irrcache", "multichannel") and inner:
            value = inner[0]  # a wrapper: take the depth of the nested integrator
        max_depth = int(self.number(value, "max_depth", -1, key))
        if max_depth < -1:
            raise self.fail(f"{key}.max_depth", f"must be -1 (unlimited) or >= 0, got {max_depth}", value)
        if kind in ("path", "volpath", "volpathmis"):
            self.note_unused(key, value, {"max_depth"})
        return max_depth

    def sensor(self, d: Mapping[str, Any], where: str) -> tuple[Camera, Film, int]:
        kind = d.get("type", "perspective")
        if kind == "thinlens":
            self.note(d, where, "thinlens: a pinhole camera used (no depth of field)")
        elif kind != "perspective":
            raise self.fail(where, f"unsupported sensor type {kind!r} (perspective, thinlens)", d)
        film_d = d.get("film") if _is_dict(d.get("film")) else next(
            (v for v in d.values() if _is_dict(v) and v.get("type") in ("hdrfilm", "ldrfilm", "specfilm")), None)
        sampler_d = d.get("sampler") if _is_dict(d.get("sampler")) else next(
            (v for v in d.values() if _is_dict(v) and v.get("type") in (
                "independent", "stratified", "multijitter", "ldsampler", "halton", "sobol", "hammersley",
                "orthogonal")), None)
        nested_keys = {k for k, v in d.items() if v is film_d or v is sampler_d}
        self.note_unused(where, d, {"fov", "fov_axis", "to_world", "near_clip", "far_clip", "focus_distance",
                                    "focal_length", "aperture_radius"} | nested_keys)
        fov = self.number(d, "fov", 45.0, where)
        if "focal_length" in d and "fov" not in d:
            text = str(d["focal_length"]).lower().replace("mm", "")
            try:
                fov = float(np.degrees(2 * np.arctan(36.0 / (2 * float(text)))))
            except ValueError:
                raise self.fail(f"{where}.focal_length", f"expected e.g. '50mm', got {d['focal_length']!r}",
                                d) from None
        try:
            camera = Camera(self.transform(d, "to_world", where), fov, str(d.get("fov_axis", "x")).lower())
        except ValueError as exc:
            raise self.fail(where, str(exc), d) from None
        f = film_d or {}
        rfilter = next((v for v in f.values() if _is_dict(v)), None)
        self.note_unused(f"{where}.film", {k: v for k, v in f.items() if v is not rfilter},
                         {"width", "height", "pixel_format", "component_format", "file_format", "banner",
                          "high_quality_edges", "rfilter"})
        if rfilter is not None and rfilter.get("type", "box") != "box":
            self.note(rfilter, f"{where}.film.rfilter", f"reconstruction filter {rfilter.get('type')!r}: "
                                                        "box filter used")
        try:
            film = Film(int(self.number(f, "width", 768, f"{where}.film")),
                        int(self.number(f, "height", 576, f"{where}.film")))
        except (TypeError, ValueError) as exc:
            raise self.fail(f"{where}.film", str(exc), f) from None
        s = sampler_d or {}
        if s and s.get("type", "independent") != "independent":
            self.note(s, f"{where}.sampler", f"sampler {s.get('type')!r}: pyclpt's independent "
                                             "counter-based sampler used")
        self.note_unused(f"{where}.sampler", s, {"sample_count", "seed"})
        spp = int(self.number(s, "sample_count", 64, f"{where}.sampler"))
        if spp < 1:
            raise self.fail(f"{where}.sampler.sample_count", f"must be >= 1, got {spp}", s)
        return camera, film, spp


def _twosided(mat: Material) -> Material:
    """The material made two-sided (dielectrics already are; wrappers pass it inward)."""
    if isinstance(mat, (Mask, BumpMap)):
        return type(mat)(**{**mat.__dict__, "material": _twosided(mat.material)})
    if isinstance(mat, (Dielectric, ThinDielectric)):
        return mat
    return type(mat)(**{**mat.__dict__, "twosided": True})


def load_dict(d: Mapping[str, Any], *, base_dir: str | os.PathLike | None = None,
              name: str = "scene", origin: str | None = None) -> Scene:
    """A Scene from a Mitsuba-3-style dict; relative file names resolve against ``base_dir``."""
    loader = _Loader(Path(base_dir) if base_dir is not None else None, origin or name)
    return loader.scene(d, name)
