"""Reading a Mitsuba XML scene file into a tree of :class:`~pyclpt.scene.mitsuba_xml.node.Node`.

:func:`read_document` parses the file with lxml (no entities, no network), replaces ``$name`` in every
attribute by the caller's parameters or the ``<default>`` values, upgrades old files
(:mod:`~pyclpt.scene.mitsuba_xml.upgrade`), splices ``<include>`` files in place (cycles are errors),
records ``<alias>`` ids and the ids of objects, and returns the :class:`Document`. :func:`resolve_file`
finds a file named in the scene as Mitsuba's file resolver does.
"""
from __future__ import annotations

import contextvars
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

from pyclpt.scene.mitsuba_xml.node import Node, SceneXMLError, Version, expect_attrs, node_error
from pyclpt.scene.mitsuba_xml.upgrade import upgrade_element, upgrade_parameters

_MAX_INCLUDE_DEPTH = 15
_PARAM = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")
_VERSION = re.compile(r"^\s*(\d+)[ .](\d+)[ .](\d+)\s*$")


@dataclass
class Document:
    """A scene file read: its root ``<scene>``, the ids of its objects, its aliases, and the caller's
    parameters that no attribute used."""

    root: Node
    ids: dict[str, Node]
    aliases: dict[str, str]
    unused_params: list[str]


def parse_version(text: str, where: str, tag: str) -> Version:
    m = _VERSION.match(text)
    if not m:
        raise SceneXMLError(f"{where}: <{tag} version=\"{text}\">: a version must be three numbers, "
                            "e.g. \"3.0.0\"")
    return int(m.group(1)), int(m.group(2)), int(m.group(3))


# the files read while a scene loads (load_xml collects them into Scene.files); None: not collected
READ_FILES: contextvars.ContextVar[list[Path] | None] = contextvars.ContextVar("pyclpt_read_files", default=None)


def _note_read(path: str | os.PathLike) -> None:
    files = READ_FILES.get()
    if files is not None:
        files.append(Path(os.path.abspath(path)))


def parse_file(path: Path) -> etree._Element:
    _note_read(path)
    parser = etree.XMLParser(resolve_entities=False, no_network=True, remove_comments=True,
                             remove_pis=True, huge_tree=True)
    try:
        return etree.fromstring(path.read_bytes(), parser)
    except etree.XMLSyntaxError as exc:
        line = exc.lineno or (exc.position[0] if exc.position else 0)
        raise SceneXMLError(f"{path}:{line}: malformed XML: {exc.msg}") from None


def resolve_file(name: str, node: Node, root_dir: Path, what: str = "file") -> str:
    """An absolute path for a file name: as given if absolute, else relative to the folder of
    the file holding ``node``, then to the main scene's folder ``root_dir`` (Mitsuba's file resolver)."""
    candidates = []
    for variant in dict.fromkeys([name, name.replace("\\", "/")]):
        p = Path(variant)
        candidates += [p] if p.is_absolute() else [node.file.parent / p, root_dir / p]
    for p in dict.fromkeys(candidates):
        if p.is_file():
            _note_read(p)
            return os.path.abspath(p)
    raise node_error(node, f"{what} not found: {os.path.abspath(candidates[0])}")


def read_document(path: Path, params: Mapping[str, str]) -> Document:
    """Scene file ``path`` read, ``params`` (which win over ``<default>`` values) substituted."""
    reader = _Reader(path, params)
    root = reader.read()
    unused = [k for k in reader.params if k not in reader.used]
    return Document(root, reader.ids, reader.aliases, unused)


class _Reader:
    def __init__(self, path: Path, params: Mapping[str, str]) -> None:
        self.path = path
        self.root_dir = path.parent
        self.params = {str(k): str(v) for k, v in params.items()}
        self.values: dict[str, str] = dict(self.params)  # parameters win over <default>s
        self.used: set[str] = set()
        self.ids: dict[str, Node] = {}
        self.aliases: dict[str, str] = {}
        self.include_stack: list[Path] = []

    def read(self) -> Node:
        root = parse_file(self.path)
        where = f"{self.path}:{root.sourceline}"
        if root.tag != "scene":
            raise SceneXMLError(f"{where}: the root element is <{root.tag}>, expected <scene>")
        attrs = self.substitute(root, self.path)
        if "version" not in attrs:
            raise SceneXMLError(f"{where}: <scene> has no version attribute (e.g. version=\"3.0.0\")")
        version = parse_version(attrs.pop("version"), where, "scene")
        node = Node("scene", attrs, self.path, root.sourceline, version)
        self.include_stack.append(self.path.resolve())
        self.check_text(root, node)
        for child in root:
            node.children.extend(self.build(child, self.path, version))
        return node

    def substitute(self, el: etree._Element, file: Path) -> dict[str, str]:
        """The element's attributes with ``$name`` replaced (longest names first, as Mitsuba)."""
        out = {}
        for attr, value in el.attrib.items():
            text = value
            if "$" in text:
                for key in sorted(self.values, key=len, reverse=True):
                    if "$" + key in text:
                        text = text.replace("$" + key, self.values[key])
                        self.used.add(key)
                m = _PARAM.search(text)
                if m:
                    raise SceneXMLError(
                        f"{file}:{el.sourceline}: <{el.tag} {attr}=\"{value}\">: undefined parameter "
                        f"${m.group(1)} (give it a <default name=\"{m.group(1)}\" value=\"...\"/> or pass "
                        "it as a parameter)")
            out[str(attr)] = text
        return out

    @staticmethod
    def check_text(el: etree._Element, node: Node) -> None:
        texts = [el.text] + [child.tail for child in el]
        stray = next((t.strip() for t in texts if t and t.strip()), None)
        if stray:
            raise node_error(node, f"unexpected text {stray[:40]!r} (values go in attributes)")

    def build(self, el: etree._Element, file: Path, version: Version) -> list[Node]:
        """One element as nodes: none for <default>/<alias>, several for an <include>."""
        if not isinstance(el.tag, str):
            return []
        attrs = self.substitute(el, file)
        tag = upgrade_element(etree.QName(el).localname, attrs, version)
        node = Node(tag, attrs, file, el.sourceline or 0, version)
        if tag == "default":
            self.default(node)
            return []
        if tag == "alias":
            self.alias(node)
            return []
        if tag == "include":
            return self.include(node)
        self.check_text(el, node)
        for child in el:
            node.children.extend(self.build(child, file, version))
        upgrade_parameters(node)
        if "id" in attrs and tag != "ref":
            self.register_id(attrs["id"], node)
        return [node]

    def register_id(self, ident: str, node: Node) -> None:
        if not ident:
            raise node_error(node, "an id must not be empty")
        if ident in self.ids or ident in self.aliases:
            prev = self.ids[ident].where if ident in self.ids else "an <alias>"
            raise node_error(node, f"duplicate id {ident!r} (first defined at {prev})")
        self.ids[ident] = node

    def default(self, node: Node) -> None:
        expect_attrs(node, {"name", "value"}, required={"name", "value"})
        name = node.attrs["name"]
        if not name:
            raise node_error(node, "a <default> needs a non-empty name")
        self.values.setdefault(name, node.attrs["value"])
        if name in self.params:
            self.used.add(name)

    def alias(self, node: Node) -> None:
        expect_attrs(node, {"id", "as"}, required={"id", "as"})
        src, dst = node.attrs["id"], node.attrs["as"]
        if src not in self.ids and src not in self.aliases:
            raise node_error(node, f"no object with id {src!r} defined before this alias")
        if dst in self.ids or dst in self.aliases:
            raise node_error(node, f"duplicate id {dst!r}")
        self.aliases[dst] = self.aliases.get(src, src)

    def include(self, node: Node) -> list[Node]:
        expect_attrs(node, {"filename"}, required={"filename"})
        path = Path(resolve_file(node.attrs["filename"], node, self.root_dir, "included file"))
        key = path.resolve()
        if key in self.include_stack:
            chain = " -> ".join(str(p) for p in [*self.include_stack, key])
            raise node_error(node, f"include cycle: {chain}")
        if len(self.include_stack) > _MAX_INCLUDE_DEPTH:
            raise node_error(node, f"includes nested more than {_MAX_INCLUDE_DEPTH} deep")
        try:
            root = parse_file(path)
        except OSError as exc:
            raise node_error(node, f"cannot read the included file: {exc}") from None
        self.include_stack.append(key)
        try:
            version = node.version
            if root.tag == "scene":
                attrs = self.substitute(root, path)
                if "version" in attrs:
                    version = parse_version(attrs["version"], f"{path}:{root.sourceline}", "scene")
                self.check_text(root, Node("scene", attrs, path, root.sourceline or 0, version))
                return [n for child in root for n in self.build(child, path, version)]
            if "version" in root.attrib:  # a single object with its own version
                version = parse_version(self.substitute(root, path)["version"], f"{path}:{root.sourceline}",
                                        root.tag)
                del root.attrib["version"]
            return self.build(root, path, version)
        finally:
            self.include_stack.pop()
