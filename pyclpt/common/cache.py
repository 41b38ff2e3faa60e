"""On-disk cache for parsed meshes and flattened BVHs.

Entries are keyed by the content they were made from (a SHA-1 over the input
arrays and the build parameters), so a changed file or setting never reuses a
stale entry. The folder is ``$PYCLPT_CACHE_DIR`` or ``~/.cache/pyclpt``.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

CACHE_VERSION = "1"


def cache_dir(kind: str) -> Path:
    """Folder for one kind of cache entry (``"mesh"``, ``"bvh"``), created on demand."""
    root = os.environ.get("PYCLPT_CACHE_DIR")
    base = Path(root) if root else Path.home() / ".cache" / "pyclpt"
    path = base / kind
    path.mkdir(parents=True, exist_ok=True)
    return path


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
    with open(tmp, "wb") as f:
        np.savez(f, **arrays)
    os.replace(tmp, path)
