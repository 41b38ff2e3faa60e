"""Tests for pyclpt.scene.mesh_io: OBJ / PLY / gzip loading, validation, errors and the on-disk cache."""
from __future__ import annotations

import gzip
import logging
import os
from pathlib import Path

import numpy as np
import pytest

from pyclpt.scene import mesh_io
from pyclpt.scene.mesh_io import MeshData, MeshLoadError, load_mesh

REPO = Path(__file__).resolve().parents[1]
SCENES = Path(os.environ.get("PYCLPT_SCENES", REPO.parent / "shared" / "scenes"))


@pytest.fixture(autouse=True)
def _cache_in_tmp(tmp_path, monkeypatch):
    monkeypatch.setenv("PYCLPT_CACHE_DIR", str(tmp_path / "cache"))


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def tri_normals(mesh: MeshData) -> np.ndarray:
    p = mesh.positions[mesh.indices]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


def corner_positions(mesh: MeshData) -> list[list[tuple[float, ...]]]:
    return [[tuple(map(float, mesh.positions[i])) for i in tri] for tri in mesh.indices]


# ----------------------------------------------------------------------------- OBJ

QUADS_OBJ = """\
# two unit quads side by side in the z=0 plane, counter-clockwise seen from +z
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0
v 2 1 0
f 1 2 3 4
f 2 5 6 3
"""


def test_obj_quads_are_triangulated_in_order_with_consistent_winding(tmp_path):
    mesh = load_mesh(write(tmp_path / "quads.obj", QUADS_OBJ))
    assert mesh.positions.dtype == np.float32 and mesh.positions.shape == (6, 3)
    assert mesh.indices.dtype == np.int32 and mesh.indices.shape == (4, 3)
    # vertex order is the file's
    np.testing.assert_array_equal(mesh.positions[:, 0], [0, 1, 1, 0, 2, 2])
    # triangles 0,1 come from quad 0 and 2,3 from quad 1
    assert set(mesh.indices[:2].ravel()) == {0, 1, 2, 3}
    assert set(mesh.indices[2:].ravel()) == {1, 4, 5, 2}
    n = tri_normals(mesh)
    assert np.all(n[:, 2] > 0) and np.allclose(n[:, :2], 0)  # all keep the quads' winding
    np.testing.assert_allclose(np.abs(n[:, 2]).sum() / 2, 2.0)  # they cover both quads exactly
    assert mesh.normals is None and mesh.uvs is None
    assert mesh.material_names == ("",)
    np.testing.assert_array_equal(mesh.material_ids, 0)


def test_obj_mixed_polygons_keep_face_order(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\n" "f 1 2 3\nf 1 2 3 5 4\nf 1 3 4\n"
    mesh = load_mesh(write(tmp_path / "mixed.obj", text))
    assert len(mesh.indices) == 1 + 3 + 1
    np.testing.assert_array_equal(mesh.indices[0], [0, 1, 2])
    np.testing.assert_array_equal(mesh.indices[-1], [0, 2, 3])
    assert set(mesh.indices[1:4].ravel()) == {0, 1, 2, 3, 4}
    assert np.all(tri_normals(mesh)[:, 2] > 0)


TWO_MATERIALS_OBJ = """\
mtllib does_not_exist.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
o thing
usemtl red
f 1 2 3
f 1 3 4
usemtl blue
f 1 2 3 4
usemtl red
f 2 3 4
"""


def test_obj_materials_one_mesh_with_ids_and_missing_mtl(tmp_path):
    mesh = load_mesh(write(tmp_path / "mats.obj", TWO_MATERIALS_OBJ))
    assert mesh.material_names == ("red", "blue")
    np.testing.assert_array_equal(mesh.material_ids, [0, 0, 1, 1, 0])
    assert mesh.material_ids.dtype == np.int32
    assert len(mesh.positions) == 4  # one mesh, vertices not duplicated per material
    np.testing.assert_array_equal(mesh.indices[0], [0, 1, 2])
    np.testing.assert_array_equal(mesh.indices[1], [0, 2, 3])
    np.testing.assert_array_equal(mesh.indices[4], [1, 2, 3])


def test_obj_faces_before_first_usemtl_get_unnamed_material(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nusemtl gold\nf 3 2 1\n"
    mesh = load_mesh(write(tmp_path / "pre.obj", text))
    assert mesh.material_names == ("", "gold")
    np.testing.assert_array_equal(mesh.material_ids, [0, 1])


NORMALS_UVS_OBJ = """\
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vt 0.5 0.5
vn 0 0 1
vn 0 0 -1
f 1/1/1 2/2/1 3/3/1
f 1/5/2 3/3/1 4/4/1
"""


def test_obj_normals_and_uvs(tmp_path):
    mesh = load_mesh(write(tmp_path / "nuv.obj", NORMALS_UVS_OBJ))
    assert mesh.normals is not None and mesh.uvs is not None
    assert mesh.normals.dtype == np.float32 and mesh.uvs.dtype == np.float32
    assert mesh.normals.shape == (len(mesh.positions), 3)
    assert mesh.uvs.shape == (len(mesh.positions), 2)
    # vertex 1 is used with two different (vt, vn) pairs, so it is split, never merged
    assert len(mesh.positions) == 5
    corners = mesh.indices
    expected_pos = [[(0, 0, 0), (1, 0, 0), (1, 1, 0)], [(0, 0, 0), (1, 1, 0), (0, 1, 0)]]
    assert corner_positions(mesh) == expected_pos
    np.testing.assert_allclose(mesh.uvs[corners], [[[0, 0], [1, 0], [1, 1]], [[0.5, 0.5], [1, 1], [0, 1]]])
    np.testing.assert_allclose(mesh.normals[corners][:, :, 2], [[1, 1, 1], [-1, 1, 1]])


def test_obj_without_vn_has_no_normals(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n"
    mesh = load_mesh(write(tmp_path / "uvonly.obj", text))
    assert mesh.normals is None  # trimesh's computed normals must not leak in
    np.testing.assert_allclose(mesh.uvs[mesh.indices[0]], [[0, 0], [1, 0], [0, 1]])


def test_obj_normals_only(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n"
    mesh = load_mesh(write(tmp_path / "nonly.obj", text))
    assert mesh.uvs is None
    np.testing.assert_allclose(mesh.normals, [[0, 0, 1]] * 3)


def test_obj_negative_indices_are_relative_to_their_line(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 5 0 0\nv 5 1 0\nf -4 -2 -1\n"
    mesh = load_mesh(write(tmp_path / "neg.obj", text))
    np.testing.assert_array_equal(mesh.indices, [[0, 1, 2], [1, 3, 4]])


def test_obj_crlf_tabs_and_comments(tmp_path):
    text = "# header\r\nv\t0 0 0\r\n  v 1 0 0  # trailing\r\nv 0 1 0\r\nusemtl mat#1\r\nf 1 2 3 # c\r\n"
    mesh = load_mesh(write(tmp_path / "crlf.obj", text))
    assert len(mesh.indices) == 1 and len(mesh.positions) == 3
    assert mesh.material_names == ("mat#1",)


def test_obj_gz(tmp_path):
    path = tmp_path / "quads.obj.gz"
    path.write_bytes(gzip.compress(QUADS_OBJ.encode()))
    assert len(load_mesh(path).indices) == 4


# ----------------------------------------------------------------------------- PLY

ASCII_PLY = """\
ply
format ascii 1.0
comment a quad and a triangle as two same-size faces each
element vertex 4
property float x
property float y
property float z
property float nx
property float ny
property float nz
property float u
property float v
element face 2
property list uchar int vertex_indices
end_header
0 0 0 0 0 1 0 0
1 0 0 0 0 1 1 0
1 1 0 0 0 1 1 1
0 1 0 0 0 1 0 1
3 0 1 2
3 0 2 3
"""


def test_ascii_ply(tmp_path):
    mesh = load_mesh(write(tmp_path / "a.ply", ASCII_PLY))
    np.testing.assert_array_equal(mesh.indices, [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_array_equal(mesh.positions[2], [1, 1, 0])
    np.testing.assert_array_equal(mesh.normals, [[0, 0, 1]] * 4)
    np.testing.assert_array_equal(mesh.uvs, [[0, 0], [1, 0], [1, 1], [0, 1]])
    assert mesh.material_names == ("",)


def test_ascii_ply_without_normals(tmp_path):
    text = ASCII_PLY.replace("property float nx\nproperty float ny\nproperty float nz\n", "").replace(
        " 0 0 1 ", " "
    )
    mesh = load_mesh(write(tmp_path / "nn.ply", text))
    assert mesh.normals is None
    assert mesh.uvs is not None


def test_ascii_ply_fast_path_matches_trimesh(tmp_path):
    rng = np.random.default_rng(1)
    pos = rng.normal(size=(50, 3))
    nrm = rng.normal(size=(50, 3))
    st = rng.random((50, 2))
    quads = rng.integers(0, 50, size=(40, 4))
    lines = [
        "ply", "format ascii 1.0", "element vertex 50",
        *[f"property float {p}" for p in ("x", "y", "z", "nx", "ny", "nz", "s", "t")],
        "element face 40", "property list uchar int vertex_indices", "end_header",
    ]
    lines += [" ".join(f"{x:.6g}" for x in row) for row in np.hstack([pos, nrm, st])]
    lines += ["4 " + " ".join(map(str, q)) for q in quads]
    data = ("\n".join(lines) + "\n").encode()
    assert mesh_io._ply_ascii_fast(data) is not None
    fast = mesh_io._validated("x", **mesh_io._parse_ply(data, "x", fast=True))
    slow = mesh_io._validated("x", **mesh_io._parse_ply(data, "x", fast=False))
    for field in ("positions", "indices", "normals", "uvs"):
        np.testing.assert_array_equal(getattr(fast, field), getattr(slow, field))
    assert len(fast.indices) == 80
    np.testing.assert_array_equal(fast.indices[:2], [quads[0][[0, 1, 2]], quads[0][[0, 2, 3]]])


def test_ascii_ply_mixed_face_sizes_keep_order(tmp_path):
    text = (
        "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 3\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n1 1 0\n0 1 0\n0.5 1.5 0\n"
        "3 0 1 2\n4 0 1 2 3\n5 0 1 2 4 3\n"
    )
    mesh = load_mesh(write(tmp_path / "mixed.ply", text))
    assert len(mesh.indices) == 1 + 2 + 3
    np.testing.assert_array_equal(mesh.indices[:3], [[0, 1, 2], [0, 1, 2], [0, 2, 3]])
    assert np.all(tri_normals(mesh)[:, 2] > 0)


def binary_ply(positions, faces, *, normals=None, uvs=None, endian="<") -> bytes:
    names = ["x", "y", "z"]
    cols = [positions]
    if normals is not None:
        names += ["nx", "ny", "nz"]
        cols.append(normals)
    if uvs is not None:
        names += ["u", "v"]
        cols.append(uvs)
    table = np.hstack(cols)
    vdt = np.dtype([(n, endian + "f4") for n in names])
    vert = np.empty(len(table), vdt)
    for i, n in enumerate(names):
        vert[n] = table[:, i]
    faces = np.asarray(faces)
    fdt = np.dtype([("n", "u1"), ("idx", endian + "i4", (faces.shape[1],))])
    face = np.empty(len(faces), fdt)
    face["n"] = faces.shape[1]
    face["idx"] = faces
    fmt = "binary_little_endian" if endian == "<" else "binary_big_endian"
    header = (
        f"ply\nformat {fmt} 1.0\nelement vertex {len(vert)}\n"
        + "".join(f"property float {n}\n" for n in names)
        + f"element face {len(face)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    return header.encode() + vert.tobytes() + face.tobytes()


POS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float32)
TRIS = np.array([[0, 1, 2], [0, 2, 3]])


@pytest.mark.parametrize("endian", ["<", ">"])
def test_binary_ply(tmp_path, endian):
    nrm = np.tile([0, 0, 1], (4, 1)).astype(np.float32)
    uv = POS[:, :2] * 0.5
    path = tmp_path / "b.ply"
    path.write_bytes(binary_ply(POS, TRIS, normals=nrm, uvs=uv, endian=endian))
    mesh = load_mesh(path)
    np.testing.assert_array_equal(mesh.positions, POS)
    np.testing.assert_array_equal(mesh.indices, TRIS)
    np.testing.assert_array_equal(mesh.normals, nrm)
    np.testing.assert_array_equal(mesh.uvs, uv)


def test_binary_ply_quads_and_no_normals(tmp_path):
    path = tmp_path / "q.ply"
    path.write_bytes(binary_ply(POS, [[0, 1, 2, 3]]))
    mesh = load_mesh(path)
    assert mesh.normals is None and mesh.uvs is None
    np.testing.assert_array_equal(mesh.indices, [[0, 1, 2], [0, 2, 3]])


def test_binary_ply_written_by_trimesh(tmp_path):
    import trimesh

    box = trimesh.creation.box()
    path = tmp_path / "box.ply"
    path.write_bytes(box.export(file_type="ply", encoding="binary", vertex_normal=False))
    mesh = load_mesh(path)
    np.testing.assert_allclose(mesh.positions, box.vertices)
    np.testing.assert_array_equal(mesh.indices, box.faces)
    assert mesh.normals is None


def test_ply_gz(tmp_path):
    path = tmp_path / "a.ply.gz"
    path.write_bytes(gzip.compress(ASCII_PLY.encode()))
    mesh = load_mesh(path)
    assert len(mesh.indices) == 2 and mesh.normals is not None
    path2 = tmp_path / "b.ply.gz"
    path2.write_bytes(gzip.compress(binary_ply(POS, TRIS)))
    np.testing.assert_array_equal(load_mesh(path2).indices, TRIS)


# ----------------------------------------------------------------------------- cache


def test_second_load_comes_from_cache(tmp_path, monkeypatch):
    path = write(tmp_path / "nuv.obj", NORMALS_UVS_OBJ)
    first = load_mesh(path)
    assert len(list((tmp_path / "cache" / "mesh").glob("*.npz"))) == 1

    def boom(*args, **kwargs):
        raise AssertionError("parsed again instead of using the cache")

    monkeypatch.setattr(mesh_io, "_parse", boom)
    second = load_mesh(path)
    for field in ("positions", "indices", "normals", "uvs", "material_ids"):
        np.testing.assert_array_equal(getattr(first, field), getattr(second, field))
        assert getattr(second, field).dtype == getattr(first, field).dtype
    assert second.material_names == first.material_names

    # different content -> different key -> parsed again
    path.write_text(NORMALS_UVS_OBJ + "f 1 2 4\n")
    with pytest.raises(AssertionError, match="parsed again"):
        load_mesh(path)


def test_cache_keeps_none_normals_and_names(tmp_path, monkeypatch):
    path = write(tmp_path / "mats.obj", TWO_MATERIALS_OBJ)
    load_mesh(path)
    monkeypatch.setattr(mesh_io, "_parse", None)
    cached = load_mesh(path)
    assert cached.normals is None and cached.uvs is None
    assert cached.material_names == ("red", "blue")


def test_damaged_cache_entry_is_a_miss(tmp_path, caplog):
    path = write(tmp_path / "quads.obj", QUADS_OBJ)
    load_mesh(path)
    (entry,) = (tmp_path / "cache" / "mesh").glob("*.npz")
    entry.write_bytes(b"garbage")
    with caplog.at_level(logging.WARNING, logger="pyclpt.scene.mesh_io"):
        mesh = load_mesh(path)
    (record,) = caplog.records
    assert "ignoring unreadable mesh cache entry" in record.getMessage() and "\n" not in record.getMessage()
    assert len(mesh.indices) == 4


# ----------------------------------------------------------------------------- errors


def test_missing_file(tmp_path):
    path = tmp_path / "nope.ply"
    with pytest.raises(FileNotFoundError, match="nope.ply"):
        load_mesh(path)


@pytest.mark.parametrize(
    "name, content",
    [
        ("garbage.ply", b"this is not a ply file\x00\x01\x02"),
        ("truncated.ply", binary_ply(POS, TRIS)[:-5]),
        ("garbage.ply.gz", b"\x1f\x8b not really gzip"),
        ("garbage.obj", b"\x00\xff\xfe binary junk \x01"),
        ("nofaces.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"),
        ("points.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                       b"property float z\nend_header\n0 0 0\n"),
        ("badnumber.obj", b"v 0 0 0\nv 1 x 0\nv 0 1 0\nf 1 2 3\n"),
        ("shortface.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n"),
        ("zeroindex.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"),
        ("mesh.stl", b"solid x\nendsolid x\n"),
    ],
)
def test_corrupt_files_raise_value_error_naming_the_file(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(ValueError, match=name.replace(".", r"\.")) as info:
        load_mesh(path)
    assert isinstance(info.value, MeshLoadError)


def test_obj_index_out_of_range(tmp_path):
    path = write(tmp_path / "oor.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 40\n")
    with pytest.raises(MeshLoadError, match=r"oor\.obj.*line 5.*vertex 40.*3 vertices"):
        load_mesh(path)


def test_obj_uv_index_out_of_range(tmp_path):
    path = write(tmp_path / "vt.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/7\n")
    with pytest.raises(MeshLoadError, match=r"vt\.obj.*texture coordinate 7"):
        load_mesh(path)


def test_obj_relative_index_out_of_range(tmp_path):
    path = write(tmp_path / "neg.obj", "v 0 0 0\nv 1 0 0\nf -1 -2 -3\n")
    with pytest.raises(MeshLoadError, match=r"neg\.obj.*line 3"):
        load_mesh(path)


def test_ply_index_out_of_range(tmp_path):
    path = tmp_path / "oor.ply"
    path.write_bytes(binary_ply(POS, [[0, 1, 2], [0, 2, 40]]))
    with pytest.raises(MeshLoadError, match=r"oor\.ply: triangle 1 references vertex 40 but the file has 4 vertices"):
        load_mesh(path)


def test_nan_position(tmp_path):
    pos = POS.copy()
    pos[2, 1] = np.nan
    path = tmp_path / "nan.ply"
    path.write_bytes(binary_ply(pos, TRIS))
    with pytest.raises(ValueError, match=r"nan\.ply: vertex 2 has a non-finite position"):
        load_mesh(path)


def test_inf_position_obj(tmp_path):
    path = write(tmp_path / "inf.obj", "v 0 0 0\nv 1 0 inf\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(ValueError, match=r"inf\.obj: vertex 1"):
        load_mesh(path)


def test_degenerate_triangles_are_kept(tmp_path):
    mesh = load_mesh(write(tmp_path / "deg.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 1 2\n"))
    assert len(mesh.indices) == 2


def test_meshdata_coerces_and_checks_shapes():
    m = MeshData(
        positions=np.zeros((3, 3)),
        indices=[[0, 1, 2]],
        normals=None,
        uvs=None,
        material_ids=[0],
        material_names=("",),
    )
    assert m.positions.dtype == np.float32 and m.indices.dtype == np.int32
    assert m.num_vertices == 3 and m.num_triangles == 1
    with pytest.raises(ValueError):
        MeshData(np.zeros((3, 2)), np.zeros((1, 3)), None, None, np.zeros(1), ("",))


# ----------------------------------------------------------------------------- real data


def _real(rel: str) -> Path:
    path = SCENES / rel
    if not path.exists():
        pytest.skip(f"{path} not available (set PYCLPT_SCENES)")
    return path


def test_real_bunny():
    mesh = load_mesh(_real("meshes/bunny.ply"))
    assert mesh.indices.shape == (69451, 3)
    assert mesh.positions.shape == (35947, 3)
    assert mesh.normals is None and mesh.uvs is None
    assert mesh.indices.min() >= 0 and mesh.indices.max() < 35947


def test_real_dragon_res2():
    mesh = load_mesh(_real("meshes/dragon_vrip_res2.ply.gz"))
    assert mesh.indices.shape == (202520, 3)
    assert mesh.positions.shape == (100250, 3)
    assert mesh.normals is None


def test_obj_partial_uvs_warn_and_are_dropped(tmp_path, caplog):
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1\nf 3 2 1\n"
    with caplog.at_level(logging.WARNING, logger="pyclpt.scene.mesh_io"):
        mesh = load_mesh(write(tmp_path / "partial.obj", text))
    messages = sorted(r.getMessage() for r in caplog.records)
    assert len(messages) == 2
    assert "partial.obj: some faces have normals (vn)" in messages[0]
    assert "partial.obj: some faces have texture coordinates (vt)" in messages[1]
    assert mesh.uvs is None and mesh.normals is None and len(mesh.indices) == 2


def test_ply_per_corner_texcoords_split_vertices(tmp_path):
    text = (
        "ply\nformat ascii 1.0\nelement vertex 4\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        "element face 2\nproperty list uchar int vertex_indices\nproperty list uchar float texcoord\nend_header\n"
        "0 0 0 0 0 1\n1 0 0 0 0 1\n1 1 0 0 0 1\n0 1 0 0 0 1\n"
        "3 0 1 2 6 0 0 1 0 1 1\n"
        "3 0 2 3 6 0.5 0.5 1 1 0 1\n"
    )
    mesh = load_mesh(write(tmp_path / "wedge.ply", text))
    assert len(mesh.positions) == 5  # vertex 0 carries two different UVs, so it is split
    assert corner_positions(mesh) == [[(0, 0, 0), (1, 0, 0), (1, 1, 0)], [(0, 0, 0), (1, 1, 0), (0, 1, 0)]]
    np.testing.assert_allclose(mesh.uvs[mesh.indices], [[[0, 0], [1, 0], [1, 1]], [[0.5, 0.5], [1, 1], [0, 1]]])
    np.testing.assert_array_equal(mesh.normals, np.tile([0, 0, 1], (5, 1)))
