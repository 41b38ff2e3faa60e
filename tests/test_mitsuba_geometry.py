"""The pure helpers of bench/peers/mitsuba_geometry.py (the geometry-gradient comparison with Mitsuba 3), without
Mitsuba: the PLY meshes are the shapes pyclpt's ``rectangle`` makes, the motions move vertices as the pose tangent
says, and the table's statistics."""
from __future__ import annotations

import numpy as np
import pytest

import pyclpt
from bench.peers import mitsuba_geometry as mg


def _positions(scene: pyclpt.Scene, name: str) -> np.ndarray:
    mesh = next(m for m in scene.meshes if m.name == name)
    return np.asarray(mesh.positions, np.float64)[np.asarray(mesh.indices).reshape(-1)]


def test_the_meshes_are_the_rectangles(tmp_path):
    """The PLY square of the lit-square scene holds the corners and triangles (the same winding, so the same face
    normal) that pyclpt's rectangle of the same to_world has (Mitsuba's rectangle: [-1, 1]^2, normal +z)."""
    m = mg.rotate([0, 1, 0], 20) @ mg.scale([0.8, 0.6, 1.0])
    d = mg.scene_dict("lit-square", tmp_path)
    ply = pyclpt.load_dict(d)
    d["shape"] = {"type": "rectangle", "to_world": m.tolist(), "bsdf": d["shape"]["bsdf"]}
    rect = pyclpt.load_dict(d)
    a, b = (next(m for m in sc.meshes if m.name == "shape") for sc in (ply, rect))
    assert np.asarray(a.positions) == pytest.approx(np.asarray(b.positions), abs=1e-6)
    for x, y in zip(np.asarray(a.indices), np.asarray(b.indices)):  # the same triangles, each turned the same way
        assert np.roll(x, -int(np.argmin(x))).tolist() == np.roll(y, -int(np.argmin(y))).tolist()


def test_transforms_match_pyclpt():
    from pyclpt.scene import transform as tf

    assert mg.look_at([0, 0, 5], [0, 0, 0]) == pytest.approx(tf.look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]))
    assert mg.rotate([0, 1, 0], 127) == pytest.approx(tf.rotate([0, 1, 0], 127))
    assert mg.rotate([1, 0, 0], 180) @ mg.translate([0, 1, 2]) == pytest.approx(
        tf.rotate([1, 0, 0], 180) @ tf.translate([0, 1, 2]))


def test_motions_are_pose_tangents(tmp_path):
    """A finite-difference scene moves the mesh by s T v, and T of 'rotate x' is the derivative of a rotation."""
    v = mg.shapes("floor")["floor"]
    assert mg.moved(v, mg._TZ, 0.5)[:, 2] == pytest.approx(v[:, 2] + 0.5)
    h = 1e-6
    rot = (mg.rotate([1, 0, 0], np.degrees(h)) - mg.rotate([1, 0, 0], -np.degrees(h))) / (2 * h)
    assert rot == pytest.approx(mg._RX, abs=1e-6)
    d = mg.scene_dict("soft-shadow", tmp_path, ("occluder", mg._TX, 0.02))
    moved = _positions(pyclpt.load_dict(d), "occluder")
    (tmp_path / "rest").mkdir()
    rest = _positions(pyclpt.load_dict(mg.scene_dict("soft-shadow", tmp_path / "rest")), "occluder")
    assert moved - rest == pytest.approx(np.tile([0.02, 0, 0], (len(rest), 1)), abs=1e-6)
    for scene_name, motions in mg.MOTIONS.items():  # every motion names a mesh of its scene
        assert all(shape in mg.shapes(scene_name) for _, shape, _ in motions)


def test_table_statistics():
    mean, se = mg.mean_se([[1.0, 2, 3], [3.0, 2, 5]])
    assert mean == pytest.approx([2, 2, 4]) and se == pytest.approx([1, 0, 1])
    text = mg.table({"s": {"m": {"pyclpt": [[1, 2, 3], [3, 2, 5]], "mitsuba": [[2, 2, 4], [2, 2, 4]],
                                 "fd": [2, 2, 4]}}})
    rows = [r for r in text.splitlines() if r.startswith("| s |")]
    assert len(rows) == 3
    assert rows[0].endswith("| +0.00 |") and rows[1].endswith("| - |")


def test_the_cube_is_pyclpts_cube(tmp_path):
    """The cube-shadow scene's PLY cube: the 24 corners (four to a face, split at its edges) of pyclpt's ``cube`` of
    the same to_world, and its triangles wound outwards; both renderers load the same file."""
    m = mg.translate([-0.1, 0.1, 0.55]) @ mg.rotate([1, 1, 0], 30) @ mg.scale(0.25)
    corners, faces = mg.cube(m)
    assert corners.shape == (24, 3) and faces.shape == (12, 3)
    scene = pyclpt.load_dict({"type": "scene", "box": {"type": "cube", "to_world": m.tolist()}})
    ours = np.asarray(scene.meshes[0].positions, np.float64)
    assert sorted(map(tuple, np.round(corners, 5))) == sorted(map(tuple, np.round(ours, 5)))
    n = np.cross(corners[faces[:, 1]] - corners[faces[:, 0]], corners[faces[:, 2]] - corners[faces[:, 0]])
    assert np.all(np.einsum("ij,ij->i", n, corners[faces].mean(1) - corners.mean(0)) > 0)
    ply = pyclpt.load_dict(mg.scene_dict("cube-shadow", tmp_path))
    cube = next(s for s in ply.meshes if s.name == "cube")
    assert np.asarray(cube.positions) == pytest.approx(corners, abs=1e-6)
