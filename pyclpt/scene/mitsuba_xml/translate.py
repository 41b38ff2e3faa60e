"""A read scene file (:class:`~pyclpt.scene.mitsuba_xml.document.Document`) as a Mitsuba 3 ``load_dict``
dictionary.

Objects (plug-ins) become nested dicts ``{"type": ..., "__where__": "file:line", ...}`` (``id`` kept when
given); in the scene they are keyed by id, else name, else a generated ``<tag>_<n>`` (the first sensor and
integrator as plain ``sensor`` / ``integrator``); nested objects by their ``name``, else by their tag
(``bsdf``, ``bsdf_1``, ...); ``<ref id=>`` becomes ``{"type": "ref", "id": ...}`` keyed like the object it
names. Properties become values (:mod:`~pyclpt.scene.mitsuba_xml.values`).
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pyclpt.scene.mitsuba_dict import VERSION, WHERE
from pyclpt.scene.mitsuba_xml import values
from pyclpt.scene.mitsuba_xml.document import Document
from pyclpt.scene.mitsuba_xml.node import Node, expect_attrs, node_error
from pyclpt.scene.mitsuba_xml.spectra import blackbody_to_rgb
from pyclpt.scene.mitsuba_xml.upgrade import legacy_version

#: Tags that are always objects (plug-ins); any other tag with a ``type`` attribute is one too.
OBJECT_TAGS = frozenset({"scene", "bsdf", "shape", "emitter", "texture", "sensor", "film", "sampler",
                         "rfilter", "integrator", "medium", "phase", "volume", "subsurface"})
#: Objects keyed by their plain tag when they are the first of their kind in the scene.
_SINGLETONS = frozenset({"sensor", "integrator"})


def to_dict(doc: Document, root_dir: Path) -> dict[str, Any]:
    """The scene of ``doc`` as a dictionary; file names resolve against ``root_dir`` too."""
    return _Translator(doc, root_dir).scene(doc.root)


class _Translator:
    def __init__(self, doc: Document, root_dir: Path) -> None:
        self.ids = doc.ids
        self.aliases = doc.aliases
        self.root_dir = root_dir

    def scene(self, root: Node) -> dict[str, Any]:
        d: dict[str, Any] = {"type": "scene", WHERE: root.where}
        if "id" in root.attrs:
            d["id"] = root.attrs["id"]
        self.fill(d, root, top_level=True)
        return d

    @staticmethod
    def is_object(node: Node) -> bool:
        if node.tag in OBJECT_TAGS:
            return True
        if node.tag == "spectrum":
            return "type" in node.attrs
        return "type" in node.attrs and node.tag not in values.VALUE_TAGS | values.TRANSFORM_OPS | {"transform", "ref"}

    def fill(self, d: dict[str, Any], node: Node, top_level: bool) -> None:
        """Translate ``node``'s children into ``d``."""
        counters: dict[str, int] = {}
        reserved = {c.attrs[a] for c in node.children for a in ("id", "name")
                    if a in c.attrs and (a == "name" or top_level)}
        for child in node.children:
            if child.tag in values.TRANSFORM_OPS:
                raise node_error(child, "a transform operation must be inside a <transform>")
            if child.tag == "ref" or self.is_object(child):
                value, tag = self.ref(child) if child.tag == "ref" else (self.object(child), child.tag)
                key = child.attrs.get("id") if top_level and child.tag != "ref" else None
                key = key or child.attrs.get("name")
                if key is None:
                    key = self.auto_key(d, tag, counters, reserved, top_level)
            elif child.tag in values.VALUE_TAGS or child.tag == "transform":
                if "name" not in child.attrs:
                    raise node_error(child, "missing attribute 'name'")
                key, value = child.attrs["name"], values.value(child, self.root_dir)
            else:
                raise node_error(child, f"unknown element <{child.tag}> (objects need a type attribute; values "
                                        f"are {', '.join(sorted(values.VALUE_TAGS | {'transform'}))})")
            if key in d or key == WHERE:
                raise node_error(child, f"{key!r} is given twice in {node.describe()}")
            d[key] = value

    @staticmethod
    def auto_key(d: Mapping[str, Any], tag: str, counters: dict[str, int], reserved: set[str],
                 top_level: bool) -> str:
        """``sensor``/``integrator`` (the first in a scene) or ``<tag>_<n>`` at the top level;
        ``<tag>``, ``<tag>_1``, ... inside an object."""
        if (not top_level or tag in _SINGLETONS) and tag not in d and tag not in reserved:
            return tag
        n = counters.get(tag, 0 if top_level and tag not in _SINGLETONS else 1)
        while f"{tag}_{n}" in d or f"{tag}_{n}" in reserved:
            n += 1
        counters[tag] = n + 1
        return f"{tag}_{n}"

    def ref(self, node: Node) -> tuple[dict[str, Any], str]:
        expect_attrs(node, {"id", "name"}, required={"id"})
        ident = self.aliases.get(node.attrs["id"], node.attrs["id"])
        target = self.ids.get(ident)
        if target is None:
            known = ", ".join(sorted(self.ids)[:20]) or "none"
            raise node_error(node, f"no object with id {ident!r} (ids: {known})")
        return {"type": "ref", "id": ident, WHERE: node.where}, target.tag

    def object(self, node: Node) -> dict[str, Any]:
        expect_attrs(node, {"type", "id", "name"}, required={"type"})
        if node.tag == "spectrum" and node.attrs["type"] == "blackbody":
            return self.blackbody_object(node)
        d: dict[str, Any] = {"type": node.attrs["type"], WHERE: node.where}
        if "id" in node.attrs:
            d["id"] = node.attrs["id"]
        version = legacy_version(node)
        if version is not None:
            d[VERSION] = version
        self.fill(d, node, top_level=False)
        return d

    def blackbody_object(self, node: Node) -> dict[str, Any]:
        """Mitsuba 3's ``<spectrum type="blackbody">`` with float ``temperature`` (and ``scale``)."""
        props: dict[str, Any] = {}
        self.fill(props, node, top_level=False)
        extra = set(props) - {"temperature", "scale"}
        if "temperature" not in props or extra:
            raise node_error(node, "a blackbody spectrum takes float 'temperature' and 'scale' only"
                             + (f" (got {', '.join(sorted(extra))})" if extra else ""))
        if not props["temperature"] > 0:
            raise node_error(node, f"the temperature must be positive, got {props['temperature']}")
        return values.rgb_object(node, blackbody_to_rgb(props["temperature"], props.get("scale", 1.0)))
