"""Build a :class:`~pyclpt.scene.model.Scene` from a Mitsuba-3-style dictionary.

The dictionary format is Mitsuba 3's ``load_dict`` (``{"type": "scene", ...}``
with the sensor, integrator, BSDFs, textures, shapes and emitters as nested
dicts under any keys, and ``{"type": "ref", "id": ...}`` references), with
transforms given as 4x4 matrices, Mitsuba ``ScalarTransform4f`` objects, or
lists of operations (see :func:`pyclpt.scene.transform.from_spec`). Built-in scenes
in ``scenes/*.json`` use it, and :mod:`pyclpt.scene.mitsuba_xml` translates Mitsuba
XML files (0.5 to 3.x) into it, adding ``"__where__": "file:line"`` to every
object so that messages name the line, and ``"__version__"`` to the few plug-ins of
pre-2.0 files that mean something else in Mitsuba 3 (``sunsky``).

The plug-ins are organised by kind, as in Mitsuba, each module with a registry
mapping a plug-in name to its small loader function:

* :mod:`~pyclpt.scene.mitsuba_dict.bsdfs` (``BSDFS``, and ``METALS``),
* :mod:`~pyclpt.scene.mitsuba_dict.textures` (``TEXTURES``, and the colour readers),
* :mod:`~pyclpt.scene.mitsuba_dict.shapes` (``SHAPES``),
* :mod:`~pyclpt.scene.mitsuba_dict.emitters` (``EMITTERS``),
* :mod:`~pyclpt.scene.mitsuba_dict.sensors` (``SENSORS``, films, samplers, integrators),

with :mod:`~pyclpt.scene.mitsuba_dict.context` (the state of one load: ids,
notes, value readers, errors) and :mod:`~pyclpt.scene.mitsuba_dict.scene` (the top
level: entries classified by kind, the Scene assembled).

Everything pyclpt does not support is reported in one warning per load (logger
``pyclpt.scene.mitsuba_dict.scene``, one line), each entry saying what, where,
and what was done instead; nothing is dropped silently. Malformed values raise
:class:`SceneDictError` naming the element.
"""
from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pyclpt.scene.mitsuba_dict.bsdfs import BSDFS, METALS
from pyclpt.scene.mitsuba_dict.context import IORS, VERSION, WHERE, LoadContext, SceneDictError
from pyclpt.scene.mitsuba_dict.emitters import EMITTERS
from pyclpt.scene.mitsuba_dict.scene import load_scene
from pyclpt.scene.mitsuba_dict.sensors import SENSORS
from pyclpt.scene.mitsuba_dict.shapes import SHAPES
from pyclpt.scene.mitsuba_dict.textures import TEXTURES
from pyclpt.scene.model import Scene

__all__ = ["BSDFS", "EMITTERS", "IORS", "METALS", "SENSORS", "SHAPES", "TEXTURES", "VERSION", "WHERE", "SceneDictError",
           "load_dict"]


def load_dict(d: Mapping[str, Any], *, base_dir: str | os.PathLike | None = None,
              name: str = "scene", origin: str | None = None) -> Scene:
    """A Scene from a Mitsuba-3-style dict; relative file names resolve against ``base_dir``.

    ``origin`` (default ``name``) names the source in messages. Raises :class:`SceneDictError`;
    logs one warning listing what the scene holds that pyclpt does not use."""
    ctx = LoadContext(Path(base_dir) if base_dir is not None else None, origin or name)
    scene = load_scene(ctx, d, name)
    scene.files = list(dict.fromkeys(ctx.files))
    return scene
