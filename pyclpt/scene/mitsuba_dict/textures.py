"""Mitsuba texture plug-ins (``bitmap``, ``checkerboard``, ``scale``) and the colour readers that accept them.

:data:`TEXTURES` maps a plug-in name to its loader; :func:`load_texture` dispatches on it.
:func:`color` reads a constant colour (a texture there is replaced by its mean colour, with a note);
:func:`color_or_texture` keeps textures, for the parameters that the device looks up per point.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from pyclpt.scene.mitsuba_dict.context import CONSTANT_COLOR_TYPES, META_KEYS, LoadContext, SceneDictError, is_dict
from pyclpt.scene.model import RGB, Bitmap, Checkerboard, Color, rgb

Texture = Bitmap | Checkerboard
TextureLoader = Callable[[LoadContext, Mapping[str, Any], str, RGB], Texture]

_UV_KEYS = frozenset({"uscale", "vscale", "uoffset", "voffset", "to_uv"})


# (u, v) -> (u, 1 - v): Mitsuba's texture coordinates (v down from the image's top) <-> pyclpt's (v up)
FLIP_V = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 1.0], [0.0, 0.0, 1.0]])


def uv_transform(ctx: LoadContext, d: Mapping[str, Any], where: str) -> dict[str, tuple[float, float]]:
    """The texture's uv transform (Mitsuba 0.x ``uscale``/``vscale``/``uoffset``/``voffset``, then 3.x
    ``to_uv``, rotation and shear included) as the model's ``uv_scale``, ``uv_skew`` and ``uv_offset``.
    Mitsuba applies it to its own coordinates, whose v runs down from the image's top; pyclpt's v runs
    up (v = 1 - v_mitsuba), so the matrix is conjugated by that flip: M' = F M F."""
    su = ctx.number(d, "uscale", 1.0, where)
    sv = ctx.number(d, "vscale", 1.0, where)
    ou = ctx.number(d, "uoffset", 0.0, where)
    ov = ctx.number(d, "voffset", 0.0, where)
    m = np.array([[su, 0.0, ou], [0.0, sv, ov], [0.0, 0.0, 1.0]])
    if "to_uv" in d:
        t = ctx.transform(d, "to_uv", where)
        m = np.array([[t[0, 0], t[0, 1], t[0, 3]], [t[1, 0], t[1, 1], t[1, 3]], [0.0, 0.0, 1.0]]) @ m
    p = FLIP_V @ m @ FLIP_V
    return {"uv_scale": (float(p[0, 0]), float(p[1, 1])), "uv_skew": (float(p[0, 1]), float(p[1, 0])),
            "uv_offset": (float(p[0, 2]), float(p[1, 2]))}


def load_scale(ctx: LoadContext, d: Mapping[str, Any], where: str, scale: RGB) -> Texture:
    """``scale``: the one nested texture, its values multiplied by ``scale``."""
    inner = [(k, v) for k, v in d.items() if k not in META_KEYS and is_dict(v)
             and ctx.deref(v, where).get("type") in TEXTURES]
    if len(inner) != 1:
        raise ctx.fail(where, "a scale texture needs exactly one nested texture", d)
    ctx.note_unused(where, d, {"scale", inner[0][0]})
    s = np.multiply(scale, color(ctx, d.get("scale", 1.0), f"{where}.scale", d))
    return load_texture(ctx, inner[0][1], f"{where}.{inner[0][0]}", tuple(float(x) for x in s))


def load_checkerboard(ctx: LoadContext, d: Mapping[str, Any], where: str, scale: RGB) -> Texture:
    uv = uv_transform(ctx, d, where)
    ctx.note_unused(where, d, {"color0", "color1"} | _UV_KEYS)
    return Checkerboard(color(ctx, d.get("color0", 0.4), f"{where}.color0", d),
                        color(ctx, d.get("color1", 0.2), f"{where}.color1", d), scale=scale, **uv)


def load_bitmap(ctx: LoadContext, d: Mapping[str, Any], where: str, scale: RGB) -> Texture:
    """``bitmap``: an image file, decoded once per file and sampling settings."""
    from pyclpt.scene.textures import load_bitmap as read_bitmap

    uv = uv_transform(ctx, d, where)
    ctx.note_unused(where, d, {"filename", "data", "filter_type", "wrap_mode", "wrap_mode_u", "wrap_mode_v", "raw",
                               "gamma", "max_anisotropy", "cache", "channel"} | _UV_KEYS)
    if ("filename" in d) == ("data" in d):
        raise ctx.fail(where, "a bitmap texture needs a filename or data (an (H, W, C) array of linear values), "
                              "one of them", d)
    filt = str(d.get("filter_type", "bilinear")).lower()
    if filt not in ("bilinear", "nearest"):
        ctx.note(d, where, f"filter_type {filt}: bilinear filtering used (no mipmaps)")
        filt = "bilinear"
    wrap = str(d.get("wrap_mode", d.get("wrap_mode_u", "repeat"))).lower()
    wrap = {"zero": "black", "one": "clamp"}.get(wrap, wrap)
    if wrap not in ("repeat", "mirror", "clamp", "black"):
        raise ctx.fail(f"{where}.wrap_mode", f"unknown wrap mode {wrap!r} (repeat, mirror, clamp, zero)", d)
    if "wrap_mode_v" in d and str(d["wrap_mode_v"]).lower() != wrap:
        ctx.note(d, where, f"separate wrap_mode_v {d['wrap_mode_v']} not supported, {wrap} used")
    if "gamma" in d:
        ctx.note(d, where, "gamma ignored: the file's own encoding (sRGB for LDR) used")
    if "channel" in d:
        ctx.note(d, where, f"channel {d['channel']!r} ignored")
    if "data" in d:  # texels given as an array: linear values (Mitsuba's bitmap `data`)
        try:
            return Bitmap(np.array(d["data"], np.float32), name=f"{where}.data", srgb=False, filter=filt,
                          wrap_mode=wrap, scale=scale, **uv)
        except (ValueError, TypeError) as exc:
            raise ctx.fail(where, str(exc), d) from None
    path = ctx.path(d["filename"], f"{where}.filename", d)
    raw = ctx.flag(d, "raw", False, where)
    key = (str(path), raw, filt, wrap, *uv.values(), tuple(scale))
    if key not in ctx.bitmaps:
        try:
            ctx.bitmaps[key] = read_bitmap(path, raw=raw, filter=filt, wrap_mode=wrap, scale=scale, **uv)
        except (OSError, ValueError) as exc:
            raise ctx.fail(where, str(exc), d) from None
    return ctx.bitmaps[key]


#: Mitsuba texture plug-ins pyclpt loads, by name.
TEXTURES: dict[str, TextureLoader] = {
    "bitmap": load_bitmap,
    "checkerboard": load_checkerboard,
    "scale": load_scale,
}


def load_texture(ctx: LoadContext, d: Mapping[str, Any], where: str, scale: RGB = (1.0, 1.0, 1.0)) -> Texture:
    """The texture ``d`` (or the one it references), its values multiplied by ``scale``."""
    d = ctx.deref(d, where)
    kind = d.get("type")
    loader = TEXTURES.get(kind)
    if loader is None:
        raise ctx.fail(where, f"unsupported texture type {kind!r} ({', '.join(TEXTURES)})", d)
    try:
        return loader(ctx, d, where, scale)
    except SceneDictError:
        raise
    except ValueError as exc:
        raise ctx.fail(where, str(exc), d) from None


def color(ctx: LoadContext, value: Any, where: str, parent: Mapping[str, Any] | None = None) -> RGB:
    """A constant colour: a number, 3 numbers, an rgb/spectrum dict, or a texture's mean colour."""
    value = ctx.deref(value, where)
    if is_dict(value) and value.get("type") in TEXTURES:
        tex = load_texture(ctx, value, where)
        mean = tex.rgba()[..., :3].mean(axis=(0, 1)) if isinstance(tex, Bitmap) else \
            0.5 * (np.asarray(tex.color0) + np.asarray(tex.color1))
        ctx.note(value, where, "a texture is not supported here, its mean color used")
        return rgb(mean, where)
    return ctx.constant_color(value, where, parent)


def color_or_texture(ctx: LoadContext, value: Any, where: str, parent: Mapping[str, Any] | None = None) -> Color:
    """A texture, or a constant colour; other texture plug-ins become grey 0.5, with a note."""
    value = ctx.deref(value, where)
    if is_dict(value) and value.get("type") in TEXTURES:
        return load_texture(ctx, value, where)
    if is_dict(value) and value.get("type") not in CONSTANT_COLOR_TYPES:
        ctx.note(value, where, f"texture type {value.get('type')!r} not supported, grey 0.5 used")
        return (0.5, 0.5, 0.5)
    return color(ctx, value, where, parent)
