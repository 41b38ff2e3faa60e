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
whose message starts with ``file:line:`` and names the element and the offending value.
"""
from __future__ import annotations

import os
import re
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from lxml import etree

from pyclpt.common.image_io import srgb_to_linear
from pyclpt.scene import transform as tf
from pyclpt.scene.mitsuba_dict import SceneDictError, load_dict
from pyclpt.scene.model import Scene

__all__ = ["SceneXMLError", "WHERE", "blackbody_to_rgb", "load_xml", "spectrum_to_rgb", "srgb_to_linear",
           "to_snake_case", "xml_to_dict"]

#: Meta key holding an object's source location ``"file:line"``.
WHERE = "__where__"

Version = tuple[int, int, int]

#: Tags that are always objects (plug-ins); any other tag with a ``type`` attribute is one too.
OBJECT_TAGS = frozenset({"scene", "bsdf", "shape", "emitter", "texture", "sensor", "film", "sampler",
                         "rfilter", "integrator", "medium", "phase", "volume", "subsurface"})
VALUE_TAGS = frozenset({"float", "integer", "boolean", "string", "rgb", "srgb", "spectrum", "blackbody",
                        "vector", "point"})
TRANSFORM_OPS = frozenset({"translate", "rotate", "scale", "matrix", "lookat"})
#: Objects keyed by their plain tag when they are the first of their kind in the scene.
_SINGLETONS = frozenset({"sensor", "integrator"})
_MAX_INCLUDE_DEPTH = 15
_PARAM = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")
_VERSION = re.compile(r"^\s*(\d+)[ .](\d+)[ .](\d+)\s*$")
_SPLIT = re.compile(r"[\s,]+")


class SceneXMLError(SceneDictError):
    """A Mitsuba XML scene file that cannot be translated; the message starts with ``file:line:``."""


# -- names -------------------------------------------------------------------------------------


def to_snake_case(name: str) -> str:
    """Mitsuba 3's upgrade of a pre-2.0 parameter name: a lowercase letter followed by an uppercase
    one starts a new word, and the whole uppercase run is lowercased (``toWorld`` -> ``to_world``,
    ``intIOR`` -> ``int_ior``, ``sunRadiusScale`` -> ``sun_radius_scale``, ``kNN`` -> ``k_nn``)."""
    out: list[str] = []
    i = 0
    while i < len(name):
        c = name[i]
        out.append(c)
        i += 1
        if c.islower() and i < len(name) and name[i].isupper():
            out.append("_")
            while i < len(name) and name[i].isupper():
                out.append(name[i].lower())
                i += 1
    return "".join(out)


# -- colour ------------------------------------------------------------------------------------

_LAMBDA = np.arange(360.0, 831.0, 1.0)  # nm, 1 nm steps over the CIE range


def _lobe(x: np.ndarray, mu: float, s1: float, s2: float) -> np.ndarray:
    t = (x - mu) / np.where(x < mu, s1, s2)
    return np.exp(-0.5 * t * t)


def _cie_xyz(lam: np.ndarray) -> np.ndarray:
    """CIE 1931 2-degree colour-matching functions, Wyman, Sloan and Shirley's (2013) multi-lobe fit."""
    x = 1.056 * _lobe(lam, 599.8, 37.9, 31.0) + 0.362 * _lobe(lam, 442.0, 16.0, 26.7) \
        - 0.065 * _lobe(lam, 501.1, 20.4, 26.2)
    y = 0.821 * _lobe(lam, 568.8, 46.9, 40.5) + 0.286 * _lobe(lam, 530.9, 16.3, 31.1)
    z = 1.217 * _lobe(lam, 437.0, 11.8, 36.0) + 0.681 * _lobe(lam, 459.0, 26.0, 13.8)
    return np.stack([x, y, z])


_XYZ_TO_SRGB = np.array([[3.2404542, -1.5371385, -0.4985314],
                         [-0.9692660, 1.8760108, 0.0415560],
                         [0.0556434, -0.2040259, 1.0572252]])
_CMF = _cie_xyz(_LAMBDA)  # (3, N)
_WHITE = _XYZ_TO_SRGB @ _CMF.sum(axis=1)  # linear sRGB of a constant spectrum of 1
_Y_NORM = float(_CMF[1].sum())  # Mitsuba's CIE_Y_NORMALIZATION: a constant 1 has Y = 1


def _sampled_to_rgb(values: np.ndarray, white_balanced: bool) -> list[float]:
    """Linear sRGB of a spectrum sampled on ``_LAMBDA``: integrated against the CIE curves, XYZ to
    linear sRGB, then divided channel-wise by the result for a constant 1 (``white_balanced``: a
    constant 1 maps to (1, 1, 1)) or by the integral of y-bar (colorimetric, as Mitsuba: Y is the
    ȳ-weighted mean, and the sRGB white, D65, maps to gray). Negative channels are clamped to 0."""
    rgb = _XYZ_TO_SRGB @ (_CMF @ values)
    rgb = rgb / _WHITE if white_balanced else rgb / _Y_NORM
    return [float(v) for v in np.maximum(rgb, 0.0)]


def spectrum_to_rgb(wavelengths: Iterable[float], values: Iterable[float]) -> list[float]:
    """Linear sRGB of a piecewise-linear spectrum (wavelengths in nm, increasing; zero outside
    them), normalised so that a constant spectrum of 1 over the visible range (360-830 nm) gives
    (1, 1, 1). Negative channels (out of gamut) are clamped to 0."""
    wl = np.asarray(list(wavelengths), np.float64)
    v = np.asarray(list(values), np.float64)
    s = np.interp(_LAMBDA, wl, v, left=0.0, right=0.0)
    return _sampled_to_rgb(s, white_balanced=True)


def blackbody_to_rgb(temperature: float, scale: float = 1.0) -> list[float]:
    """Linear sRGB of a black body, times ``scale``: Planck's spectral radiance in W/(m^2 sr nm), as
    Mitsuba's ``blackbody``, converted colorimetrically (XYZ with Y the ȳ-weighted mean radiance,
    then linear sRGB, without :func:`spectrum_to_rgb`'s white balance), so a 6500 K body is about
    neutral, about 4.2e4 per channel."""
    h, c, k = 6.62607015e-34, 299792458.0, 1.380649e-23
    lam = _LAMBDA * 1e-9
    with np.errstate(over="ignore"):
        radiance = 1e-9 * (2.0 * h * c * c) / lam**5 / np.expm1((h * c) / (lam * k * temperature))
    return [scale * v for v in _sampled_to_rgb(radiance, white_balanced=False)]


# -- the parsed tree -----------------------------------------------------------------------------


@dataclass
class _Node:
    """One XML element after parameter substitution, version upgrade and include splicing."""

    tag: str
    attrs: dict[str, str]
    file: Path
    line: int
    version: Version
    children: list[_Node] = field(default_factory=list)

    @property
    def where(self) -> str:
        return f"{self.file}:{self.line}"

    def describe(self) -> str:
        """The element as written, e.g. ``<float name="fov" value="abc">``."""
        attrs = "".join(f' {k}="{v}"' for k, v in self.attrs.items())
        return f"<{self.tag}{attrs}>"


def _parse_version(text: str, where: str, tag: str) -> Version:
    m = _VERSION.match(text)
    if not m:
        raise SceneXMLError(f"{where}: <{tag} version=\"{text}\">: a version must be three numbers, "
                            "e.g. \"3.0.0\"")
    return int(m.group(1)), int(m.group(2)), int(m.group(3))


def _parse_file(path: Path) -> etree._Element:
    parser = etree.XMLParser(resolve_entities=False, no_network=True, remove_comments=True,
                             remove_pis=True, huge_tree=True)
    try:
        return etree.fromstring(path.read_bytes(), parser)
    except etree.XMLSyntaxError as exc:
        line = exc.lineno or (exc.position[0] if exc.position else 0)
        raise SceneXMLError(f"{path}:{line}: malformed XML: {exc.msg}") from None


# -- translation ---------------------------------------------------------------------------------


class _Translator:
    def __init__(self, path: Path, params: Mapping[str, str]) -> None:
        self.path = path
        self.root_dir = path.parent
        self.params = {str(k): str(v) for k, v in params.items()}
        self.values: dict[str, str] = dict(self.params)  # parameters win over <default>s
        self.used: set[str] = set()
        self.ids: dict[str, _Node] = {}
        self.aliases: dict[str, str] = {}
        self.include_stack: list[Path] = []

    @staticmethod
    def error(node: _Node, msg: str) -> SceneXMLError:
        return SceneXMLError(f"{node.where}: {node.describe()}: {msg}")

    # -- pass 1: substitution, upgrade, includes, defaults, ids ------------------------------------
    def read(self) -> _Node:
        root = _parse_file(self.path)
        where = f"{self.path}:{root.sourceline}"
        if root.tag != "scene":
            raise SceneXMLError(f"{where}: the root element is <{root.tag}>, expected <scene>")
        attrs = self.substitute(root, self.path)
        if "version" not in attrs:
            raise SceneXMLError(f"{where}: <scene> has no version attribute (e.g. version=\"3.0.0\")")
        version = _parse_version(attrs.pop("version"), where, "scene")
        node = _Node("scene", attrs, self.path, root.sourceline, version)
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

    def check_text(self, el: etree._Element, node: _Node) -> None:
        texts = [el.text] + [child.tail for child in el]
        stray = next((t.strip() for t in texts if t and t.strip()), None)
        if stray:
            raise self.error(node, f"unexpected text {stray[:40]!r} (values go in attributes)")

    def build(self, el: etree._Element, file: Path, version: Version) -> list[_Node]:
        """One element as nodes: none for <default>/<alias>, several for an <include>."""
        if not isinstance(el.tag, str):
            return []
        tag = etree.QName(el).localname
        attrs = self.substitute(el, file)
        if version < (2, 0, 0):
            if tag == "lookAt":
                tag = "lookat"
            if "name" in attrs and tag != "default":
                attrs["name"] = to_snake_case(attrs["name"])
        node = _Node(tag, attrs, file, el.sourceline or 0, version)
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
        if version < (2, 0, 0) and tag == "bsdf" and attrs.get("type") == "diffuse":
            for child in node.children:
                if child.attrs.get("name") == "diffuse_reflectance":
                    child.attrs["name"] = "reflectance"
        if "id" in attrs and tag not in ("ref",):
            self.register_id(attrs["id"], node)
        return [node]

    def register_id(self, ident: str, node: _Node) -> None:
        if not ident:
            raise self.error(node, "an id must not be empty")
        if ident in self.ids or ident in self.aliases:
            prev = self.ids[ident].where if ident in self.ids else "an <alias>"
            raise self.error(node, f"duplicate id {ident!r} (first defined at {prev})")
        self.ids[ident] = node

    def default(self, node: _Node) -> None:
        self.expect_attrs(node, {"name", "value"}, required={"name", "value"})
        name = node.attrs["name"]
        if not name:
            raise self.error(node, "a <default> needs a non-empty name")
        self.values.setdefault(name, node.attrs["value"])
        if name in self.params:
            self.used.add(name)

    def alias(self, node: _Node) -> None:
        self.expect_attrs(node, {"id", "as"}, required={"id", "as"})
        src, dst = node.attrs["id"], node.attrs["as"]
        if src not in self.ids and src not in self.aliases:
            raise self.error(node, f"no object with id {src!r} defined before this alias")
        if dst in self.ids or dst in self.aliases:
            raise self.error(node, f"duplicate id {dst!r}")
        self.aliases[dst] = self.aliases.get(src, src)

    def include(self, node: _Node) -> list[_Node]:
        self.expect_attrs(node, {"filename"}, required={"filename"})
        path = Path(self.resolve(node.attrs["filename"], node, "included file"))
        key = path.resolve()
        if key in self.include_stack:
            chain = " -> ".join(str(p) for p in [*self.include_stack, key])
            raise self.error(node, f"include cycle: {chain}")
        if len(self.include_stack) > _MAX_INCLUDE_DEPTH:
            raise self.error(node, f"includes nested more than {_MAX_INCLUDE_DEPTH} deep")
        try:
            root = _parse_file(path)
        except OSError as exc:
            raise self.error(node, f"cannot read the included file: {exc}") from None
        self.include_stack.append(key)
        try:
            version = node.version
            if root.tag == "scene":
                attrs = self.substitute(root, path)
                if "version" in attrs:
                    version = _parse_version(attrs["version"], f"{path}:{root.sourceline}", "scene")
                self.check_text(root, _Node("scene", attrs, path, root.sourceline or 0, version))
                return [n for child in root for n in self.build(child, path, version)]
            if "version" in root.attrib:  # a single object with its own version
                version = _parse_version(self.substitute(root, path)["version"], f"{path}:{root.sourceline}",
                                         root.tag)
                del root.attrib["version"]
            return self.build(root, path, version)
        finally:
            self.include_stack.pop()

    # -- helpers ---------------------------------------------------------------------------------
    def expect_attrs(self, node: _Node, allowed: set[str], required: Iterable[str] = ()) -> None:
        for attr in node.attrs:
            if attr not in allowed:
                raise self.error(node, f"unexpected attribute {attr!r} (allowed: {', '.join(sorted(allowed))})")
        for attr in sorted(required):
            if attr not in node.attrs:
                raise self.error(node, f"missing attribute {attr!r}")

    def resolve(self, name: str, node: _Node, what: str = "file") -> str:
        """An absolute path for a file name: as given if absolute, else relative to the folder of
        the file holding ``node``, then to the main scene's folder (Mitsuba's file resolver)."""
        candidates = []
        for variant in dict.fromkeys([name, name.replace("\\", "/")]):
            p = Path(variant)
            candidates += [p] if p.is_absolute() else [node.file.parent / p, self.root_dir / p]
        for p in dict.fromkeys(candidates):
            if p.is_file():
                return os.path.abspath(p)
        raise self.error(node, f"{what} not found: {os.path.abspath(candidates[0])}")

    # -- pass 2: nodes to dicts ----------------------------------------------------------------------
    def scene(self, root: _Node) -> dict[str, Any]:
        d: dict[str, Any] = {"type": "scene", WHERE: root.where}
        if "id" in root.attrs:
            d["id"] = root.attrs["id"]
        self.fill(d, root, top_level=True)
        return d

    def is_object(self, node: _Node) -> bool:
        if node.tag in OBJECT_TAGS:
            return True
        if node.tag == "spectrum":
            return "type" in node.attrs
        return "type" in node.attrs and node.tag not in VALUE_TAGS | TRANSFORM_OPS | {"transform", "ref"}

    def fill(self, d: dict[str, Any], node: _Node, top_level: bool) -> None:
        """Translate ``node``'s children into ``d``."""
        counters: dict[str, int] = {}
        reserved = {c.attrs[a] for c in node.children for a in ("id", "name")
                    if a in c.attrs and (a == "name" or top_level)}
        for child in node.children:
            if child.tag in TRANSFORM_OPS:
                raise self.error(child, "a transform operation must be inside a <transform>")
            if child.tag == "ref" or self.is_object(child):
                value, tag = self.ref(child) if child.tag == "ref" else (self.object(child), child.tag)
                key = child.attrs.get("id") if top_level and child.tag != "ref" else None
                key = key or child.attrs.get("name")
                if key is None:
                    key = self.auto_key(d, tag, counters, reserved, top_level)
            elif child.tag in VALUE_TAGS or child.tag == "transform":
                if "name" not in child.attrs:
                    raise self.error(child, "missing attribute 'name'")
                key, value = child.attrs["name"], self.value(child)
            else:
                raise self.error(child, f"unknown element <{child.tag}> (objects need a type attribute; "
                                        f"values are {', '.join(sorted(VALUE_TAGS | {'transform'}))})")
            if key in d or key == WHERE:
                raise self.error(child, f"{key!r} is given twice in {node.describe()}")
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

    def ref(self, node: _Node) -> tuple[dict[str, Any], str]:
        self.expect_attrs(node, {"id", "name"}, required={"id"})
        ident = self.aliases.get(node.attrs["id"], node.attrs["id"])
        target = self.ids.get(ident)
        if target is None:
            known = ", ".join(sorted(self.ids)[:20]) or "none"
            raise self.error(node, f"no object with id {ident!r} (ids: {known})")
        return {"type": "ref", "id": ident, WHERE: node.where}, target.tag

    def object(self, node: _Node) -> dict[str, Any]:
        self.expect_attrs(node, {"type", "id", "name"}, required={"type"})
        if node.tag == "spectrum" and node.attrs["type"] == "blackbody":
            return self.blackbody_object(node)
        d: dict[str, Any] = {"type": node.attrs["type"], WHERE: node.where}
        if "id" in node.attrs:
            d["id"] = node.attrs["id"]
        self.fill(d, node, top_level=False)
        return d

    # -- values ----------------------------------------------------------------------------------
    def value(self, node: _Node) -> Any:
        if node.tag == "transform":
            return self.transform(node)
        if node.children:
            raise self.error(node, f"<{node.tag}> cannot have child elements")
        tag = node.tag
        if tag in ("float", "integer", "boolean", "string"):
            self.expect_attrs(node, {"name", "value"}, required={"value"})
            text = node.attrs["value"]
            if tag == "float":
                return self.number(node, text)
            if tag == "integer":
                return self.integer(node, text)
            if tag == "boolean":
                if text.strip().lower() not in ("true", "false"):
                    raise self.error(node, f"a boolean must be \"true\" or \"false\", got {text!r}")
                return text.strip().lower() == "true"
            return self.resolve(text, node) if node.attrs["name"] == "filename" else text
        if tag in ("vector", "point"):
            return self.xyz(node, 0.0, {"name"})
        if tag in ("rgb", "srgb"):
            self.expect_attrs(node, {"name", "value", "intent"}, required={"value"})
            return self.rgb(node, self.color(node, node.attrs["value"], srgb=tag == "srgb"))
        if tag == "spectrum":
            return self.rgb(node, self.spectrum(node))
        return self.rgb(node, self.blackbody(node))

    def rgb(self, node: _Node, value: list[float]) -> dict[str, Any]:
        return {"type": "rgb", "value": value, WHERE: node.where}

    def number(self, node: _Node, text: str, what: str = "number") -> float:
        try:
            return float(text)
        except ValueError:
            raise self.error(node, f"could not parse a {what} from {text!r}") from None

    def integer(self, node: _Node, text: str) -> int:
        try:
            return int(text.strip())
        except ValueError:
            raise self.error(node, f"could not parse an integer from {text!r}") from None

    def numbers(self, node: _Node, text: str, counts: tuple[int, ...], what: str) -> list[float]:
        tokens = [t for t in _SPLIT.split(text.strip()) if t]
        if len(tokens) not in counts:
            want = " or ".join(str(c) for c in counts)
            raise self.error(node, f"{what} needs {want} numbers, got {len(tokens)} in {text!r}")
        return [self.number(node, t) for t in tokens]

    def color(self, node: _Node, text: str, srgb: bool) -> list[float]:
        """``r, g, b`` / ``r g b`` / one gray value / ``#rrggbb`` (always sRGB-encoded)."""
        s = text.strip()
        if s.startswith("#"):
            if not re.fullmatch(r"#[0-9a-fA-F]{6}", s):
                raise self.error(node, f"a hex colour must be #rrggbb, got {text!r}")
            return [srgb_to_linear(int(s[i:i + 2], 16) / 255.0) for i in (1, 3, 5)]
        values = self.numbers(node, s, (1, 3), f"<{node.tag}>")
        if len(values) == 1:
            values *= 3
        return [srgb_to_linear(v) for v in values] if srgb else values

    def spectrum(self, node: _Node) -> list[float]:
        self.expect_attrs(node, {"name", "value", "filename"})
        if ("value" in node.attrs) == ("filename" in node.attrs):
            raise self.error(node, "a <spectrum> needs exactly one of 'value' and 'filename'")
        if "filename" in node.attrs:
            wl, vals = self.spd_file(node, self.resolve(node.attrs["filename"], node, "spectrum file"))
        else:
            text = node.attrs["value"]
            tokens = [t for t in _SPLIT.split(text.strip()) if t]
            if len(tokens) == 1 and ":" not in tokens[0]:
                return [self.number(node, tokens[0])] * 3
            if all(":" not in t for t in tokens) and len(tokens) == 3 and node.version < (2, 0, 0):
                return [self.number(node, t) for t in tokens]  # Mitsuba 0.x RGB build: 3 samples
            wl, vals = [], []
            for t in tokens:
                pair = t.split(":")
                if len(pair) != 2:
                    raise self.error(node, f"expected wavelength:value pairs, got {t!r}")
                wl.append(self.number(node, pair[0], "wavelength"))
                vals.append(self.number(node, pair[1]))
        if not wl or any(b <= a for a, b in zip(wl, wl[1:])):
            raise self.error(node, "spectrum wavelengths must be given in increasing order")
        return spectrum_to_rgb(wl, vals)

    def spd_file(self, node: _Node, path: str) -> tuple[list[float], list[float]]:
        wl, vals = [], []
        try:
            lines = Path(path).read_text().splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise self.error(node, f"cannot read spectrum file {path}: {exc}") from None
        for i, line in enumerate(lines, 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            parts = line.split()
            try:
                if len(parts) != 2:
                    raise ValueError
                wl.append(float(parts[0]))
                vals.append(float(parts[1]))
            except ValueError:
                raise self.error(node, f"{path}:{i}: expected 'wavelength value', got {line!r}") from None
        return wl, vals

    def blackbody(self, node: _Node) -> list[float]:
        self.expect_attrs(node, {"name", "temperature", "scale", "multiplier"}, required={"temperature"})
        text = node.attrs["temperature"].strip()
        temperature = self.number(node, text[:-1] if text[-1:] in "kK" and text else text, "temperature")
        scale = self.number(node, node.attrs.get("scale", node.attrs.get("multiplier", "1")), "scale")
        if not temperature > 0:
            raise self.error(node, f"the temperature must be positive, got {text!r}")
        return blackbody_to_rgb(temperature, scale)

    def blackbody_object(self, node: _Node) -> dict[str, Any]:
        """Mitsuba 3's ``<spectrum type="blackbody">`` with float ``temperature`` (and ``scale``)."""
        props: dict[str, Any] = {}
        self.fill(props, node, top_level=False)
        extra = set(props) - {"temperature", "scale"}
        if "temperature" not in props or extra:
            raise self.error(node, "a blackbody spectrum takes float 'temperature' and 'scale' only"
                             + (f" (got {', '.join(sorted(extra))})" if extra else ""))
        if not props["temperature"] > 0:
            raise self.error(node, f"the temperature must be positive, got {props['temperature']}")
        return self.rgb(node, blackbody_to_rgb(props["temperature"], props.get("scale", 1.0)))

    def xyz(self, node: _Node, default: float, extra: set[str]) -> list[float]:
        """x/y/z attributes (missing ones ``default``) or ``value`` with one or three numbers."""
        self.expect_attrs(node, {"x", "y", "z", "value"} | extra)
        if "value" in node.attrs:
            if any(a in node.attrs for a in "xyz"):
                raise self.error(node, "give either 'value' or 'x'/'y'/'z', not both")
            values = self.numbers(node, node.attrs["value"], (1, 3), f"<{node.tag}>")
            return values * 3 if len(values) == 1 else values
        return [self.number(node, node.attrs[a]) if a in node.attrs else default for a in "xyz"]

    # -- transforms ------------------------------------------------------------------------------
    def transform(self, node: _Node) -> np.ndarray:
        self.expect_attrs(node, {"name", "time"})
        m = np.eye(4)
        for op in node.children:
            if op.tag not in TRANSFORM_OPS:
                raise self.error(op, "a <transform> may only hold translate, rotate, scale, matrix and "
                                     "lookat operations")
            try:
                m = self.operation(op) @ m
            except ValueError as exc:
                if isinstance(exc, SceneXMLError):
                    raise
                raise self.error(op, str(exc)) from None
        return m

    def operation(self, op: _Node) -> np.ndarray:
        if op.children:
            raise self.error(op, f"<{op.tag}> cannot have child elements")
        if op.tag == "translate":
            return tf.translate(self.xyz(op, 0.0, set()))
        if op.tag == "scale":
            return tf.scale(self.xyz(op, 1.0, set()))
        if op.tag == "rotate":
            axis = self.xyz(op, 0.0, {"angle"})
            if "angle" not in op.attrs:
                raise self.error(op, "missing attribute 'angle'")
            return tf.rotate(axis, self.number(op, op.attrs["angle"], "angle"))
        if op.tag == "matrix":
            self.expect_attrs(op, {"value"}, required={"value"})
            return tf.matrix(self.numbers(op, op.attrs["value"], (16, 9), "a matrix"))
        self.expect_attrs(op, {"origin", "target", "up"}, required={"origin", "target"})
        origin = self.numbers(op, op.attrs["origin"], (3,), "lookat origin")
        target = self.numbers(op, op.attrs["target"], (3,), "lookat target")
        up = self.numbers(op, op.attrs["up"], (3,), "lookat up") if "up" in op.attrs else [0.0, 0.0, 0.0]
        if not any(up):  # Mitsuba: any vector perpendicular to the viewing direction
            up = _perpendicular(np.subtract(target, origin))
        return tf.look_at(origin, target, up)

    def warn_unused(self) -> None:
        unused = [k for k in self.params if k not in self.used]
        if unused:
            warnings.warn(f"{self.path}: parameter{'s' if len(unused) > 1 else ''} "
                          f"{', '.join(unused)} not used by the scene", stacklevel=3)


def _perpendicular(d: np.ndarray) -> list[float]:
    """A unit vector perpendicular to ``d`` (Duff et al.'s coordinate_system, as Mitsuba)."""
    n = d / np.linalg.norm(d) if np.linalg.norm(d) > 0 else np.array([0.0, 0.0, 1.0])
    sign = 1.0 if n[2] >= 0 else -1.0
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    return [float(v) for v in (1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0])]


# -- public API ----------------------------------------------------------------------------------


def xml_to_dict(path: str | os.PathLike, params: Mapping[str, str] | None = None) -> dict[str, Any]:
    """A Mitsuba XML scene file as a Mitsuba 3 ``load_dict`` dictionary (see the module docstring).

    ``params`` override the file's ``<default>`` values (as Mitsuba's ``-D name=value``).
    Raises :class:`SceneXMLError` for malformed or invalid files, FileNotFoundError if ``path``
    does not exist; warns about parameters the scene does not use.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: scene file not found")
    t = _Translator(path, params or {})
    root = t.read()
    d = t.scene(root)
    t.warn_unused()
    return d


def load_xml(path: str | os.PathLike, **params: object) -> Scene:
    """A :class:`~pyclpt.scene.model.Scene` from a Mitsuba XML file; ``params`` (converted with ``str``)
    override its ``<default>`` values. The scene is named after its folder for ``scene.xml``,
    else after the file."""
    path = Path(path)
    d = xml_to_dict(path, {k: str(v) for k, v in params.items()})
    name = path.resolve().parent.name if path.name.lower() == "scene.xml" else path.stem
    scene = load_dict(d, base_dir=path.parent, name=name or path.stem, origin=str(path))
    scene.source = path
    return scene
