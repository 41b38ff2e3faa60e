"""Property elements of a Mitsuba XML scene file as plain values: ``<float>``, ``<integer>``, ``<boolean>``,
``<string>`` (a ``filename`` resolved to an absolute path), ``<vector>``/``<point>`` (``[x, y, z]``),
``<rgb>``/``<srgb>``/``<spectrum>``/``<blackbody>`` (``{"type": "rgb", "value": [r, g, b]}``, linear) and
``<transform>`` (a 4x4 float64 matrix, operations applied in document order, each left-multiplying).
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from pyclpt.common.image_io import srgb_to_linear
from pyclpt.scene import transform as tf
from pyclpt.scene.mitsuba_dict import WHERE
from pyclpt.scene.mitsuba_xml.document import resolve_file
from pyclpt.scene.mitsuba_xml.node import Node, SceneXMLError, expect_attrs, node_error
from pyclpt.scene.mitsuba_xml.spectra import blackbody_to_rgb, spectrum_to_rgb

#: Property elements: each becomes one value of its parent object.
VALUE_TAGS = frozenset({"float", "integer", "boolean", "string", "rgb", "srgb", "spectrum", "blackbody",
                        "vector", "point"})
#: The operations a ``<transform>`` holds.
TRANSFORM_OPS = frozenset({"translate", "rotate", "scale", "matrix", "lookat"})
_SPLIT = re.compile(r"[\s,]+")


def value(node: Node, root_dir: Path) -> Any:
    """The value of property element ``node`` (file names also resolve against ``root_dir``)."""
    if node.tag == "transform":
        return transform(node)
    if node.children:
        raise node_error(node, f"<{node.tag}> cannot have child elements")
    tag = node.tag
    if tag in ("float", "integer", "boolean", "string"):
        expect_attrs(node, {"name", "value"}, required={"value"})
        text = node.attrs["value"]
        if tag == "float":
            return number(node, text)
        if tag == "integer":
            return integer(node, text)
        if tag == "boolean":
            if text.strip().lower() not in ("true", "false"):
                raise node_error(node, f"a boolean must be \"true\" or \"false\", got {text!r}")
            return text.strip().lower() == "true"
        return resolve_file(text, node, root_dir) if node.attrs["name"] == "filename" else text
    if tag in ("vector", "point"):
        return xyz(node, 0.0, {"name"})
    if tag in ("rgb", "srgb"):
        expect_attrs(node, {"name", "value", "intent"}, required={"value"})
        return rgb_object(node, color(node, node.attrs["value"], srgb=tag == "srgb"))
    if tag == "spectrum":
        return rgb_object(node, spectrum(node, root_dir))
    return rgb_object(node, blackbody(node))


def rgb_object(node: Node, rgb: list[float]) -> dict[str, Any]:
    return {"type": "rgb", "value": rgb, WHERE: node.where}


# -- numbers ---------------------------------------------------------------------------------------

def number(node: Node, text: str, what: str = "number") -> float:
    try:
        return float(text)
    except ValueError:
        raise node_error(node, f"could not parse a {what} from {text!r}") from None


def integer(node: Node, text: str) -> int:
    try:
        return int(text.strip())
    except ValueError:
        raise node_error(node, f"could not parse an integer from {text!r}") from None


def numbers(node: Node, text: str, counts: tuple[int, ...], what: str) -> list[float]:
    """Numbers separated by spaces or commas, as many as one of ``counts``."""
    tokens = [t for t in _SPLIT.split(text.strip()) if t]
    if len(tokens) not in counts:
        want = " or ".join(str(c) for c in counts)
        raise node_error(node, f"{what} needs {want} numbers, got {len(tokens)} in {text!r}")
    return [number(node, t) for t in tokens]


def xyz(node: Node, default: float, extra: set[str]) -> list[float]:
    """x/y/z attributes (missing ones ``default``) or ``value`` with one or three numbers."""
    expect_attrs(node, {"x", "y", "z", "value"} | extra)
    if "value" in node.attrs:
        if any(a in node.attrs for a in "xyz"):
            raise node_error(node, "give either 'value' or 'x'/'y'/'z', not both")
        values = numbers(node, node.attrs["value"], (1, 3), f"<{node.tag}>")
        return values * 3 if len(values) == 1 else values
    return [number(node, node.attrs[a]) if a in node.attrs else default for a in "xyz"]


# -- colours ---------------------------------------------------------------------------------------

def color(node: Node, text: str, srgb: bool) -> list[float]:
    """``r, g, b`` / ``r g b`` / one gray value / ``#rrggbb`` (always sRGB-encoded)."""
    s = text.strip()
    if s.startswith("#"):
        if not re.fullmatch(r"#[0-9a-fA-F]{6}", s):
            raise node_error(node, f"a hex colour must be #rrggbb, got {text!r}")
        return [srgb_to_linear(int(s[i:i + 2], 16) / 255.0) for i in (1, 3, 5)]
    values = numbers(node, s, (1, 3), f"<{node.tag}>")
    if len(values) == 1:
        values *= 3
    return [srgb_to_linear(v) for v in values] if srgb else values


def spectrum(node: Node, root_dir: Path) -> list[float]:
    """A ``<spectrum>``: one value, ``wavelength:value`` pairs or a file of them (Mitsuba 0.x: 3 values
    are RGB)."""
    expect_attrs(node, {"name", "value", "filename"})
    if ("value" in node.attrs) == ("filename" in node.attrs):
        raise node_error(node, "a <spectrum> needs exactly one of 'value' and 'filename'")
    if "filename" in node.attrs:
        wl, vals = spd_file(node, resolve_file(node.attrs["filename"], node, root_dir, "spectrum file"))
    else:
        text = node.attrs["value"]
        tokens = [t for t in _SPLIT.split(text.strip()) if t]
        if len(tokens) == 1 and ":" not in tokens[0]:
            return [number(node, tokens[0])] * 3
        if all(":" not in t for t in tokens) and len(tokens) == 3 and node.version < (2, 0, 0):
            return [number(node, t) for t in tokens]  # Mitsuba 0.x RGB build: 3 samples
        wl, vals = [], []
        for t in tokens:
            pair = t.split(":")
            if len(pair) != 2:
                raise node_error(node, f"expected wavelength:value pairs, got {t!r}")
            wl.append(number(node, pair[0], "wavelength"))
            vals.append(number(node, pair[1]))
    if not wl or any(b <= a for a, b in zip(wl, wl[1:])):
        raise node_error(node, "spectrum wavelengths must be given in increasing order")
    return spectrum_to_rgb(wl, vals)


def spd_file(node: Node, path: str) -> tuple[list[float], list[float]]:
    """A spectrum file: ``wavelength value`` lines, ``#`` comments."""
    wl, vals = [], []
    try:
        lines = Path(path).read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise node_error(node, f"cannot read spectrum file {path}: {exc}") from None
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
            raise node_error(node, f"{path}:{i}: expected 'wavelength value', got {line!r}") from None
    return wl, vals


def blackbody(node: Node) -> list[float]:
    """A ``<blackbody temperature= scale=>`` (Mitsuba 0.x also ``multiplier``)."""
    expect_attrs(node, {"name", "temperature", "scale", "multiplier"}, required={"temperature"})
    text = node.attrs["temperature"].strip()
    temperature = number(node, text[:-1] if text[-1:] in "kK" and text else text, "temperature")
    scale = number(node, node.attrs.get("scale", node.attrs.get("multiplier", "1")), "scale")
    if not temperature > 0:
        raise node_error(node, f"the temperature must be positive, got {text!r}")
    return blackbody_to_rgb(temperature, scale)


# -- transforms ------------------------------------------------------------------------------------

def transform(node: Node) -> np.ndarray:
    """A ``<transform>``: its operations applied in document order."""
    expect_attrs(node, {"name", "time"})
    m = np.eye(4)
    for op in node.children:
        if op.tag not in TRANSFORM_OPS:
            raise node_error(op, "a <transform> may only hold translate, rotate, scale, matrix and "
                                 "lookat operations")
        try:
            m = operation(op) @ m
        except ValueError as exc:
            if isinstance(exc, SceneXMLError):
                raise
            raise node_error(op, str(exc)) from None
    return m


def operation(op: Node) -> np.ndarray:
    """One transform operation as a 4x4 matrix."""
    if op.children:
        raise node_error(op, f"<{op.tag}> cannot have child elements")
    if op.tag == "translate":
        return tf.translate(xyz(op, 0.0, set()))
    if op.tag == "scale":
        return tf.scale(xyz(op, 1.0, set()))
    if op.tag == "rotate":
        axis = xyz(op, 0.0, {"angle"})
        if "angle" not in op.attrs:
            raise node_error(op, "missing attribute 'angle'")
        return tf.rotate(axis, number(op, op.attrs["angle"], "angle"))
    if op.tag == "matrix":
        expect_attrs(op, {"value"}, required={"value"})
        return tf.matrix(numbers(op, op.attrs["value"], (16, 9), "a matrix"))
    expect_attrs(op, {"origin", "target", "up"}, required={"origin", "target"})
    origin = numbers(op, op.attrs["origin"], (3,), "lookat origin")
    target = numbers(op, op.attrs["target"], (3,), "lookat target")
    up = numbers(op, op.attrs["up"], (3,), "lookat up") if "up" in op.attrs else [0.0, 0.0, 0.0]
    if not any(up):  # Mitsuba: any vector perpendicular to the viewing direction
        up = perpendicular(np.subtract(target, origin))
    return tf.look_at(origin, target, up)


def perpendicular(d: np.ndarray) -> list[float]:
    """A unit vector perpendicular to ``d`` (Duff et al.'s coordinate_system, as Mitsuba)."""
    n = d / np.linalg.norm(d) if np.linalg.norm(d) > 0 else np.array([0.0, 0.0, 1.0])
    sign = 1.0 if n[2] >= 0 else -1.0
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    return [float(v) for v in (1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0])]
