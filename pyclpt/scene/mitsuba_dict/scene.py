"""The top level of a scene dictionary: each entry classified by plug-in kind and handed to its
module's loader; the :class:`~pyclpt.scene.model.Scene` assembled; the load's notes logged as one
warning (one line, entries separated by ``"; "``).
"""
from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

from pyclpt.scene.mitsuba_dict import bsdfs, emitters, sensors, shapes, textures
from pyclpt.scene.mitsuba_dict.context import META_KEYS, LoadContext, is_dict
from pyclpt.scene.model import Camera, Film, Scene

log = logging.getLogger(__name__)

#: Top-level plug-ins pyclpt does not use (participating media).
OTHER_TYPES = frozenset({"homogeneous", "heterogeneous", "isotropic", "hg", "medium"})
#: XML tags of elements pyclpt does not use (mitsuba_xml keys untyped objects by their tag).
OTHER_TAGS = frozenset({"medium", "phase", "volume", "subsurface", "film", "sampler", "rfilter"})


def classify(key: str, value: Mapping[str, Any]) -> str:
    """The kind of top-level entry ``key``: bsdf, texture, shape, emitter, integrator, sensor or other."""
    kind = value.get("type")
    if kind in bsdfs.BSDFS or kind in bsdfs.UNSUPPORTED:
        return "bsdf"
    if kind in textures.TEXTURES:
        return "texture"
    if kind in shapes.SHAPES or kind in shapes.UNSUPPORTED or kind in shapes.INSTANCING:
        return "shape"
    if kind in emitters.KNOWN:
        return "emitter"
    if key.startswith("integrator") or kind in sensors.INTEGRATORS:
        return "integrator"
    if key.startswith("sensor") or kind in sensors.SENSORS or kind in sensors.OTHER_SENSORS:
        return "sensor"
    return "other"


def register_ids(ctx: LoadContext, d: Mapping[str, Any]) -> None:
    """Objects nested anywhere may carry an id that others reference (Mitsuba allows it)."""
    for v in d.values():
        if is_dict(v) and v.get("type") != "ref":
            if "id" in v:
                ctx.named.setdefault(str(v["id"]), v)
            register_ids(ctx, v)


def load_scene(ctx: LoadContext, d: Mapping[str, Any], name: str) -> Scene:
    """The Scene of dictionary ``d``; what it does not use is logged in one warning."""
    if d.get("type") != "scene":
        raise ctx.fail("<root>", "the top-level dict must have type 'scene'", d)
    camera, film, spp, max_depth = Camera(), Film(), 64, -1
    entries = [(k, v) for k, v in d.items() if k not in META_KEYS]
    for key, value in entries:
        if not is_dict(value):
            raise ctx.fail(key, f"expected a dict, got {value!r}", d)
        ctx.named[str(value.get("id", key))] = value
        register_ids(ctx, value)
    have_sensor = have_integrator = False
    sensor_id = "sensor"
    for key, value in entries:
        role = classify(key, value)
        if role in ("bsdf", "texture"):
            continue  # used through references
        if role == "sensor":
            if have_sensor:
                ctx.note(value, key, "a second sensor is not supported, ignored")
                continue
            have_sensor = True
            camera, film, spp = sensors.load_sensor(ctx, value, key)
            sensor_id = str(value.get("id", key))
        elif role == "integrator":
            if have_integrator:
                ctx.note(value, key, "a second integrator ignored")
                continue
            have_integrator = True
            max_depth = sensors.load_integrator(ctx, key, value)
        elif role == "shape":
            shapes.load_shape(ctx, key, value)
        elif role == "emitter":
            emitters.load_emitter(ctx, key, value)
        elif value.get("type") in OTHER_TYPES or key.split("_")[0] in OTHER_TAGS:
            ctx.note(value, key, f"{value.get('type')!r} not supported, ignored")
        else:
            raise ctx.fail(key, f"unsupported element type {value.get('type')!r}", value)
    if not ctx.meshes and not ctx.instances:
        raise ctx.fail("<root>", "the scene has no shapes", d)
    used_groups = {i.group for i in ctx.instances}
    for gid in ctx.groups:
        if gid not in used_groups:
            ctx.note(ctx.named.get(gid), gid, "shapegroup never instanced, not drawn")
    for key, value in entries:
        ident = str(value.get("id", key))
        if classify(key, value) in ("bsdf", "texture") and ident not in ctx.referenced:
            ctx.note(value, key, f"{value.get('type')} defined but never referenced by a shape, unused")
    if ctx.notes:
        # one line; the command line shows the list ("ignored") as one short line per entry
        log.warning("%s: not used by pyclpt (%d): %s", ctx.origin, len(ctx.notes), "; ".join(ctx.notes),
                    extra={"ignored": tuple(ctx.notes), "origin": ctx.origin})
    ctx.ids["camera"] = sensor_id  # the prefix of the sensor's parameters (pyclpt.traverse), after the others
    return Scene(ctx.meshes, ctx.materials, camera, film, ctx.environment, spp, max_depth, name, lights=ctx.lights,
                 ids=ctx.ids, groups=ctx.groups, instances=ctx.instances)
