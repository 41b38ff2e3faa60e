"""Triangle-mesh file loading: Wavefront OBJ and PLY (ASCII or binary), optionally gzipped.

``load_mesh(path)`` returns a :class:`MeshData` holding one triangle mesh:
positions, triangle indices, and -- only when the file stores them -- per-vertex
shading normals and texture coordinates, plus a per-triangle material id for
OBJ ``usemtl`` groups.

Parsing is done by ``trimesh`` (its ``exchange`` level loaders, which hand back
plain arrays, so no normals are computed behind our back). Around it this
module:

* decompresses ``.gz`` files in memory and picks the format from the name;
* keeps vertex order and face order as in the file (OBJ vertices that carry
  several ``vt``/``vn`` combinations are split, never merged; vertices no
  face uses may be dropped), and fan-triangulates quads and polygons so the
  triangles of face *i* come right after those of face *i - 1*, all with the
  file's winding;
* records OBJ ``usemtl`` names itself (the MTL file is never read, so a missing
  one is not an error) and returns ONE mesh with ``material_ids``;
* resolves OBJ negative (relative) indices by the line they appear on;
* reads the common simple ASCII PLY layout (one ``vertex`` and one ``face``
  element, all faces the same size) with a vectorised fast path, because
  trimesh parses ASCII PLY line by line (about 7 s for the 871k-triangle
  Stanford dragon against about 1 s here); anything else goes to trimesh;
* validates the result (indices in range, finite values, at least one
  triangle) and turns every library failure into :class:`MeshLoadError`
  naming the file;
* caches parsed meshes as ``.npz`` files (``cache_path("mesh", key)``), keyed by the
  file's bytes, the format and the loader/trimesh versions.
"""
from __future__ import annotations

import errno
import functools
import gzip
import importlib.metadata
import io
import logging
import os
import re
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pyclpt.common.cache import cache_path, content_key, save_npz

__all__ = ["LOADER_VERSION", "MeshData", "MeshLoadError", "load_mesh"]

log = logging.getLogger(__name__)

#: Bump whenever parsing or validation changes: it is part of the cache key.
LOADER_VERSION = "mesh_io-1"

_INT32_MAX = np.iinfo(np.int32).max


class MeshLoadError(ValueError):
    """A mesh file could not be read: corrupt, unsupported, empty or inconsistent.

    The message always names the file.
    """


@dataclass(frozen=True)
class MeshData:
    """One triangle mesh, as loaded from a file.

    Arrays are coerced to the documented dtypes and checked for shape on
    construction (indices and ranges are checked by the loader).
    """

    positions: np.ndarray  #: (V, 3) float32
    indices: np.ndarray  #: (T, 3) int32, triangles, winding as in the file
    normals: np.ndarray | None  #: (V, 3) float32 per-vertex shading normals, None if the file has none
    uvs: np.ndarray | None  #: (V, 2) float32 texture coordinates, None if the file has none
    material_ids: np.ndarray  #: (T,) int32 index into material_names
    material_names: tuple[str, ...]  #: OBJ ``usemtl`` names, in order of first use; ("",) if none

    def __post_init__(self) -> None:
        def coerce(field: str, dtype: type, cols: int | None) -> None:
            arr = getattr(self, field)
            if arr is None:
                return
            arr = np.ascontiguousarray(arr, dtype=dtype)
            want = (-1, cols) if cols else (-1,)
            if arr.ndim != len(want) or (cols and arr.shape[1] != cols):
                raise ValueError(f"MeshData.{field} must have shape {want}, got {arr.shape}")
            object.__setattr__(self, field, arr)

        coerce("positions", np.float32, 3)
        coerce("indices", np.int32, 3)
        coerce("normals", np.float32, 3)
        coerce("uvs", np.float32, 2)
        coerce("material_ids", np.int32, None)
        object.__setattr__(self, "material_names", tuple(str(n) for n in self.material_names))
        nv, nt = len(self.positions), len(self.indices)
        for field in ("normals", "uvs"):
            arr = getattr(self, field)
            if arr is not None and len(arr) != nv:
                raise ValueError(f"MeshData.{field} has {len(arr)} rows for {nv} vertices")
        if len(self.material_ids) != nt:
            raise ValueError(f"MeshData.material_ids has {len(self.material_ids)} entries for {nt} triangles")
        if not self.material_names:
            raise ValueError("MeshData.material_names must not be empty (use ('',))")

    @property
    def num_vertices(self) -> int:
        return len(self.positions)

    @property
    def num_triangles(self) -> int:
        return len(self.indices)


# --------------------------------------------------------------------------- public entry


def load_mesh(path: str | os.PathLike) -> MeshData:
    """Load an OBJ / PLY / ``.obj.gz`` / ``.ply.gz`` file as one triangle mesh.

    Raises ``FileNotFoundError`` if the file does not exist and
    :class:`MeshLoadError` (a ``ValueError``) if it cannot be read or parsed,
    has no triangles, or holds invalid data (out-of-range indices, NaN/inf).
    A second load of the same bytes is served from the on-disk cache.
    """
    p = Path(os.fspath(path))
    name = str(p)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise FileNotFoundError(errno.ENOENT, "mesh file not found", name) from None
    except OSError as exc:
        raise MeshLoadError(f"{name}: cannot read mesh file: {exc}") from exc

    fmt, compressed = _detect_format(p, raw)
    key = content_key(raw, LOADER_VERSION, fmt, _trimesh_version())
    mesh = _cache_read(key, name)
    if mesh is not None:
        return mesh
    data = _gunzip(raw, name) if compressed else raw
    mesh = _parse(data, fmt, name)
    _cache_write(key, mesh)
    return mesh


@functools.lru_cache(maxsize=1)
def _trimesh_version() -> str:
    """trimesh's version without importing it (that takes ~0.5 s, and a cache hit needs no trimesh)."""
    try:
        return importlib.metadata.version("trimesh")
    except importlib.metadata.PackageNotFoundError:
        import trimesh

        return str(trimesh.__version__)


def _detect_format(p: Path, raw: bytes) -> tuple[str, bool]:
    lower = p.name.lower()
    compressed = lower.endswith(".gz") or raw[:2] == b"\x1f\x8b"
    if lower.endswith(".gz"):
        lower = lower[:-3]
    for ext in ("obj", "ply"):
        if lower.endswith("." + ext):
            return ext, compressed
    raise MeshLoadError(f"{p}: unsupported mesh format (expected .obj or .ply, optionally .gz)")


def _gunzip(raw: bytes, name: str) -> bytes:
    try:
        return gzip.decompress(raw)
    except (OSError, EOFError, zlib.error) as exc:
        raise MeshLoadError(f"{name}: not a valid gzip file: {exc}") from exc


def _parse(data: bytes, fmt: str, name: str) -> MeshData:
    """Parse decompressed file bytes (``fmt`` is "obj" or "ply") and validate the result."""
    if fmt == "obj":
        arrays = _parse_obj(data, name)
    else:
        arrays = _parse_ply(data, name)
    return _validated(name, **arrays)


# --------------------------------------------------------------------------- cache


def _cache_read(key: str, name: str) -> MeshData | None:
    try:
        path = cache_path("mesh", key)
        if path is None or not path.exists():
            return None
        with np.load(path, allow_pickle=False) as f:
            return MeshData(
                positions=f["positions"],
                indices=f["indices"],
                normals=f["normals"] if "normals" in f.files else None,
                uvs=f["uvs"] if "uvs" in f.files else None,
                material_ids=f["material_ids"],
                material_names=tuple(str(s) for s in f["material_names"]),
            )
    except Exception as exc:  # a damaged or foreign cache entry is only a miss
        log.warning("ignoring unreadable mesh cache entry for %s: %s", name, " ".join(str(exc).split()))
        return None


def _cache_write(key: str, mesh: MeshData) -> None:
    arrays = {
        "positions": mesh.positions,
        "indices": mesh.indices,
        "material_ids": mesh.material_ids,
        "material_names": np.array(mesh.material_names, dtype=str),
    }
    if mesh.normals is not None:
        arrays["normals"] = mesh.normals
    if mesh.uvs is not None:
        arrays["uvs"] = mesh.uvs
    try:
        path = cache_path("mesh", key)
        if path is not None:  # None: the cache folder cannot be used (warned once)
            save_npz(path, **arrays)
    except OSError as exc:  # read-only or full disk: loading still works, just uncached
        log.warning("could not write mesh cache: %s", " ".join(str(exc).split()))


# --------------------------------------------------------------------------- validation


def _validated(
    name: str,
    positions: np.ndarray,
    faces: np.ndarray,
    normals: np.ndarray | None = None,
    uvs: np.ndarray | None = None,
    material_ids: np.ndarray | None = None,
    material_names: tuple[str, ...] = ("",),
) -> MeshData:
    """Check everything that the file could get wrong, with messages naming the file."""
    positions = np.asarray(positions)
    faces = np.asarray(faces)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise MeshLoadError(f"{name}: vertex positions have shape {positions.shape}, expected (V, 3)")
    nv = len(positions)
    if faces.size == 0:
        raise MeshLoadError(f"{name}: the file contains no triangles")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise MeshLoadError(f"{name}: triangle array has shape {faces.shape}, expected (T, 3)")
    if nv > _INT32_MAX:
        raise MeshLoadError(f"{name}: {nv} vertices do not fit 32-bit indices")
    bad = np.flatnonzero(((faces < 0) | (faces >= nv)).any(axis=1))
    if len(bad):
        t = int(bad[0])
        row = faces[t]
        v = int(row[(row < 0) | (row >= nv)][0])
        raise MeshLoadError(
            f"{name}: triangle {t} references vertex {v} but the file has {nv} vertices"
            + (f" ({len(bad)} triangles are out of range)" if len(bad) > 1 else "")
        )
    positions = positions.astype(np.float32)
    _check_finite(name, "position", positions)
    if normals is not None:
        normals = np.asarray(normals, dtype=np.float32)
        if normals.shape != (nv, 3):
            raise MeshLoadError(f"{name}: {len(normals)} normals for {nv} vertices")
        _check_finite(name, "normal", normals)
    if uvs is not None:
        uvs = np.asarray(uvs, dtype=np.float32)
        if uvs.shape != (nv, 2):
            raise MeshLoadError(f"{name}: texture coordinates have shape {uvs.shape}, expected ({nv}, 2)")
        _check_finite(name, "texture coordinate", uvs)
    if material_ids is None:
        material_ids = np.zeros(len(faces), dtype=np.int32)
    if len(material_ids) != len(faces):
        raise MeshLoadError(
            f"{name}: internal error: {len(material_ids)} material ids for {len(faces)} triangles"
        )
    return MeshData(
        positions=positions,
        indices=faces.astype(np.int32),
        normals=normals,
        uvs=uvs,
        material_ids=material_ids,
        material_names=tuple(material_names),
    )


def _check_finite(name: str, what: str, arr: np.ndarray) -> None:
    bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
    if len(bad):
        i = int(bad[0])
        values = ", ".join(f"{x:g}" for x in arr[i])
        raise MeshLoadError(
            f"{name}: vertex {i} has a non-finite {what} ({values})"
            + (f"; {len(bad)} vertices are affected" if len(bad) > 1 else "")
        )


def _fan(faces: np.ndarray) -> np.ndarray:
    """(N, k) polygons -> (N*(k-2), 3) triangles; polygon i's triangles stay together, in order."""
    k = faces.shape[1]
    if k == 3:
        return faces
    tris = np.stack([faces[:, [0, j, j + 1]] for j in range(1, k - 1)], axis=1)
    return tris.reshape(-1, 3)


def _fan_ragged(name: str, polys: object) -> np.ndarray:
    """Fan-triangulate polygons of different sizes, keeping file order (polygon i's triangles together)."""
    polys = [np.asarray(p, dtype=np.int64).reshape(-1) for p in polys]  # type: ignore[union-attr]
    lengths = np.array([len(p) for p in polys], dtype=np.int64)
    short = np.flatnonzero(lengths < 3)
    if len(short):
        raise MeshLoadError(f"{name}: face {int(short[0])} has only {int(lengths[short[0]])} vertices")
    flat = np.concatenate(polys)
    ntri = lengths - 2
    starts = np.repeat(np.cumsum(lengths) - lengths, ntri)
    j = np.arange(int(ntri.sum())) - np.repeat(np.cumsum(ntri) - ntri, ntri) + 1
    return flat[np.stack([starts, starts + j, starts + j + 1], axis=1)]


# --------------------------------------------------------------------------- OBJ

# The normalised text starts with "\n" so that "\n<keyword> " finds every line, the first too;
# patterns with a literal "\n" prefix are much faster in Python's re than "^" with re.M.
_RE_FACE_LINES = re.compile(r"\nf ([^\n]*)")
_RE_FACE_OR_MTL = re.compile(r"\n(usemtl\b|f )([^\n]*)")
_RE_ZERO_INDEX = re.compile(r"[ /\n]0(?![\d.])")  # an index "0", searched in "\n" + face lines
_RE_VT_REF = re.compile(r"\d/-?\d")  # "v/vt" in a face corner
_RE_VN_REF = re.compile(r"/-?\d*/-?\d")  # "v//vn" or "v/vt/vn"


def _normalize_obj_text(text: str) -> str:
    """Uniform line endings and spacing so trimesh and our own scans see the same lines.

    The result starts with "\n", so line k of the file is element k of ``text.split("\n")``
    (apart from lines joined by ``\\`` continuations). Comments are removed.
    """
    text = "\n" + text.replace("\r\n", "\n").replace("\r", "\n").replace("\\\n", "").replace("\t", " ")
    if "\n " in text:
        text = re.sub(r"\n +", "\n", text)
    if "#" in text:
        # a '#' at a line start or after a space starts a comment; 'mat#1' stays a name
        text = re.sub(r"(?<![^ \n])#[^\n]*", "", text)
    return text


def _obj_counts(text: str) -> tuple[int, int, int]:
    return text.count("\nv "), text.count("\nvt "), text.count("\nvn ")


def _obj_materials(text: str, tris_per_face: np.ndarray) -> tuple[np.ndarray | None, tuple[str, ...]]:
    """Per-triangle material ids from the order of ``usemtl`` and ``f`` lines (None without usemtl)."""
    if "\nusemtl" not in text:
        return None, ("",)
    names: dict[str, int] = {}
    current = -1  # faces before the first usemtl get the unnamed material ""
    face_mat: list[int] = []
    for m in _RE_FACE_OR_MTL.finditer(text):
        if m.group(1) != "f ":
            current = names.setdefault(m.group(2).strip(), len(names))
            continue
        if current < 0:
            current = names.setdefault("", len(names))
        face_mat.append(current)
    if len(face_mat) != len(tris_per_face):
        raise AssertionError("face scan mismatch")
    ids = np.repeat(np.asarray(face_mat, dtype=np.int32), tris_per_face)
    return ids, (tuple(names) if names else ("",))


def _resolve_negative_indices(text: str, name: str) -> str:
    """Rewrite OBJ relative indices (-1 = latest vertex so far) as absolute ones."""
    out = []
    counts = [0, 0, 0]  # v, vt, vn defined so far
    kinds = ("vertex", "texture coordinate", "normal")
    for lineno, line in enumerate(text.split("\n")):
        if line.startswith("v "):
            counts[0] += 1
        elif line.startswith("vt "):
            counts[1] += 1
        elif line.startswith("vn "):
            counts[2] += 1
        elif line.startswith("f ") and "-" in line:
            corners = []
            for tok in line[2:].split():
                parts = tok.split("/")
                for i, part in enumerate(parts[:3]):
                    if part.startswith("-"):
                        try:
                            idx = counts[i] + int(part) + 1
                        except ValueError:
                            raise MeshLoadError(f"{name}: line {lineno}: malformed face index {tok!r}") from None
                        if idx < 1:
                            raise MeshLoadError(
                                f"{name}: line {lineno}: relative {kinds[i]} index {part} reaches before "
                                f"the first {kinds[i]} ({counts[i]} defined so far)"
                            )
                        parts[i] = str(idx)
                corners.append("/".join(parts))
            line = "f " + " ".join(corners)
        out.append(line)
    return "\n".join(out)


def _diagnose_obj(text: str, name: str) -> None:
    """Slow scan used only when something is off: raise a precise error for the first bad line."""
    totals = _obj_counts(text)
    kinds = ("vertex", "texture coordinate", "normal")
    plural = ("vertices", "texture coordinates", "normals")
    for lineno, line in enumerate(text.split("\n")):
        if line.startswith(("v ", "vt ", "vn ")):
            try:
                [float(x) for x in line.split()[1:]]
            except ValueError:
                raise MeshLoadError(f"{name}: line {lineno}: malformed vertex data {line!r}") from None
            continue
        if not line.startswith("f "):
            continue
        toks = line[2:].split()
        if len(toks) < 3:
            raise MeshLoadError(f"{name}: line {lineno}: face with fewer than 3 vertices: {line!r}")
        for tok in toks:
            for i, part in enumerate(tok.split("/")[:3]):
                if part == "" and i > 0:
                    continue
                try:
                    idx = int(part)
                except ValueError:
                    raise MeshLoadError(f"{name}: line {lineno}: malformed face index {tok!r}") from None
                if idx == 0:
                    raise MeshLoadError(f"{name}: line {lineno}: face index 0 is invalid (OBJ indices start at 1)")
                if idx > totals[i]:
                    raise MeshLoadError(
                        f"{name}: line {lineno}: face references {kinds[i]} {idx} "
                        f"but the file has {totals[i]} {plural[i]}"
                    )


def _parse_obj(data: bytes, name: str) -> dict:
    from trimesh.exchange.obj import load_obj

    text = _normalize_obj_text(data.decode("utf-8", errors="replace"))

    face_lines = _RE_FACE_LINES.findall(text)
    corners = np.fromiter((len(f.split()) for f in face_lines), dtype=np.int64, count=len(face_lines))
    face_text = "\n".join(face_lines)
    if (corners < 3).any() or _RE_ZERO_INDEX.search("\n" + face_text):
        _diagnose_obj(text, name)
    if "-" in face_text:
        text = _resolve_negative_indices(text, name)
    tris_per_face = corners - 2
    expected_tris = int(tris_per_face.sum())

    material_ids, material_names = _obj_materials(text, tris_per_face)
    # trimesh splits the mesh at every usemtl (and names the pieces after the MTL's contents,
    # which we do not load); we tracked materials ourselves, so hide them from it.
    if material_ids is not None:
        text = re.sub(r"\nusemtl\b[^\n]*", "\n", text)

    try:
        kw = load_obj(
            io.StringIO(text),
            group_material=False,
            skip_materials=True,
            # maintain_order=True would give each position the median of its vt/vn indices,
            # i.e. wrong UVs/normals along seams and hard edges; False splits such vertices
            # (never merges) and keeps vertices sorted by their index in the file.
            maintain_order=False,
        )
    except Exception as exc:
        _diagnose_obj(text, name)
        raise MeshLoadError(f"{name}: could not parse OBJ: {type(exc).__name__}: {exc}") from exc

    geometry = kw.get("geometry") or {}
    if not geometry or expected_tris == 0:
        raise MeshLoadError(f"{name}: the file contains no triangles")
    if len(geometry) != 1:
        raise MeshLoadError(f"{name}: internal error: trimesh returned {len(geometry)} pieces, expected 1")
    g = next(iter(geometry.values()))

    faces = np.asarray(g["faces"])
    positions = np.asarray(g["vertices"])
    normals = g.get("vertex_normals")
    visual = g.get("visual")
    uvs = getattr(visual, "uv", None) if visual is not None else None

    # trimesh drops UVs / normals it cannot index (inside a bare except) or that only some faces
    # have; bad indices are an error, a partial attribute is dropped with a warning
    for missing, pattern, what in ((uvs is None, _RE_VT_REF, "texture coordinates (vt)"),
                                   (normals is None, _RE_VN_REF, "normals (vn)")):
        if missing and pattern.search(face_text):
            _diagnose_obj(text, name)
            log.warning("%s: some faces have %s and others do not; loading the mesh without them", name, what)

    if faces.ndim == 2 and faces.shape[1] > 3:
        faces = _fan(faces)
    if len(faces) != expected_tris:
        _diagnose_obj(text, name)
        raise MeshLoadError(
            f"{name}: internal error: parsed {len(faces)} triangles but the face lines describe {expected_tris}"
        )
    return dict(
        positions=positions,
        faces=faces,
        normals=normals,
        uvs=uvs,
        material_ids=material_ids,
        material_names=material_names,
    )


# --------------------------------------------------------------------------- PLY

_UV_NAMES = (("texture_u", "texture_v"), ("u", "v"), ("s", "t"))
_FACE_INDEX_NAMES = ("vertex_indices", "vertex_index")


def _ply_header(data: bytes) -> tuple[str, list[tuple[str, int, list[tuple[str, bool]]]], int] | None:
    """(format, [(element, count, [(property, is_list)])], body offset), or None if unusual."""
    end = data.find(b"end_header", 0, 1 << 16)
    if not data.startswith(b"ply") or end < 0:
        return None
    nl = data.find(b"\n", end)
    if nl < 0:
        return None
    fmt = ""
    elements: list[tuple[str, int, list[tuple[str, bool]]]] = []
    for line in data[:end].decode("ascii", errors="replace").splitlines()[1:]:
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] == "format" and len(tok) >= 2:
            fmt = tok[1]
        elif tok[0] == "element" and len(tok) == 3 and tok[2].isdigit():
            elements.append((tok[1], int(tok[2]), []))
        elif tok[0] == "property" and elements and len(tok) >= 3:
            elements[-1][2].append((tok[-1], tok[1] == "list"))
        else:
            return None
    return fmt, elements, nl + 1


def _fromstring(text: bytes, dtype: type) -> np.ndarray | None:
    """Whitespace-separated numbers; None if something else is in the way."""
    with warnings.catch_warnings():  # numpy < 2.3 warns and returns a short array instead of raising
        warnings.simplefilter("ignore", DeprecationWarning)
        try:
            return np.fromstring(text, sep=" ", dtype=dtype)
        except ValueError:
            return None


def _ply_ascii_fast(data: bytes) -> tuple[dict[str, np.ndarray], np.ndarray] | None:
    """Vectorised read of the common ASCII layout; None whenever anything differs from it."""
    header = _ply_header(data)
    if header is None:
        return None
    fmt, elements, offset = header
    if fmt != "ascii" or [e[0] for e in elements] != ["vertex", "face"]:
        return None
    (_, nv, vprops), (_, nf, fprops) = elements
    if nv == 0 or nf == 0 or any(is_list for _, is_list in vprops):
        return None
    if len(fprops) != 1 or not fprops[0][1] or fprops[0][0] not in _FACE_INDEX_NAMES:
        return None
    body = data[offset:]
    newlines = np.flatnonzero(np.frombuffer(body, dtype=np.uint8) == 10)
    if len(newlines) < nv:
        return None
    cut = int(newlines[nv - 1]) + 1
    verts = _fromstring(body[:cut], np.float64)
    if verts is None or verts.size != nv * len(vprops):
        return None
    verts = verts.reshape(nv, len(vprops))
    flat = _fromstring(body[cut:], np.int64)
    if flat is None or flat.size == 0:
        return None
    k = int(flat[0])
    if k < 3 or flat.size != nf * (k + 1):
        return None
    table = flat.reshape(nf, k + 1)
    if (table[:, 0] != k).any():
        return None
    columns = {pname: verts[:, i] for i, (pname, _) in enumerate(vprops)}
    return columns, table[:, 1:]


def _column(data: object, key: str, n: int) -> np.ndarray | None:
    try:
        col = np.asarray(data[key])  # type: ignore[index]
    except (KeyError, ValueError, IndexError, TypeError):
        return None
    if col.dtype == object or col.size != n:
        return None
    return col.reshape(n)


def _rows(data: object) -> int:
    if isinstance(data, dict):
        return len(next(iter(data.values()))) if data else 0
    return 0 if data is None else len(data)  # type: ignore[arg-type]


def _ply_via_trimesh(data: bytes, name: str) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray | None]:
    from trimesh.exchange.ply import load_ply

    if not data.startswith(b"ply"):
        raise MeshLoadError(f"{name}: not a PLY file (it does not start with 'ply')")
    try:
        kw = load_ply(io.BytesIO(data), fix_texture=False, skip_materials=True)
    except Exception as exc:
        hint = ""
        if "unexpected length" in str(exc):
            hint = (
                " (truncated or corrupt file, or a binary PLY whose faces are not all the same size,"
                " which trimesh cannot read)"
            )
        elif "could not be read to its end" in str(exc):
            hint = " (non-numeric data where numbers were expected)"
        raise MeshLoadError(f"{name}: could not parse PLY: {type(exc).__name__}: {exc}{hint}") from exc

    raw = kw.get("metadata", {}).get("_ply_raw", {})
    vert = raw.get("vertex")
    if not vert or not vert.get("length"):
        raise MeshLoadError(f"{name}: the file contains no vertices")
    nv = int(vert["length"])
    vdata = vert.get("data")
    if _rows(vdata) != nv:
        raise MeshLoadError(f"{name}: the header declares {nv} vertices but the file holds {_rows(vdata)}")
    columns = {}
    for pname in vert["properties"]:
        col = _column(vdata, pname, nv)
        if col is not None:
            columns[pname] = col

    face = raw.get("face")
    if not face or not face.get("length") or kw.get("faces") is None:
        raise MeshLoadError(f"{name}: the file contains no triangles")
    nf = int(face["length"])
    fdata = face.get("data")
    if _rows(fdata) != nf:
        raise MeshLoadError(f"{name}: the header declares {nf} faces but the file holds {_rows(fdata)}")
    faces = np.asarray(kw["faces"])
    if faces.dtype == object or faces.ndim != 2 or len(faces) != nf:
        # faces of different sizes: trimesh triangulated them grouped by size; redo it in file order
        polys = None
        if isinstance(fdata, dict):
            polys = next((fdata[k] for k in _FACE_INDEX_NAMES if k in fdata), None)
        if polys is None:
            raise MeshLoadError(f"{name}: could not read the face vertex lists")
        faces = _fan_ragged(name, polys)
    elif faces.shape[1] > 3:
        faces = _fan(faces)

    texcoord = None
    if "texcoord" in face["properties"]:
        fdata = face["data"]
        try:
            texcoord = np.asarray(fdata["texcoord"]["f1"] if not isinstance(fdata, dict) else fdata["texcoord"])
        except Exception:
            texcoord = None
        if texcoord is None or texcoord.dtype == object or texcoord.shape != (nf, 6) or len(faces) != nf:
            log.warning("%s: per-face texcoords are only supported on triangle meshes; UVs ignored", name)
            texcoord = None
    return columns, faces, texcoord


def _parse_ply(data: bytes, name: str, fast: bool = True) -> dict:
    fast_result = _ply_ascii_fast(data) if fast else None
    texcoord = None
    if fast_result is not None:
        columns, faces = fast_result
        if faces.shape[1] != 3:
            faces = _fan(faces)
    else:
        columns, faces, texcoord = _ply_via_trimesh(data, name)

    if not all(c in columns for c in "xyz"):
        raise MeshLoadError(f"{name}: vertices lack x/y/z properties")
    positions = np.column_stack([columns[c] for c in "xyz"])
    normals = None
    if all(c in columns for c in ("nx", "ny", "nz")):
        normals = np.column_stack([columns[c] for c in ("nx", "ny", "nz")])
    uvs = None
    for u, v in _UV_NAMES:
        if u in columns and v in columns:
            uvs = np.column_stack([columns[u], columns[v]])
            break

    if texcoord is not None:
        # UVs stored per face corner: split vertices whose corners disagree (like trimesh's fix_texture,
        # but keeping normals in step with positions).
        from trimesh.grouping import unique_rows
        from trimesh.visual.texture import unmerge_faces

        if ((faces < 0) | (faces >= len(positions))).any():
            _validated(name, positions, faces)  # raises the out-of-range message
        corner_uv = texcoord.reshape(-1, 2)
        unique, inverse = unique_rows(corner_uv)
        faces, mask_v, mask_vt = unmerge_faces(faces, np.asarray(inverse).reshape(faces.shape))
        positions = positions[mask_v]
        if normals is not None:
            normals = normals[mask_v]
        uvs = corner_uv[unique][mask_vt]

    return dict(positions=positions, faces=faces, normals=normals, uvs=uvs)
