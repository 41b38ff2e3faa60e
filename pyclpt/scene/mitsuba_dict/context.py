"""The state one :func:`~pyclpt.scene.mitsuba_dict.load_dict` call shares between the plug-in loaders.

A :class:`LoadContext` knows where the scene came from (``origin``, ``base_dir`` for relative file
names), which objects carry an id (``named``) and which of them something referenced, collects the
notes that become the one warning of the load, and holds what the loaders have built so far
(materials, meshes, shapegroups and instances, point lights, the environment). Its readers turn one
dictionary value into a checked Python value (number, flag, existing path, transform, constant colour) and raise
:class:`SceneDictError` naming the element and its source line otherwise.
"""
from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from pyclpt.scene import transform as tf
from pyclpt.scene.model import RGB, Bitmap, Envmap, Instance, Light, Material, Mesh, ShapeGroup, rgb

#: Meta key holding an object's source location ``"file:line"`` (added by :mod:`pyclpt.scene.mitsuba_xml`).
WHERE = "__where__"
#: Meta key holding the Mitsuba version (``"0.6.0"``) of the file a plug-in came from, added by
#: :mod:`pyclpt.scene.mitsuba_xml` to the plug-ins of pre-2.0 files whose meaning (not only their
#: parameters' names) changed in Mitsuba 3 (``sunsky``); an object without it is read as Mitsuba 3's.
VERSION = "__version__"
#: Keys of an object that are not parameters.
META_KEYS = frozenset({"type", "id", WHERE, VERSION})
#: Colour-like objects that hold a constant value.
CONSTANT_COLOR_TYPES = frozenset({"rgb", "spectrum", "srgb"})

#: Mitsuba's named indices of refraction (accepted wherever a number is expected).
IORS = {"vacuum": 1.0, "helium": 1.000036, "hydrogen": 1.000132, "air": 1.000277, "carbon dioxide": 1.00045,
        "water": 1.333, "acetone": 1.36, "ethanol": 1.361, "carbon tetrachloride": 1.461, "glycerol": 1.4729,
        "benzene": 1.501, "silicone oil": 1.52045, "bromine": 1.661, "water ice": 1.31, "fused quartz": 1.458,
        "pyrex": 1.47, "acrylic glass": 1.49, "polypropylene": 1.49, "bk7": 1.5046, "glass": 1.5046,
        "sodium chloride": 1.544, "amber": 1.55, "pet": 1.575, "diamond": 2.419}


class SceneDictError(ValueError):
    """A scene dictionary (or scene file) that cannot be loaded; the message names the element."""


def is_dict(v: Any) -> bool:
    return isinstance(v, Mapping)


class LoadContext:
    """One load: its origin, ids, notes, and the scene parts built so far."""

    def __init__(self, base_dir: Path | None, origin: str) -> None:
        self.base_dir = base_dir
        self.files: list[Path] = []  # the files read (Scene.files)
        self.origin = origin
        self.named: dict[str, Mapping[str, Any]] = {}  # objects with an id
        self.referenced: set[str] = set()
        self.notes: list[str] = []
        self.materials: list[Material] = []
        self.material_ids: dict[str, int] = {}
        self.ids: dict[str, str] = {}  # Scene.ids: Mitsuba's names of the scene's objects
        self.meshes: list[Mesh] = []
        self.groups: dict[str, ShapeGroup] = {}  # shapegroups by id, loaded when met or first instanced
        self.instances: list[Instance] = []
        self.lights: list[Light] = []
        self.environment: RGB | Envmap | None = None
        self.bitmaps: dict[tuple, Bitmap] = {}  # one Bitmap per file and sampling settings

    # -- messages ------------------------------------------------------------
    @staticmethod
    def loc(d: Mapping[str, Any] | None, where: str) -> str:
        """``where`` followed by the object's source location, when it has one."""
        at = d.get(WHERE) if is_dict(d) else None
        return f"{where} ({at})" if at else where

    def fail(self, where: str, msg: str, d: Mapping[str, Any] | None = None) -> SceneDictError:
        """The error to raise for element ``where`` (of object ``d``, whose location it names)."""
        at = d.get(WHERE) if is_dict(d) else None
        return SceneDictError(f"{at or self.origin}: {where}: {msg}")

    def note(self, d: Mapping[str, Any] | None, where: str, what: str) -> None:
        """An entry of the load's one warning: something not used, or used differently."""
        self.notes.append(f"{self.loc(d, where)}: {what}")

    def note_unused(self, where: str, d: Mapping[str, Any], used: Iterable[str]) -> None:
        """One entry naming every parameter of ``d`` outside ``used``."""
        used = set(used)
        extra = [k for k in d if k not in used and k not in META_KEYS]
        if extra:
            at = d.get(WHERE) if is_dict(d) else None
            names = ", ".join(f"{where}.{k}" for k in extra)
            self.notes.append(f"{names}{f' ({at})' if at else ''}: ignored")

    # -- references ------------------------------------------------------------
    def deref(self, v: Any, where: str) -> Any:
        """The object a ``{"type": "ref", "id": ...}`` names (marked referenced), else ``v``."""
        if is_dict(v) and v.get("type") == "ref":
            ref = v.get("id")
            if ref not in self.named:
                raise self.fail(where, f"reference to unknown id {ref!r}", v)
            self.referenced.add(ref)
            return self.named[ref]
        return v

    def nested(self, d: Mapping[str, Any], types: Iterable[str], where: str) -> list[tuple[str, Mapping[str, Any]]]:
        """The nested objects (or references) of ``d`` whose type is one of ``types``, with their keys."""
        types = set(types)
        out = []
        for k, v in d.items():
            if k in META_KEYS or not is_dict(v):
                continue
            target = self.deref(v, f"{where}.{k}")
            if target.get("type") in types:
                out.append((k, v))
        return out

    # -- values ----------------------------------------------------------------
    def number(self, d: Mapping[str, Any], key: str, default: float, where: str) -> float:
        """A finite number: a number, a named IOR, or the mean of an rgb/spectrum."""
        v = d.get(key, default)
        if isinstance(v, str):
            v = IORS.get(v.lower(), v)
        if is_dict(v) and v.get("type") in ("rgb", "spectrum") and "value" in v:
            arr = np.asarray(v["value"], np.float64).reshape(-1)
            v = float(arr.mean())
        try:
            out = float(v)
        except (TypeError, ValueError):
            raise self.fail(f"{where}.{key}", f"expected a number, got {v!r}", d) from None
        if not np.isfinite(out):
            raise self.fail(f"{where}.{key}", f"expected a finite number, got {v!r}", d)
        return out

    def flag(self, d: Mapping[str, Any], key: str, default: bool, where: str) -> bool:
        v = d.get(key, default)
        if isinstance(v, (bool, np.bool_)):
            return bool(v)
        if isinstance(v, str) and v.lower() in ("true", "false"):
            return v.lower() == "true"
        raise self.fail(f"{where}.{key}", f"expected true or false, got {v!r}", d)

    def path(self, name: Any, where: str, d: Mapping[str, Any] | None = None) -> Path:
        """An existing file: environment variables expanded, relative names against ``base_dir``."""
        expanded = os.path.expandvars(str(name))
        if "$" in expanded:
            raise self.fail(where, f"{name!r} names an unset environment variable", d)
        p = Path(expanded)
        if not p.is_absolute() and self.base_dir is not None:
            p = self.base_dir / p
        if not p.exists():
            raise self.fail(where, f"file not found: {p}", d)
        self.files.append(Path(os.path.abspath(p)))
        return p

    def transform(self, d: Mapping[str, Any], key: str, where: str) -> np.ndarray:
        """A 4x4 matrix (see :func:`pyclpt.scene.transform.from_spec`); identity when absent."""
        try:
            return tf.from_spec(d.get(key))
        except (ValueError, KeyError, TypeError) as exc:
            raise self.fail(f"{where}.{key}", f"bad transform: {exc}", d) from None

    def vector(self, d: Mapping[str, Any], key: str, where: str) -> np.ndarray:
        """Three numbers (a point or a direction)."""
        try:
            return np.asarray(d[key], np.float64).reshape(3)
        except (ValueError, TypeError):
            raise self.fail(f"{where}.{key}", f"expected 3 numbers, got {d[key]!r}", d) from None

    def constant_color(self, value: Any, where: str, parent: Mapping[str, Any] | None = None) -> RGB:
        """A constant colour: a number, 3 numbers or an rgb/spectrum dict (textures: see
        :func:`pyclpt.scene.mitsuba_dict.textures.color`)."""
        if is_dict(value):
            if value.get("type") in CONSTANT_COLOR_TYPES and "value" in value:
                value = value["value"]
            else:
                raise self.fail(where, f"unsupported color {dict(value)!r} (rgb, spectrum or a number)", value)
        try:
            return rgb(value, where)
        except ValueError as exc:
            raise self.fail(where, str(exc), parent) from None
