"""Finding scenes: pyclpt's built-in scenes (``scenes/*.json``) and the shared
scene folder named by ``PYCLPT_SCENES`` (real scenes and meshes that are not
part of the package, e.g. the Stanford bunny).
"""
from __future__ import annotations

import json
import logging
import os
import re
from pathlib import Path

from pyclpt.common import env
from pyclpt.scene.mitsuba_dict import SceneDictError, load_dict
from pyclpt.scene.model import Scene

log = logging.getLogger(__name__)
SCENES_ENV = "PYCLPT_SCENES"
_warned_roots: set[Path] = set()  # PYCLPT_SCENES values already warned about


def builtin_dir() -> Path:
    package = Path(__file__).resolve().parent.parent
    for candidate in (package / "scenes", package.parent / "scenes"):
        if candidate.is_dir() and any(candidate.glob("*.json")):
            return candidate
    raise FileNotFoundError(f"pyclpt's built-in scenes are missing next to {package}")


def builtin_scenes() -> dict[str, str]:
    """Built-in scene names and their one-line descriptions."""
    out = {}
    for path in sorted(builtin_dir().glob("*.json")):
        out[path.stem] = json.loads(path.read_text()).get("description", "")
    return out


def scenes_root() -> Path | None:
    """The shared scene folder: ``$PYCLPT_SCENES``, else ``../shared/scenes`` beside the
    working directory or beside pyclpt's source tree; None if none exists. A ``PYCLPT_SCENES``
    that is not a folder is returned as it is (loading what needs it then fails, naming it),
    with one warning naming the variable."""
    root = env.path(SCENES_ENV)
    if root is not None:
        if not root.is_dir() and root not in _warned_roots:
            _warned_roots.add(root)
            log.warning("%s: %s, so the scenes and meshes of the shared scene folder cannot be found: set it to "
                        "the folder holding meshes/ and the real scenes, or unset it", env.describe(SCENES_ENV),
                        "a file, not a folder" if root.exists() else "no such folder")
        return root
    checkout = Path(__file__).resolve().parents[2]
    for candidate in (Path.cwd().parent / "shared" / "scenes", checkout.parent / "shared" / "scenes"):
        if candidate.is_dir():
            return candidate
    return None


def shared_path(relative: str) -> Path:
    """A file in the shared scene folder, with a clear error if it is absent."""
    root = scenes_root()
    if root is None:
        raise FileNotFoundError(
            f"{relative} lives in the shared scene folder, which was not found: set PYCLPT_SCENES "
            "to the folder holding meshes/ and the real scenes (e.g. ../shared/scenes)")
    path = root / relative
    if not path.exists():
        raise FileNotFoundError(f"{path} not found (PYCLPT_SCENES={root})")
    return path


def load(name_or_path: str | os.PathLike, /, **params: object) -> Scene:
    """A built-in scene by name (``pyclpt.load("cornell-box")``) or a scene file (.json, or Mitsuba
    .xml). ``params`` (converted with ``str``) override an XML file's ``<default>`` values, as
    Mitsuba's ``-D name=value``: ``pyclpt.load("scene.xml", spp=16, resx=64)``."""
    text = str(name_or_path)
    path = Path(text)
    builtin = builtin_dir() / f"{text}.json"
    if not path.suffix and builtin.is_file():
        path, name = builtin, text
    elif path.is_file():
        name = path.stem
    else:
        known = ", ".join(builtin_scenes())
        raise FileNotFoundError(f"no built-in scene or scene file named {text!r} (built-in: {known})")
    if path.suffix.lower() == ".xml":
        from pyclpt.scene.mitsuba_xml import load_xml

        return load_xml(path, **params)
    if path.suffix.lower() != ".json":
        raise SceneDictError(f"{path}: unsupported scene file type {path.suffix!r} (.json, .xml)")
    if params:
        raise ValueError(f"{path}: parameters ({', '.join(params)}) apply only to Mitsuba .xml scenes")
    try:
        d = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise SceneDictError(f"{path}:{exc.lineno}: invalid JSON: {exc.msg}") from None
    except UnicodeDecodeError as exc:
        raise SceneDictError(f"{path}: not a UTF-8 text file ({exc.reason} at byte {exc.start})") from None
    if not isinstance(d, dict):
        kind = {list: "an array", str: "a string", bool: "a boolean", int: "a number", float: "a number"}
        raise SceneDictError(f"{path}: a JSON scene is an object ({{\"type\": \"scene\", ...}}) at the top level, "
                             f"not {kind.get(type(d), 'null')}")
    d.pop("description", None)
    text_d = json.dumps(d)
    if "${PYCLPT_SCENES}" in text_d:
        root = scenes_root()
        if root is None:
            raise FileNotFoundError(
                f"scene {name!r} needs files from the shared scene folder (e.g. meshes/bunny.ply), "
                "which was not found: set PYCLPT_SCENES to it (e.g. ../shared/scenes)")
        d = json.loads(text_d.replace("${PYCLPT_SCENES}", root.as_posix()))
        for rel in re.findall(r'\$\{PYCLPT_SCENES\}/([^"]*)"', text_d):
            if not (root / rel).exists():
                raise FileNotFoundError(
                    f"scene {name!r} needs {rel} from the shared scene folder, but {root / rel} does not "
                    f"exist: set PYCLPT_SCENES to the folder holding meshes/ (e.g. ../shared/scenes)")
    scene = load_dict(d, base_dir=path.parent, name=name, origin=str(path))
    scene.source = path
    scene.files = list(dict.fromkeys([Path(os.path.abspath(path)), *scene.files]))
    return scene
