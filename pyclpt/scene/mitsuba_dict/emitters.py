"""Mitsuba emitter plug-ins: point, directional and spot lights, and the environment (``constant``,
``envmap``, ``sunsky``, ``sky``, ``sun``); ``area`` emitters attach to shapes (:func:`area_radiance`).

:data:`EMITTERS` maps a top-level emitter plug-in to its loader, which adds a light to the scene or
returns its environment (a scene has at most one; a second is reported and ignored). :data:`UNSUPPORTED`
names the Mitsuba emitters pyclpt ignores with a note.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from pyclpt.scene.mitsuba_dict.context import VERSION, LoadContext, SceneDictError
from pyclpt.scene.mitsuba_dict.textures import Texture, color, color_or_texture
from pyclpt.scene.model import RGB, Bitmap, Checkerboard, DirectionalLight, Envmap, PointLight, SpotLight

Environment = RGB | Envmap
#: A loader adds to the scene (point lights) and returns None, or returns the scene's environment.
EmitterLoader = Callable[[LoadContext, Mapping[str, Any], str], Environment | None]

#: Mitsuba emitters pyclpt does not have: reported, and ignored.
UNSUPPORTED = frozenset({"projector", "collimated", "directionalarea"})


def area_radiance(ctx: LoadContext, em: Mapping[str, Any], where: str) -> tuple[RGB, Texture | None]:
    """The radiance of an emitter nested in a shape (which must be ``area``): a constant, or (1, 1, 1)
    and a texture looked up at the shape's uv."""
    if em.get("type") != "area":
        raise ctx.fail(where, f"only 'area' emitters attach to shapes, got {em.get('type')!r}", em)
    ctx.note_unused(where, em, {"radiance"})
    value = color_or_texture(ctx, em.get("radiance", 1.0), f"{where}.radiance", em)
    if isinstance(value, (Bitmap, Checkerboard)):
        return (1.0, 1.0, 1.0), value
    return value, None


def load_point(ctx: LoadContext, d: Mapping[str, Any], where: str) -> None:
    """``point``: at ``position`` (or the origin of ``to_world``), with ``intensity``."""
    ctx.note_unused(where, d, {"position", "intensity", "to_world"})
    pos = np.zeros(3)
    if "to_world" in d:
        pos = ctx.transform(d, "to_world", where)[:3, 3]
    if "position" in d:
        pos = ctx.vector(d, "position", where)
    ctx.lights.append(PointLight(tuple(pos), color(ctx, d.get("intensity", 1.0), f"{where}.intensity", d)))
    ctx.ids[f"light:{len(ctx.lights) - 1}"] = str(d.get("id", where))
    return None


def _add_light(ctx: LoadContext, d: Mapping[str, Any], where: str, light) -> None:
    ctx.lights.append(light)
    ctx.ids[f"light:{len(ctx.lights) - 1}"] = str(d.get("id", where))


def load_directional(ctx: LoadContext, d: Mapping[str, Any], where: str) -> None:
    """``directional``: ``irradiance`` travelling along ``direction`` (else the +z axis of ``to_world``)."""
    ctx.note_unused(where, d, {"irradiance", "direction", "to_world"})
    direction = np.array([0.0, 0.0, 1.0])
    if "to_world" in d:
        direction = ctx.transform(d, "to_world", where)[:3, :3] @ direction
    if "direction" in d:
        direction = ctx.vector(d, "direction", where)
    _add_light(ctx, d, where, DirectionalLight(tuple(direction), color(ctx, d.get("irradiance", 1.0),
                                                                       f"{where}.irradiance", d)))


def load_spot(ctx: LoadContext, d: Mapping[str, Any], where: str) -> None:
    """``spot``: at the origin of ``to_world``, shining along its +z axis, with ``intensity``,
    ``cutoff_angle`` and ``beam_width`` (degrees)."""
    ctx.note_unused(where, d, {"intensity", "cutoff_angle", "beam_width", "to_world", "texture"})
    texture = None
    if "texture" in d:
        texture = color_or_texture(ctx, d["texture"], f"{where}.texture", d)
        if not isinstance(texture, (Bitmap, Checkerboard)):
            raise ctx.fail(f"{where}.texture", "a spot light's texture must be spatially varying (a bitmap or "
                                               "a checkerboard), as Mitsuba requires", d)
    m = ctx.transform(d, "to_world", where) if "to_world" in d else np.eye(4)
    cutoff = ctx.number(d, "cutoff_angle", 20.0, where)
    beam = ctx.number(d, "beam_width", 0.75 * cutoff, where)
    try:
        light = SpotLight(tuple(m[:3, 3]), tuple(m[:3, :3] @ np.array([0.0, 0.0, 1.0])),
                          color(ctx, d.get("intensity", 1.0), f"{where}.intensity", d), cutoff, beam,
                          texture=texture, to_world=m[:3, :3] if texture is not None else None)
    except ValueError as exc:
        raise ctx.fail(where, str(exc), d) from None
    _add_light(ctx, d, where, light)


def load_constant(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Environment:
    ctx.note_unused(where, d, {"radiance"})
    return color(ctx, d.get("radiance", 1.0), f"{where}.radiance", d)


def load_envmap(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Environment:
    """``envmap``: an equirectangular image (8-bit files decoded from sRGB), ``to_world`` and ``scale``."""
    from pyclpt.scene.textures import read_texture_image

    ctx.note_unused(where, d, {"filename", "data", "to_world", "scale"})
    if ("filename" in d) == ("data" in d):
        raise ctx.fail(where, "an envmap needs a filename or data (an (H, W, 3) array of linear radiance), "
                              "one of them", d)
    if "data" in d:
        try:
            return Envmap(np.array(d["data"], np.float32), ctx.transform(d, "to_world", where),
                          ctx.number(d, "scale", 1.0, where), f"{where}.data")
        except (ValueError, TypeError) as exc:
            raise ctx.fail(where, str(exc), d) from None
    path = ctx.path(d["filename"], f"{where}.filename", d)
    try:
        pixels, ldr = read_texture_image(path)
        if ldr:
            from pyclpt.common.image_io import srgb_to_linear

            pixels = srgb_to_linear(pixels)
            ctx.note(d, where, "an 8-bit environment map, decoded from sRGB")
        if pixels.shape[2] < 3:
            pixels = np.repeat(pixels[:, :, :1], 3, axis=2)
        return Envmap(pixels[:, :, :3], ctx.transform(d, "to_world", where), ctx.number(d, "scale", 1.0, where),
                      path.name)
    except (OSError, ValueError) as exc:
        if isinstance(exc, SceneDictError):
            raise
        raise ctx.fail(where, str(exc), d) from None


#: The sun's place and time (Mitsuba's sun position), each plug-in's default in :class:`SunTime`.
SUN_TIME_KEYS = ("latitude", "longitude", "timezone", "year", "month", "day", "hour", "minute", "second")


def _file_version(d: Mapping[str, Any]) -> tuple[int, ...]:
    """The version of the file the plug-in came from (its ``__version__``); 3.0.0 when it has none."""
    v = d.get(VERSION)
    try:
        return tuple(int(x) for x in str(v).split(".")) if v is not None else (3, 0, 0)
    except ValueError:
        return (3, 0, 0)


def load_sunsky(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Environment:
    """``sunsky`` (and Mitsuba 0.5's ``sky`` and ``sun``), baked into an environment map (see
    :mod:`pyclpt.scene.sky`). A ``sunsky`` of a pre-2.0 file (``__version__``), ``sky`` and ``sun`` are
    Mitsuba 0.5's (+y up, its sun model, ``sun_radius_scale`` (0: a directional light beside the map),
    ``resolution``, ``extend``, ``stretch``); any other ``sunsky`` is Mitsuba 3's (+z up, its sun,
    ``sun_aperture``, ``complex_sun``)."""
    from pyclpt.scene.sky import SunTime, directional_sun_05, sunsky_envmap

    kind = d.get("type")
    legacy = kind != "sunsky" or _file_version(d) < (2, 0, 0)
    used = {"turbidity", "albedo", "sun_direction", "sky_scale", "sun_scale", "to_world", *SUN_TIME_KEYS}
    used |= {"scale", "sun_radius_scale", "resolution", "extend", "stretch"} if legacy else {"sun_aperture",
                                                                                            "complex_sun"}
    ctx.note_unused(where, d, used)
    timed = [k for k in SUN_TIME_KEYS if k in d]
    if "sun_direction" in d and timed:
        raise ctx.fail(where, f"give sun_direction or the sun's place and time ({', '.join(timed)}), not both", d)
    time = None
    if "sun_direction" not in d:
        values = {k: ctx.number(d, k, getattr(SunTime, k), where) for k in timed}
        for k in ("year", "month", "day"):
            if k in values:
                if values[k] != int(values[k]):
                    raise ctx.fail(f"{where}.{k}", f"expected an integer, got {values[k]!r}", d)
                values[k] = int(values[k])
        time = SunTime(**values)
    scale = ctx.number(d, "scale", 1.0, where) if legacy else 1.0
    if kind == "sky":
        sky_scale, sun_scale = scale, 0.0
    elif kind == "sun":
        sky_scale, sun_scale = 0.0, scale
    else:
        sky_scale, sun_scale = ctx.number(d, "sky_scale", scale, where), ctx.number(d, "sun_scale", scale, where)
    albedo = color(ctx, d["albedo"], f"{where}.albedo", d) if "albedo" in d else None
    options: dict[str, Any] = {}
    if legacy:
        options = {"sun_radius_scale": ctx.number(d, "sun_radius_scale", 1.0, where),
                   "extend": ctx.flag(d, "extend", False, where), "stretch": ctx.number(d, "stretch", 1.0, where)}
        if "resolution" in d:
            options["resolution"] = ctx.number(d, "resolution", 512, where)
    else:
        options = {"sun_aperture": ctx.number(d, "sun_aperture", 0.5358, where),
                   "complex_sun": ctx.flag(d, "complex_sun", False, where)}
    sun_direction = ctx.vector(d, "sun_direction", where) if "sun_direction" in d else None
    turbidity = ctx.number(d, "turbidity", 3.0, where)
    to_world = ctx.transform(d, "to_world", where) if "to_world" in d else None
    try:
        if legacy and options["sun_radius_scale"] == 0.0 and sun_scale > 0.0:  # Mitsuba 0.5's directional sun
            direction, irradiance = directional_sun_05(sun_direction, time=time, turbidity=turbidity,
                                                       sun_scale=sun_scale, to_world=to_world,
                                                       stretch=options["stretch"])
            _add_light(ctx, d, where, DirectionalLight(tuple(direction), tuple(irradiance)))
            if sky_scale == 0.0:  # nothing left for the environment
                return None
        return sunsky_envmap(sun_direction, convention="mitsuba0.5" if legacy else "mitsuba3", time=time,
                             turbidity=turbidity, albedo=albedo, sky_scale=sky_scale, sun_scale=sun_scale,
                             to_world=to_world, name=str(kind), **options)
    except ValueError as exc:
        if isinstance(exc, SceneDictError):
            raise
        raise ctx.fail(where, str(exc), d) from None


#: Mitsuba emitter plug-ins pyclpt loads at the top level of a scene, by name.
EMITTERS: dict[str, EmitterLoader] = {
    "point": load_point,
    "directional": load_directional,
    "spot": load_spot,
    "constant": load_constant,
    "envmap": load_envmap,
    "sunsky": load_sunsky,
    "sky": load_sunsky,
    "sun": load_sunsky,
}
#: The emitters that are the scene's environment (one per scene).
ENVIRONMENTS = frozenset({"constant", "envmap", "sunsky", "sky", "sun"})
#: Every emitter name pyclpt knows: loaded, attached to shapes, or reported.
KNOWN = frozenset(EMITTERS) | {"area"} | UNSUPPORTED


def load_emitter(ctx: LoadContext, name: str, d: Mapping[str, Any]) -> None:
    """Add the top-level emitter ``d`` (keyed ``name``) to the scene: a point light, or its environment."""
    kind = d.get("type")
    where = name
    if kind == "area":
        ctx.note(d, where, "an area emitter outside a shape emits nothing, ignored")
        return
    if kind in UNSUPPORTED:
        ctx.note(d, where, f"emitter type {kind!r} not supported, ignored")
        return
    loader = EMITTERS.get(kind)
    if loader is None:
        raise ctx.fail(where, f"unsupported emitter type {kind!r} "
                              f"(supported: {', '.join(sorted(EMITTERS.keys() | {'area'}))})", d)
    if kind in ENVIRONMENTS and ctx.environment is not None:
        ctx.note(d, where, "a second environment emitter is not supported, ignored")
        return
    try:
        environment = loader(ctx, d, where)
    except SceneDictError:
        raise
    except ValueError as exc:  # the model's own checks
        raise ctx.fail(where, str(exc), d) from None
    if environment is not None:
        ctx.environment = environment
        ctx.ids["environment"] = str(d.get("id", name))
