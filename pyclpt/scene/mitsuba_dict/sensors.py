"""Mitsuba sensor plug-ins with their film and sampler, and the integrator: camera, image size, sample
count and path depth.

:data:`SENSORS` maps the sensor plug-ins pyclpt loads to their loaders (``perspective``, ``thinlens``,
``orthographic``); :data:`OTHER_SENSORS` are recognised as sensors but rejected.
Films (with their reconstruction filter, :func:`load_rfilter`) and samplers are read by :func:`load_film`
and :func:`load_sampler`. Every Mitsuba integrator
(:data:`INTEGRATORS`) becomes pyclpt's path tracer with the integrator's ``max_depth``
(:func:`load_integrator`), with a note when it is not ``path``.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from pyclpt.scene.mitsuba_dict.context import META_KEYS, LoadContext, is_dict
from pyclpt.scene.model import Camera, Film, ReconstructionFilter

SensorLoader = Callable[[LoadContext, Mapping[str, Any], str], Camera]

FILMS = frozenset({"hdrfilm", "ldrfilm", "specfilm"})
SAMPLERS = frozenset({"independent", "stratified", "multijitter", "ldsampler", "halton", "sobol", "hammersley",
                      "orthogonal"})
#: Mitsuba sensors pyclpt recognises but cannot render.
OTHER_SENSORS = frozenset({"radiancemeter", "irradiancemeter", "spherical", "telecentric", "batch"})
#: Mitsuba integrators: all become pyclpt's path tracer (the path tracers without a note).
PATH_TRACERS = frozenset({"path", "volpath", "volpathmis"})
INTEGRATORS = PATH_TRACERS | {"direct", "aov", "sppm", "bdpt", "pssmlt", "mlt", "erpt", "ptracer", "photonmapper",
                              "ppm", "vpl", "ao", "prb", "prb_basic", "direct_projective", "prb_projective",
                              "stokes", "moment", "depth", "field", "adaptive", "irrcache", "multichannel",
                              "volpath_simple"}
#: Integrators that wrap another one: the nested integrator's depth is used.
WRAPPER_INTEGRATORS = frozenset({"adaptive", "irrcache", "multichannel"})


def _nested_of(d: Mapping[str, Any], key: str, types: frozenset[str]) -> Mapping[str, Any] | None:
    """``d[key]`` when it is an object, else the first nested object of one of ``types``."""
    if is_dict(d.get(key)):
        return d[key]
    return next((v for v in d.values() if is_dict(v) and v.get("type") in types), None)


def load_perspective(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Camera:
    """``perspective`` and ``thinlens`` (with ``aperture_radius`` and ``focus_distance``, both required as in
    Mitsuba): ``fov`` (or ``focal_length``), ``fov_axis``, ``to_world``."""
    fov = ctx.number(d, "fov", 45.0, where)
    if "focal_length" in d and "fov" not in d:
        text = str(d["focal_length"]).lower().replace("mm", "")
        try:
            fov = float(np.degrees(2 * np.arctan(36.0 / (2 * float(text)))))
        except ValueError:
            raise ctx.fail(f"{where}.focal_length", f"expected e.g. '50mm', got {d['focal_length']!r}",
                           d) from None
    lens: dict = {}
    if d.get("type", "perspective") == "thinlens":
        for key in ("aperture_radius", "focus_distance"):
            if key not in d:
                raise ctx.fail(where, f"a thinlens sensor needs {key}", d)
        lens = {"kind": "thinlens", "aperture_radius": ctx.number(d, "aperture_radius", 0.0, where),
                "focus_distance": ctx.number(d, "focus_distance", 0.0, where)}
    try:
        return Camera(ctx.transform(d, "to_world", where), fov, str(d.get("fov_axis", "x")).lower(), **lens)
    except ValueError as exc:
        raise ctx.fail(where, str(exc), d) from None


def load_orthographic(ctx: LoadContext, d: Mapping[str, Any], where: str) -> Camera:
    """``orthographic``: parallel rays; ``to_world``'s scale sets the extent (Mitsuba's camera-space square
    x in [-1, 1], y in [-1/aspect, 1/aspect])."""
    try:
        return Camera(ctx.transform(d, "to_world", where), kind="orthographic")
    except ValueError as exc:
        raise ctx.fail(where, str(exc), d) from None


#: Mitsuba sensor plug-ins pyclpt loads, by name.
SENSORS: dict[str, SensorLoader] = {
    "perspective": load_perspective,
    "thinlens": load_perspective,
    "orthographic": load_orthographic,
}
#: The parameters the sensor loaders read.
_SENSOR_KEYS = frozenset({"fov", "fov_axis", "to_world", "near_clip", "far_clip", "focus_distance", "focal_length",
                          "aperture_radius"})


#: Mitsuba reconstruction filters pyclpt approximates by its gaussian (with a note).
OTHER_RFILTERS = frozenset({"mitchell", "catmullrom", "lanczos"})


def load_rfilter(ctx: LoadContext, r: Mapping[str, Any] | None, where: str) -> ReconstructionFilter:
    """The film's ``rfilter``: ``box``, ``tent`` (``radius``, default 1) or ``gaussian`` (``stddev``, default
    0.5); none given: Mitsuba's default, the gaussian. Mitsuba's negative-lobed filters (``mitchell``,
    ``catmullrom``, ``lanczos``) become the default gaussian with a note; any other type is an error."""
    if r is None:
        return ReconstructionFilter("gaussian")
    kind = r.get("type", "gaussian")
    params = {"tent": {"radius"}, "gaussian": {"stddev"}}.get(kind, set())
    if kind in OTHER_RFILTERS:
        ctx.note(r, where, f"reconstruction filter {kind!r}: the gaussian (stddev 0.5) used")
        return ReconstructionFilter("gaussian")
    if kind not in ("box", "tent", "gaussian"):
        raise ctx.fail(where, f"unknown reconstruction filter {kind!r} (box, tent, gaussian; mitchell, "
                              f"catmullrom and lanczos load as the gaussian)", r)
    ctx.note_unused(where, r, params)
    try:
        return ReconstructionFilter(kind, radius=ctx.number(r, "radius", 1.0, where) if kind == "tent" else 1.0,
                                    stddev=ctx.number(r, "stddev", 0.5, where) if kind == "gaussian" else 0.5)
    except ValueError as exc:
        raise ctx.fail(where, str(exc), r) from None


def load_film(ctx: LoadContext, f: Mapping[str, Any], where: str) -> Film:
    """The film's ``width`` and ``height`` (Mitsuba's defaults 768 x 576) and its reconstruction filter."""
    rfilter = f["rfilter"] if is_dict(f.get("rfilter")) else next((v for v in f.values() if is_dict(v)), None)
    key = next((k for k, v in f.items() if v is rfilter), "rfilter")
    ctx.note_unused(where, {k: v for k, v in f.items() if v is not rfilter},
                    {"width", "height", "pixel_format", "component_format", "file_format", "banner",
                     "high_quality_edges", "rfilter", "sample_border"})
    filt = load_rfilter(ctx, rfilter, f"{where}.{key}")
    try:
        return Film(int(ctx.number(f, "width", 768, where)), int(ctx.number(f, "height", 576, where)), filt)
    except (TypeError, ValueError) as exc:
        raise ctx.fail(where, str(exc), f) from None


def load_sampler(ctx: LoadContext, s: Mapping[str, Any], where: str) -> int:
    """The sampler's ``sample_count`` (default 64); pyclpt's own sampler is used whatever the type."""
    if s and s.get("type", "independent") != "independent":
        ctx.note(s, where, f"sampler {s.get('type')!r}: pyclpt's independent counter-based sampler used")
    ctx.note_unused(where, s, {"sample_count", "seed"})
    spp = int(ctx.number(s, "sample_count", 64, where))
    if spp < 1:
        raise ctx.fail(f"{where}.sample_count", f"must be >= 1, got {spp}", s)
    return spp


def load_sensor(ctx: LoadContext, d: Mapping[str, Any], where: str) -> tuple[Camera, Film, int]:
    """The camera, film and samples per pixel of sensor ``d``."""
    kind = d.get("type", "perspective")
    loader = SENSORS.get(kind)
    if loader is None:
        raise ctx.fail(where, f"unsupported sensor type {kind!r} ({', '.join(SENSORS)})", d)
    film_d = _nested_of(d, "film", FILMS)
    sampler_d = _nested_of(d, "sampler", SAMPLERS)
    nested_keys = {k for k, v in d.items() if v is film_d or v is sampler_d}
    camera = loader(ctx, d, where)
    ctx.note_unused(where, d, _SENSOR_KEYS | nested_keys)
    film = load_film(ctx, film_d or {}, f"{where}.film")
    spp = load_sampler(ctx, sampler_d or {}, f"{where}.sampler")
    return camera, film, spp


def load_integrator(ctx: LoadContext, key: str, value: Mapping[str, Any]) -> int:
    """The integrator's ``max_depth`` (-1: unlimited)."""
    kind = value.get("type")
    inner = [v for k, v in value.items() if k not in META_KEYS and is_dict(v)]
    if kind not in PATH_TRACERS:
        ctx.note(value, key, f"integrator {kind!r}: pyclpt's path tracer used")
    elif kind != "path":
        ctx.note(value, key, f"integrator {kind!r}: pyclpt's path tracer (no media) used")
    if kind in WRAPPER_INTEGRATORS and inner:
        value = inner[0]  # a wrapper: take the depth of the nested integrator
    max_depth = int(ctx.number(value, "max_depth", -1, key))
    if max_depth < -1:
        raise ctx.fail(f"{key}.max_depth", f"must be -1 (unlimited) or >= 0, got {max_depth}", value)
    if kind in PATH_TRACERS:
        ctx.note_unused(key, value, {"max_depth"})
    return max_depth
