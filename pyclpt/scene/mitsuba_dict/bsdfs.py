"""Mitsuba BSDF plug-ins: one small loader per plug-in, turning its dictionary into a model material.

:data:`BSDFS` maps a plug-in name to its loader (``diffuse``, the conductors, dielectrics and plastics,
and the wrappers ``twosided``, ``mask``, ``bumpmap``); :data:`UNSUPPORTED` names the Mitsuba BSDFs pyclpt
does not have, which load as grey diffuse with a note. :func:`material_index` gives a shape its index into
the scene's material list, sharing one entry per referenced id.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from pyclpt.scene.mitsuba_dict.context import LoadContext, SceneDictError
from pyclpt.scene.mitsuba_dict.textures import TEXTURES, color, color_or_texture, load_texture
from pyclpt.scene.model import (
    RGB,
    BumpMap,
    Conductor,
    Dielectric,
    Diffuse,
    Mask,
    Material,
    Plastic,
    ThinDielectric,
    TwoSided,
    base_material,
)

BsdfLoader = Callable[[LoadContext, Mapping[str, Any], str], Material]

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

#: Mitsuba BSDFs pyclpt does not have: reported, and a grey diffuse used instead.
UNSUPPORTED = frozenset({"blendbsdf", "coating", "roughcoating", "phong", "ward", "hk", "null", "difftrans",
                         "principled", "principledthin", "measured", "polarizer", "retarder", "pplastic", "irawan",
                         "roughdiffuse", "dipole", "normalmap", "mixturebsdf", "bsdf"})


# -- shared parameters -----------------------------------------------------------------------------

def roughness(ctx: LoadContext, d: Mapping[str, Any], where: str, used: set[str],
              anisotropic: bool = True) -> tuple[float, float | None, str]:
    """``alpha`` (or ``alpha_u``), ``alpha_v`` (None when isotropic) and the distribution; adds their keys to
    ``used``. ``anisotropic=False`` (Mitsuba's roughplastic, which has only ``alpha``): the geometric mean of
    ``alpha_u``/``alpha_v``, with a note."""
    used |= {"alpha", "distribution", "alpha_u", "alpha_v", "sample_visible"}
    dist = str(d.get("distribution", "beckmann")).lower()  # Mitsuba's default
    if dist not in ("ggx", "beckmann"):
        ctx.note(d, where, f"microfacet distribution {dist!r} not supported, Beckmann used")
        dist = "beckmann"
    alpha_v = None
    if "alpha_u" in d or "alpha_v" in d:
        au = ctx.number(d, "alpha_u", 0.1, where)
        av = ctx.number(d, "alpha_v", au, where)
        for name, a in (("alpha_u", au), ("alpha_v", av)):
            if not 0.0 <= a <= 4.0:
                raise ctx.fail(f"{where}.{name}", f"roughness must be in [0, 4], got {a}", d)
        if au == av:
            alpha = au
        elif anisotropic:  # Mitsuba clamps each to 1e-4
            alpha, alpha_v = au, max(av, 1e-4)
        else:
            ctx.note(d, where, f"anisotropic roughness ({au}, {av}) not supported by {d.get('type')}, "
                               f"alpha {np.sqrt(au * av):.4g} used")
            alpha = float(np.sqrt(au * av))
    else:
        alpha = ctx.number(d, "alpha", 0.1, where)
    if not 0.0 <= alpha <= 4.0:
        raise ctx.fail(f"{where}.alpha", f"roughness must be in [0, 4], got {alpha}", d)
    return max(alpha, 1e-4), alpha_v, dist


def iors(ctx: LoadContext, d: Mapping[str, Any], where: str, default_int: float) -> tuple[float, float]:
    int_ior = ctx.number(d, "int_ior", default_int, where)
    ext_ior = ctx.number(d, "ext_ior", 1.000277, where)
    if int_ior <= 0 or ext_ior <= 0:
        raise ctx.fail(where, f"IORs must be positive, got {int_ior}, {ext_ior}", d)
    return int_ior, ext_ior


def _is_rough(d: Mapping[str, Any]) -> bool:
    return str(d.get("type", "")).startswith("rough")


# -- materials -------------------------------------------------------------------------------------

def load_diffuse(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Material:
    ctx.note_unused(where, d, {"reflectance"})
    return Diffuse(color_or_texture(ctx, d.get("reflectance", 0.5), f"{where}.reflectance", d))


def load_conductor(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Material:
    """``conductor`` and ``roughconductor``: a named metal or explicit eta/k, relative to ``ext_eta``."""
    used = {"material", "eta", "k", "specular_reflectance", "ext_eta"}
    alpha, alpha_v, dist = roughness(ctx, d, where, used) if _is_rough(d) else (0.0, None, "ggx")
    ctx.note_unused(where, d, used)
    metal = d.get("material", "none")
    if "eta" in d or "k" in d:
        eta = color(ctx, d.get("eta", 0.0), f"{where}.eta", d)
        k = color(ctx, d.get("k", 1.0), f"{where}.k", d)
    elif metal in METALS:
        eta, k = METALS[metal]
    else:
        raise ctx.fail(f"{where}.material", f"unknown metal {metal!r} (known: {', '.join(METALS)})", d)
    ext = ctx.number(d, "ext_eta", 1.0, where)
    if ext <= 0:
        raise ctx.fail(f"{where}.ext_eta", f"must be positive, got {ext}", d)
    eta = tuple(e / ext for e in eta)
    k = tuple(x / ext for x in k)
    spec = color_or_texture(ctx, d.get("specular_reflectance", 1.0), f"{where}.specular_reflectance", d)
    return Conductor(eta, k, alpha, spec, distribution=dist, alpha_v=alpha_v)


def _dielectric_params(ctx: LoadContext, d: Mapping[str, Any], where: str, rough: bool):
    used = {"int_ior", "ext_ior", "specular_reflectance", "specular_transmittance"}
    alpha, alpha_v, dist = roughness(ctx, d, where, used) if rough else (0.0, None, "ggx")
    ctx.note_unused(where, d, used)
    int_ior, ext_ior = iors(ctx, d, where, 1.5046)
    spec_r = color_or_texture(ctx, d.get("specular_reflectance", 1.0), f"{where}.specular_reflectance", d)
    spec_t = color_or_texture(ctx, d.get("specular_transmittance", 1.0), f"{where}.specular_transmittance", d)
    return int_ior, ext_ior, spec_r, spec_t, alpha, alpha_v, dist


def load_dielectric(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Material:
    """``dielectric`` and ``roughdielectric``."""
    int_ior, ext_ior, spec_r, spec_t, alpha, alpha_v, dist = _dielectric_params(ctx, d, where, _is_rough(d))
    return Dielectric(int_ior, ext_ior, spec_r, spec_t, alpha, dist, alpha_v)


def load_thindielectric(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Material:
    int_ior, ext_ior, spec_r, spec_t, _, _, _ = _dielectric_params(ctx, d, where, rough=False)
    return ThinDielectric(int_ior, ext_ior, spec_r, spec_t)


def load_plastic(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Material:
    """``plastic`` and ``roughplastic``."""
    used = {"diffuse_reflectance", "specular_reflectance", "int_ior", "ext_ior", "nonlinear"}
    alpha, _, dist = roughness(ctx, d, where, used, anisotropic=False) if _is_rough(d) else (0.0, None, "ggx")
    ctx.note_unused(where, d, used)
    int_ior, ext_ior = iors(ctx, d, where, 1.49)
    return Plastic(color_or_texture(ctx, d.get("diffuse_reflectance", 0.5), f"{where}.diffuse_reflectance", d),
                   color_or_texture(ctx, d.get("specular_reflectance", 1.0), f"{where}.specular_reflectance", d),
                   int_ior, ext_ior, alpha, dist, ctx.flag(d, "nonlinear", False, where))


# -- wrappers --------------------------------------------------------------------------------------

def make_twosided(mat: Material) -> Material:
    """The material made two-sided (dielectrics already are; wrappers pass it inward)."""
    if isinstance(mat, (Mask, BumpMap)):
        return dataclasses.replace(mat, material=make_twosided(mat.material))
    if isinstance(mat, (Dielectric, ThinDielectric, TwoSided)):  # already two-sided
        return mat
    return dataclasses.replace(mat, twosided=True)


def _inner_bsdfs(ctx: LoadContext, d: Mapping[str, Any], where: str) -> list[tuple[str, Mapping[str, Any]]]:
    return ctx.nested(d, BSDFS.keys() | UNSUPPORTED, where)


def load_twosided(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Material:
    """One nested BSDF: it on both sides. Two: the first on the front, the second on the back (seeing the
    directions mirrored to its front), as Mitsuba's; neither may transmit (Mitsuba refuses that too)."""
    inner = _inner_bsdfs(ctx, d, where)
    if not inner or len(inner) > 2:
        raise ctx.fail(where, f"twosided needs one or two nested BSDFs, got {len(inner)}", d)
    ctx.note_unused(where, d, {k for k, _ in inner})
    sides = [resolve_bsdf(ctx, v, f"{where}.{k}") for k, v in inner]
    if len(sides) == 1 or sides[0] == sides[1]:
        return make_twosided(sides[0])
    bases = []
    for (key, _), mat in zip(inner, sides):
        if isinstance(mat, (Mask, BumpMap)):
            ctx.note(d, where, f"a {type(mat).__name__.lower()} inside a twosided with two BSDFs is not "
                               f"supported (put it around the twosided), {key}'s BSDF used without it")
            mat = base_material(mat)
        if isinstance(mat, (Dielectric, ThinDielectric)):
            raise ctx.fail(f"{where}.{key}", "twosided: only materials without transmission can be nested", d)
        bases.append(mat)
    return TwoSided(bases[0], bases[1])


def _one_inner_bsdf(ctx: LoadContext, d: Mapping[str, Any], where: str) -> tuple[str, Material]:
    inner = _inner_bsdfs(ctx, d, where)
    if len(inner) != 1:
        raise ctx.fail(where, f"{d.get('type')} needs exactly one nested BSDF", d)
    return inner[0][0], resolve_bsdf(ctx, inner[0][1], f"{where}.{inner[0][0]}")


def load_mask(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Material:
    key, mat = _one_inner_bsdf(ctx, d, where)
    ctx.note_unused(where, d, {"opacity", key})
    return Mask(color_or_texture(ctx, d.get("opacity", 0.5), f"{where}.opacity", d), mat)


def load_bumpmap(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Material:
    key, mat = _one_inner_bsdf(ctx, d, where)
    tex = ctx.nested(d, TEXTURES, where)
    if len(tex) != 1:
        raise ctx.fail(where, "bumpmap needs exactly one nested texture (the height map)", d)
    ctx.note_unused(where, d, {tex[0][0], key, "scale"})
    height = load_texture(ctx, tex[0][1], f"{where}.{tex[0][0]}")
    return BumpMap(height, mat, ctx.number(d, "scale", 1.0, where))


#: Mitsuba BSDF plug-ins pyclpt loads, by name.
BSDFS: dict[str, BsdfLoader] = {
    "diffuse": load_diffuse,
    "conductor": load_conductor,
    "roughconductor": load_conductor,
    "dielectric": load_dielectric,
    "roughdielectric": load_dielectric,
    "thindielectric": load_thindielectric,
    "plastic": load_plastic,
    "roughplastic": load_plastic,
    "twosided": load_twosided,
    "mask": load_mask,
    "bumpmap": load_bumpmap,
}


# -- dispatch --------------------------------------------------------------------------------------

def load_bsdf(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Material:
    """The material of BSDF object ``d``; an unsupported Mitsuba BSDF is grey diffuse, with a note."""
    kind = d.get("type")
    loader = BSDFS.get(kind)
    if loader is None:
        if kind in UNSUPPORTED:
            ctx.note(d, where, f"BSDF type {kind!r} not supported, grey diffuse (0.5) used")
            return Diffuse()
        raise ctx.fail(where, f"unsupported BSDF type {kind!r} (supported: {', '.join(sorted(BSDFS))})", d)
    try:
        return loader(ctx, d, where)
    except SceneDictError:
        raise
    except ValueError as exc:  # the model's own checks
        raise ctx.fail(where, str(exc), d) from None


def resolve_bsdf(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Material:
    """:func:`load_bsdf` of ``d`` or of the BSDF it references (then named after its id)."""
    if d.get("type") == "ref":
        ref = d.get("id")
        if ref not in ctx.named:
            raise ctx.fail(where, f"reference to unknown BSDF id {ref!r}", d)
        ctx.referenced.add(ref)
        return load_bsdf(ctx, ctx.named[ref], ref)
    return load_bsdf(ctx, d, where)


def material_index(ctx: LoadContext, d: Mapping[str, Any] | None, where: str, *, black: bool = False) -> int:
    """The index into the scene's materials of BSDF ``d`` (None: the default grey diffuse, or with ``black``
    a black one: Mitsuba 3's default for an area emitter's shape), loading it the first time; a referenced
    or named BSDF (and each default) is one material however many shapes use it."""
    if d is None:
        key = "<default-black>" if black else "<default>"
    elif d.get("type") == "ref":
        key = f"id:{d.get('id')}"
    elif "id" in d:
        key = f"id:{d['id']}"
    else:
        key = None
    if key is not None and key in ctx.material_ids:
        return ctx.material_ids[key]
    mat: Material = (Diffuse((0.0, 0.0, 0.0)) if black else Diffuse()) if d is None else resolve_bsdf(ctx, d, where)
    ctx.materials.append(mat)
    idx = len(ctx.materials) - 1
    # Mitsuba's name of the BSDF: its id, else its place in the shape (traverse's names)
    ctx.ids[f"material:{idx}"] = key[3:] if key is not None and key.startswith("id:") else (
        "default_bsdf" if d is None else where)
    if key is not None:
        ctx.material_ids[key] = idx
    return idx
