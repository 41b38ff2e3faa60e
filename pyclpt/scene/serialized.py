"""Reader for Mitsuba's ``.serialized`` triangle-mesh format (file versions 3 and 4).

Layout (little endian), as documented by Mitsuba 0.5/0.6 and Mitsuba 3 (``shapes/serialized.cpp``):

* per shape: ``uint16`` magic ``0x041C``, ``uint16`` version (3 or 4), then one zlib stream holding
  ``uint32`` flags, the shape name (version 4 only: null-terminated UTF-8), ``uint64`` vertex and
  triangle counts, positions, [normals], [uvs], [vertex colors] as float32 or float64 (flags
  ``0x1000`` / ``0x2000``), then triangle indices (``uint32``, ``uint64`` if more than 2^32 vertices);
* at the end of the file: the byte offset of every shape (``uint64`` in version 4, ``uint32`` in
  version 3) followed by the ``uint32`` shape count.

Flags: ``0x0001`` vertex normals, ``0x0002`` uvs, ``0x0008`` vertex colors (read and skipped),
``0x0010`` face normals (the file's vertex normals are dropped, as Mitsuba's ``face_normals``).
"""
from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path

import numpy as np

from pyclpt.scene.mesh_io import MeshData, MeshLoadError

MAGIC = 0x041C
VERSIONS = (3, 4)

HAS_NORMALS = 0x0001
HAS_UVS = 0x0002
HAS_COLORS = 0x0008
FACE_NORMALS = 0x0010
SINGLE_PRECISION = 0x1000
DOUBLE_PRECISION = 0x2000

_CHUNK = 1 << 20


class _Reader:
    """Sequential little-endian reads from a decompressed shape block, with truncation checks."""

    def __init__(self, data: bytes, fail) -> None:
        self.data, self.pos, self.fail = data, 0, fail

    def take(self, n: int, what: str) -> bytes:
        if n < 0 or self.pos + n > len(self.data):
            raise self.fail(f"truncated data while reading {what} (needs {n} bytes at offset {self.pos}, "
                            f"{len(self.data) - self.pos} left)")
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def scalar(self, fmt: str, what: str) -> int:
        return struct.unpack("<" + fmt, self.take(struct.calcsize(fmt), what))[0]

    def array(self, dtype: str, count: int, cols: int, what: str) -> np.ndarray:
        dt = np.dtype(dtype).newbyteorder("<")
        raw = self.take(count * cols * dt.itemsize, what)
        return np.frombuffer(raw, dt).reshape(count, cols)

    def cstring(self, what: str) -> str:
        end = self.data.find(b"\0", self.pos)
        if end < 0:
            raise self.fail(f"truncated data while reading {what} (no terminating null byte)")
        raw = self.data[self.pos:end]
        self.pos = end + 1
        return raw.decode("utf-8", errors="replace")


def _shape_offset(f, size: int, version: int, shape_index: int, fail) -> int:
    """The byte offset of shape ``shape_index`` from the end-of-file dictionary."""
    if size < 4:
        raise fail("truncated file (no end-of-file shape dictionary)")
    f.seek(size - 4)
    (count,) = struct.unpack("<I", f.read(4))
    if shape_index >= count:
        raise fail(f"shape index {shape_index} is out of range (the file holds {count} shape"
                   f"{'s' if count != 1 else ''}: 0..{count - 1})")
    width = 8 if version == 4 else 4
    start = size - 4 - width * (count - shape_index)
    if start < 0:
        raise fail(f"corrupt end-of-file dictionary ({count} shapes do not fit in {size} bytes)")
    f.seek(start)
    (offset,) = struct.unpack("<Q" if width == 8 else "<I", f.read(width))
    if offset + 4 > size:
        raise fail(f"corrupt end-of-file dictionary (offset {offset} beyond the file's {size} bytes)")
    return offset


def _inflate(f, fail) -> bytes:
    """Decompress one zlib stream from the current file position (stops at its end)."""
    d = zlib.decompressobj()
    parts = []
    try:
        while not d.eof:
            chunk = f.read(_CHUNK)
            if not chunk:
                break
            parts.append(d.decompress(chunk))
    except zlib.error as exc:
        raise fail(f"corrupt compressed data ({exc})") from None
    if not d.eof:
        raise fail("truncated data (the compressed stream ends early)")
    return b"".join(parts)


def read_serialized(path: str | os.PathLike, shape_index: int = 0) -> MeshData:
    """Shape ``shape_index`` of a Mitsuba ``.serialized`` file as :class:`~pyclpt.scene.mesh_io.MeshData`.

    Raises :class:`~pyclpt.scene.mesh_io.MeshLoadError` (a ValueError) naming the file and shape for a
    bad header, an out-of-range shape index, truncated or corrupt data; OSError if the file cannot
    be read.
    """
    path = Path(path)
    shape_index = int(shape_index)

    def fail(msg: str) -> MeshLoadError:
        return MeshLoadError(f"{path} (shape {shape_index}): {msg}")

    if shape_index < 0:
        raise fail("the shape index must be >= 0")
    with open(path, "rb") as f:
        size = f.seek(0, os.SEEK_END)
        f.seek(0)
        _, version = _header(f.read(4), fail)
        if shape_index != 0:
            offset = _shape_offset(f, size, version, shape_index, fail)
            f.seek(offset)
            _, shape_version = _header(f.read(4), fail)
            if shape_version != version:
                raise fail(f"shape has file version {shape_version}, the file {version}")
        data = _inflate(f, fail)
    return _decode(_Reader(data, fail), version, fail)


def _header(raw: bytes, fail) -> tuple[int, int]:
    if len(raw) < 4:
        raise fail("truncated file (no header)")
    magic, version = struct.unpack("<HH", raw)
    if magic != MAGIC:
        raise fail(f"not a Mitsuba .serialized file (magic 0x{magic:04X}, expected 0x{MAGIC:04X})")
    if version not in VERSIONS:
        raise fail(f"unsupported .serialized version {version} (3 or 4)")
    return magic, version


def _decode(r: _Reader, version: int, fail) -> MeshData:
    flags = r.scalar("I", "flags")
    if version == 4:
        r.cstring("the shape name")
    nv = r.scalar("Q", "the vertex count")
    nt = r.scalar("Q", "the triangle count")
    if flags & DOUBLE_PRECISION and flags & SINGLE_PRECISION:
        raise fail(f"flags 0x{flags:04X} ask for both single and double precision")
    real = "f8" if flags & DOUBLE_PRECISION else "f4"
    positions = r.array(real, nv, 3, "positions")
    normals = r.array(real, nv, 3, "normals") if flags & HAS_NORMALS else None
    uvs = r.array(real, nv, 2, "uvs") if flags & HAS_UVS else None
    if flags & HAS_COLORS:
        r.array(real, nv, 3, "vertex colors")
    indices = r.array("u8" if nv > 0xFFFFFFFF else "u4", nt, 3, "triangle indices")
    if nt and int(indices.max()) >= nv:
        raise fail(f"triangle index {int(indices.max())} out of range for {nv} vertices")
    if nv > np.iinfo(np.int32).max:
        raise fail(f"{nv} vertices are more than pyclpt's 32-bit indices address")
    if flags & FACE_NORMALS:
        normals = None
    try:
        return MeshData(positions, indices.astype(np.int32), normals, uvs,
                        np.zeros(nt, np.int32), ("",))
    except ValueError as exc:
        raise fail(str(exc)) from None
