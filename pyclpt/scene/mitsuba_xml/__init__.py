"""Mitsuba XML scene files (versions 0.5, 0.6, 2.x and 3.x) as Mitsuba 3 ``load_dict`` dictionaries.

:func:`xml_to_dict` translates a scene file into exactly the dictionary format that
:func:`pyclpt.scene.mitsuba_dict.load_dict` (and Mitsuba 3's ``load_dict``) reads; :func:`load_xml` loads
the result as a :class:`~pyclpt.scene.model.Scene`. The translation follows Mitsuba 3's XML parser:

* files older than 2.0.0 are upgraded as Mitsuba 3 does: parameter names go from camelCase to
  snake_case (``toWorld`` -> ``to_world``, ``intIOR`` -> ``int_ior``), ``<lookAt>`` becomes
  ``<lookat>``, a diffuse BSDF's ``diffuse_reflectance`` becomes ``reflectance``;
* ``<default name= value=>`` and caller parameters (which win) replace ``$name`` in every
  attribute; an undefined ``$name`` is an error, a parameter the scene never uses a warning;
* ``<include filename=>`` splices the included scene's children in place (relative to the
  including file; cycles are errors); ``<alias id= as=>`` makes a second id for an object;
* objects become nested dicts ``{"type": ..., "__where__": "file:line", ...}`` (``id`` kept when
  given); in the scene they are keyed by id, else name, else a generated ``<tag>_<n>`` (the first
  sensor and integrator as plain ``sensor`` / ``integrator``); nested objects by their ``name``,
  else by their tag (``bsdf``, ``bsdf_1``, ...); ``<ref id=>`` becomes ``{"type": "ref", "id": ...}``
  keyed like the object it names;
* properties become plain values: floats, ints, bools, strings, ``[x, y, z]`` for vectors and
  points, 4x4 float64 numpy arrays for transforms (operations applied in document order, each
  left-multiplying the result), ``{"type": "rgb", "value": [r, g, b]}`` for ``rgb``, ``srgb``
  (decoded to linear), ``spectrum`` and ``blackbody`` (see :func:`spectrum_to_rgb` and
  :func:`blackbody_to_rgb`);
* ``filename`` strings resolve against the file's folder (then the main scene's folder) and become
  absolute paths; a missing file is an error.

Nothing is dropped: plug-in types, parameters and elements pyclpt does not use are translated all
the same, and :func:`~pyclpt.scene.mitsuba_dict.load_dict` reports them. Errors are :class:`SceneXMLError`,
whose message starts with ``file:line:`` and names the element and the offending value; parameters the
scene never uses are logged as one warning (logger ``pyclpt.scene.mitsuba_xml``).

Modules: ``document`` (parsing, substitution, includes, aliases, ids), ``upgrade`` (the pre-2.0 renames,
as tables), ``values`` (numbers, colours, transforms), ``spectra`` (spectra and black bodies to RGB),
``translate`` (the tree to the dictionary), ``node`` (an element and the errors naming it).
"""
from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pyclpt.common.image_io import srgb_to_linear
from pyclpt.scene.mitsuba_dict import WHERE, load_dict
from pyclpt.scene.mitsuba_xml.document import read_document
from pyclpt.scene.mitsuba_xml.node import SceneXMLError
from pyclpt.scene.mitsuba_xml.spectra import blackbody_to_rgb, spectrum_to_rgb
from pyclpt.scene.mitsuba_xml.translate import to_dict
from pyclpt.scene.mitsuba_xml.upgrade import to_snake_case
from pyclpt.scene.model import Scene

__all__ = ["SceneXMLError", "WHERE", "blackbody_to_rgb", "load_xml", "spectrum_to_rgb", "srgb_to_linear",
           "to_snake_case", "xml_to_dict"]

log = logging.getLogger(__name__)


def xml_to_dict(path: str | os.PathLike, params: Mapping[str, str] | None = None) -> dict[str, Any]:
    """A Mitsuba XML scene file as a Mitsuba 3 ``load_dict`` dictionary (see the module docstring).

    ``params`` override the file's ``<default>`` values (as Mitsuba's ``-D name=value``).
    Raises :class:`SceneXMLError` for malformed or invalid files, FileNotFoundError if ``path``
    does not exist; logs a warning naming the parameters the scene does not use.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: scene file not found")
    doc = read_document(path, params or {})
    d = to_dict(doc, path.parent)
    if doc.unused_params:
        log.warning("%s: parameter%s %s not used by the scene", path, "s" if len(doc.unused_params) > 1 else "",
                    ", ".join(doc.unused_params))
    return d


def load_xml(path: str | os.PathLike, **params: object) -> Scene:
    """A :class:`~pyclpt.scene.model.Scene` from a Mitsuba XML file; ``params`` (converted with ``str``)
    override its ``<default>`` values. The scene is named after its folder for ``scene.xml``,
    else after the file."""
    from pyclpt.scene.mitsuba_xml.document import READ_FILES

    path = Path(path)
    read: list[Path] = [Path(os.path.abspath(path))]
    token = READ_FILES.set(read)
    try:
        d = xml_to_dict(path, {k: str(v) for k, v in params.items()})
    finally:
        READ_FILES.reset(token)
    name = path.resolve().parent.name if path.name.lower() == "scene.xml" else path.stem
    scene = load_dict(d, base_dir=path.parent, name=name or path.stem, origin=str(path))
    scene.source = path
    scene.files = list(dict.fromkeys([*read, *scene.files]))
    return scene
