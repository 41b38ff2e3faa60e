"""Converged reference images of the denoising evaluation, rendered once and cached on disk.

A reference is ``pyclpt.Renderer(scene, width=, height=, device=).render(spp, seed=1)`` of the
scene seen from one camera. It is cached in a folder (default ``$PYCLPT_CACHE_DIR/denoise-references``,
the platform's cache folder without it: ``~/.cache/pyclpt/denoise-references`` on Linux) as
``<scene>-<W>x<H>-<spp>spp-<key>.npy`` with a ``.json`` beside it (how it was made). The key is a
SHA-1 over the scene's content (materials, emitters, geometry, by
:func:`pyclpt.rendering.progressive.scene_fingerprint`), the camera (its
matrix, field of view and axis), the size, the samples per pixel, the seed and the max depth: a
changed scene or camera never reuses a stale image. References of one scene from several cameras
(the orbit) share one renderer (:class:`ReferenceRenderer`), whose camera is swapped in place.
"""
from __future__ import annotations

import copy
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

import pyclpt
from pyclpt.common.cache import cache_root, content_key
from pyclpt.rendering.progressive import scene_fingerprint

FORMAT = 1
SEED = 1


def default_folder() -> Path:
    return cache_root() / "denoise-references"


def camera_parts(camera: pyclpt.Camera) -> tuple:
    return (np.asarray(camera.to_world, np.float64), float(camera.fov), str(camera.fov_axis))


def reference_key(scene: pyclpt.Scene, width: int, height: int, spp: int, *, camera: pyclpt.Camera | None = None,
                  seed: int = SEED, max_depth: int | None = None) -> str:
    """The cache key of a reference (see the module docstring)."""
    camera = scene.camera if camera is None else camera
    fp = scene_fingerprint(scene, resolution=(width, height), max_depth=max_depth)
    fp = {k: v for k, v in fp.items() if k != "camera"}  # the camera is keyed on its own
    return content_key("denoise-reference", FORMAT, repr(sorted(fp.items())), *camera_parts(camera), int(width),
                       int(height), int(spp), int(seed), max_depth)[:16]


def _safe(label: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in label)


class ReferenceRenderer:
    """References of one scene at one size from any number of cameras, cached in ``folder``
    (None: the default folder; False: no cache). ``device``: as :func:`pyclpt.get_device`.
    ``hits`` / ``misses`` count cache look-ups; ``seconds`` the rendering time of the misses."""

    def __init__(self, scene: pyclpt.Scene, label: str, width: int, height: int, spp: int, *, device: Any = None,
                 folder: str | os.PathLike | None | bool = None, seed: int = SEED, max_depth: int | None = None,
                 progress: bool = False) -> None:
        if spp < 1:
            raise ValueError(f"reference spp must be >= 1, got {spp}")
        self.scene = copy.copy(scene)  # a shallow copy: its camera is swapped, nothing else changes
        self.camera = scene.camera  # the default view
        self.label = label
        self.width, self.height, self.spp = int(width), int(height), int(spp)
        self.seed = int(seed)
        self.max_depth = max_depth
        self.device = device
        self.folder = None if folder is False else Path(folder) if folder not in (None, True) else default_folder()
        self.progress = progress
        self._renderer: pyclpt.Renderer | None = None
        self.hits = self.misses = 0
        self.seconds = 0.0
        self.files: list[str] = []

    def paths(self, camera: pyclpt.Camera) -> tuple[Path, Path] | None:
        if self.folder is None:
            return None
        key = reference_key(self.scene, self.width, self.height, self.spp, camera=camera, seed=self.seed,
                            max_depth=self.max_depth)
        stem = f"{_safe(self.label)}-{self.width}x{self.height}-{self.spp}spp-{key}"
        return self.folder / f"{stem}.npy", self.folder / f"{stem}.json"

    def load(self, camera: pyclpt.Camera | None = None) -> np.ndarray | None:
        """The cached reference for ``camera`` (default: the scene's as given), or None."""
        p = self.paths(self.camera if camera is None else camera)
        if p is None or not p[0].is_file():
            return None
        try:
            img = np.load(p[0], allow_pickle=False)
        except (OSError, ValueError):
            return None
        if img.shape != (self.height, self.width, 3) or img.dtype != np.float32:
            return None
        return img

    def render(self, camera: pyclpt.Camera | None = None) -> np.ndarray:
        """The reference seen from ``camera`` (default: the scene's): from the cache, or rendered
        (and then cached)."""
        camera = self.camera if camera is None else camera
        img = self.load(camera)
        if img is not None:
            self.hits += 1
            p = self.paths(camera)
            if p:
                self.files.append(p[0].name)
            return img
        self.misses += 1
        t = time.perf_counter()
        if self._renderer is None:
            self.scene.camera = camera
            self._renderer = pyclpt.Renderer(self.scene, width=self.width, height=self.height, device=self.device,
                                             max_depth=self.max_depth)
        else:
            self.scene.camera = camera
            self._renderer.scene_buffers.refresh_camera()
        img = self._renderer.render(self.spp, seed=self.seed, progress=self.progress)
        seconds = time.perf_counter() - t
        self.seconds += seconds
        p = self.paths(camera)
        if p is not None:
            self._save(p, img, camera, seconds)
        return img

    def _save(self, paths: tuple[Path, Path], img: np.ndarray, camera: pyclpt.Camera, seconds: float) -> None:
        npy, meta = paths
        try:
            npy.parent.mkdir(parents=True, exist_ok=True)
            tmp = npy.with_name(f"{npy.name}.{os.getpid()}.tmp")
            with open(tmp, "wb") as f:
                np.save(f, np.ascontiguousarray(img, np.float32), allow_pickle=False)
            os.replace(tmp, npy)
            info = {"format": FORMAT, "scene": self.label, "width": self.width, "height": self.height,
                    "spp": self.spp, "seed": self.seed, "max_depth": self.max_depth,
                    "camera": {"to_world": np.asarray(camera.to_world).tolist(), "fov": camera.fov,
                               "fov_axis": camera.fov_axis},
                    "seconds": seconds,
                    "device": getattr(self._renderer.device, "name", None) if self._renderer else None,
                    "pyclpt": pyclpt.__version__, "date": time.strftime("%Y-%m-%d %H:%M:%S")}
            meta.write_text(json.dumps(info, indent=1))
            self.files.append(npy.name)
        except OSError as exc:  # a read-only cache folder: the reference is still returned
            print(f"warning: could not cache the reference in {npy.parent}: {exc}")

    def release(self) -> None:
        """Drop the renderer (its device buffers)."""
        self._renderer = None
