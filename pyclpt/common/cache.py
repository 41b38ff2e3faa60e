"""On-disk cache for parsed meshes and flattened BVHs.

Entries are keyed by the content they were made from (a SHA-1 over the input
arrays and the build parameters), so a changed file or setting never reuses a
stale entry. The folder is ``$PYCLPT_CACHE_DIR``, else the platform's user cache folder
(``platformdirs.user_cache_dir("pyclpt")``: ``~/.cache/pyclpt`` or ``$XDG_CACHE_HOME/pyclpt`` on
Linux, ``~/Library/Caches/pyclpt`` on macOS, under ``%LOCALAPPDATA%`` on Windows). A folder
that cannot be used (a file, not creatable, not writable) turns caching off with
one warning naming it: loading and rendering work as before, only uncached.
"""
from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path

import numpy as np
import platformdirs

from pyclpt.common import env

CACHE_VERSION = "1"
CACHE_ENV = "PYCLPT_CACHE_DIR"

log = logging.getLogger(__name__)
_unusable: set[Path] = set()  # folders already found unusable (and warned about)


def cache_root() -> Path:
    """The cache folder: ``$PYCLPT_CACHE_DIR``, else the platform's user cache folder for pyclpt
    (``platformdirs.user_cache_dir("pyclpt")``; ``~/.cache/pyclpt`` on Linux)."""
    return env.path(CACHE_ENV) or Path(platformdirs.user_cache_dir("pyclpt"))


def cache_dir(kind: str) -> Path | None:
    """Folder for one kind of cache entry (``"mesh"``, ``"bvh"``), created on demand; None when
    the cache folder cannot be used (caching is then off, after one warning for that folder)."""
    root = cache_root()
    folder = root / kind
    if root in _unusable:
        return None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if not os.access(folder, os.W_OK | os.X_OK):
            raise PermissionError(f"{folder} is not writable")
    except OSError as exc:
        _unusable.add(root)
        reason = " ".join(str(exc).split())
        if env.get(CACHE_ENV) is not None:
            log.warning("%s=%r cannot be used as the cache folder (%s); caching of meshes and BVHs is off: "
                        "point %s at a writable folder", CACHE_ENV, env.get(CACHE_ENV), reason, CACHE_ENV)
        else:
            log.warning("the cache folder %s cannot be used (%s); caching of meshes and BVHs is off: "
                        "set %s to a writable folder", root, reason, CACHE_ENV)
        return None
    return folder


def cache_path(kind: str, key: str) -> Path | None:
    """The ``.npz`` file of the entry ``key`` of one kind; None when caching is off (see :func:`cache_dir`).
    Every cache of pyclpt (meshes, BVHs) finds its entries through this function."""
    folder = cache_dir(kind)
    return None if folder is None else folder / f"{key}.npz"


def content_key(*parts: object) -> str:
    """SHA-1 hex digest over numpy arrays (dtype, shape and bytes), bytes and strings."""
    h = hashlib.sha1(CACHE_VERSION.encode())
    for part in parts:
        if isinstance(part, np.ndarray):
            arr = np.ascontiguousarray(part)
            h.update(str(arr.dtype).encode())
            h.update(str(arr.shape).encode())
            h.update(arr.tobytes())
        elif isinstance(part, (bytes, bytearray, memoryview)):
            h.update(bytes(part))
        else:
            h.update(repr(part).encode())
        h.update(b"\x00")
    return h.hexdigest()


def save_npz(path: Path, **arrays: np.ndarray) -> None:
    """Write atomically (temp file + rename) so concurrent readers never see half a file."""
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
