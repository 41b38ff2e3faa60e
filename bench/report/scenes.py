"""The scenes a report covers: each loaded, or skipped with the reason.

Scene arguments (``--scenes``):

- ``builtin``: every built-in scene (``pyclpt scenes``); those that need the shared scene
  folder (``cornell-bunny``, ``cornell-dragon``) are skipped with a note when it is absent;
- ``shared``: every real scene of the shared folder (``$PYCLPT_SCENES/*/scene.xml``), loaded
  with ``pyclpt.load``; a scene the importer cannot load (yet) is skipped with the reason;
- a built-in scene name, a folder name of the shared scene folder (``living-room``), or the
  path of a scene file.

Real scenes are labelled ``shared/<folder>``.
"""
from __future__ import annotations

import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyclpt
from pyclpt.common.logs import captured_warnings
from pyclpt.scene.library import builtin_scenes, scenes_root


@dataclass
class SceneEntry:
    label: str
    source: str  # a built-in name or a file path
    kind: str  # "builtin", "shared" or "file"
    scene: Any = None
    load_s: float = 0.0
    skipped: str | None = None  # the reason, when it could not be loaded or rendered
    info: dict = field(default_factory=dict)

    def record(self) -> dict:
        return {"scene": self.label, "source": self.source, "kind": self.kind, "load_s": self.load_s,
                "skipped": self.skipped, **self.info}


def shared_scene_files() -> list[Path]:
    root = scenes_root()
    if root is None or not root.is_dir():
        return []
    return sorted(p for p in root.glob("*/scene.xml") if p.is_file())


def resolve(names: list[str]) -> list[SceneEntry]:
    """The scene entries named by ``names`` (see the module docstring), in order, without repeats."""
    builtins = list(builtin_scenes())
    shared = {p.parent.name: p for p in shared_scene_files()}
    out: list[SceneEntry] = []
    for name in names:
        if name == "builtin":
            out += [SceneEntry(b, b, "builtin") for b in builtins]
        elif name == "shared":
            root = scenes_root()
            if root is None or not root.is_dir():
                where = f" ({root} does not exist)" if root else ""
                out.append(SceneEntry("shared", "shared", "shared",
                                      skipped=f"the shared scene folder (PYCLPT_SCENES) was not found{where}"))
            elif not shared:
                out.append(SceneEntry("shared", str(root), "shared", skipped=f"no */scene.xml in {root}"))
            out += [SceneEntry(f"shared/{k}", str(p), "shared") for k, p in shared.items()]
        elif name in builtins:
            out.append(SceneEntry(name, name, "builtin"))
        elif name.removeprefix("shared/") in shared:
            key = name.removeprefix("shared/")
            out.append(SceneEntry(f"shared/{key}", str(shared[key]), "shared"))
        elif name.startswith("shared/"):
            where = scenes_root()
            note = (f"{where / name.removeprefix('shared/') / 'scene.xml'} does not exist" if where else
                    "the shared scene folder (PYCLPT_SCENES) was not found")
            out.append(SceneEntry(name, name, "shared", skipped=note))
        else:
            out.append(SceneEntry(Path(name).stem if Path(name).suffix else name, name, "file"))
    seen, unique = set(), []
    for e in out:
        if e.label not in seen:
            seen.add(e.label)
            unique.append(e)
    return unique


def reason(exc: BaseException) -> str:
    """One line naming the exception, for the report's skipped-scene notes."""
    text = " ".join(str(exc).split())
    if len(text) > 300:
        text = text[:297] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def load(entry: SceneEntry) -> SceneEntry:
    """Load the entry's scene; on any failure mark it skipped with the reason (never raises)."""
    if entry.skipped:
        return entry
    t0 = time.perf_counter()
    try:
        with captured_warnings() as caught:  # what the importer ignored or approximated, for the scene notes
            scene = pyclpt.load(entry.source)
        notes = [" ".join(m.split()) for m in caught]
        if notes:
            entry.info["load_warnings"] = notes
        scene.name = entry.label
        entry.scene = scene
        entry.info["triangles"] = int(scene.triangle_count)
    except Exception as exc:  # noqa: BLE001 - any importer failure is a note in the report
        entry.skipped = f"could not be loaded: {reason(exc)}"
        entry.info["traceback"] = traceback.format_exc(limit=3)
    entry.load_s = time.perf_counter() - t0
    return entry
