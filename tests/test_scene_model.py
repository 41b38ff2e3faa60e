"""The scene model: transforms, camera, load_dict and the built-in scenes (Mitsuba conventions)."""
from __future__ import annotations

import json
import logging
import math
import re
import warnings

import numpy as np
import pytest

import pyclpt
from pyclpt.scene import transform as tf
from pyclpt.scene.library import builtin_scenes
from pyclpt.scene.mitsuba_dict import METALS, SceneDictError, load_dict
from pyclpt.scene.model import Camera, Conductor, Dielectric, Diffuse, Film, Mask, Mesh, Plastic, Scene, TwoSided


def _geometric_normals(mesh: Mesh) -> np.ndarray:
    p = mesh.positions.astype(np.float64)
    i = mesh.indices
    n = np.cross(p[i[:, 1]] - p[i[:, 0]], p[i[:, 2]] - p[i[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _mesh(scene: Scene, name: str) -> Mesh:
    return next(m for m in scene.meshes if m.name == name)


def _scene(**elements) -> dict:
    return {"type": "scene", **elements}


RECT = {"type": "rectangle"}

# -- transforms ---------------------------------------------------------------------


def test_look_at_matches_mitsuba_cornell_camera():
    m = tf.look_at([0, 0, 3.9], [0, 0, 0], [0, 1, 0])
    # Mitsuba: columns (left, up, dir, origin); looking down -z with +y up, "left" is -x
    want = np.array([[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 3.9], [0, 0, 0, 1]], float)
    np.testing.assert_allclose(m, want, atol=1e-12)


def test_look_at_general_case():
    # dir = +x, up = +z: left = up x dir = +y, new up = dir x left = +z
    m = tf.look_at([1, 2, 3], [5, 2, 3], [0, 0, 7])
    np.testing.assert_allclose(m[:3, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(m[:3, 1], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(m[:3, 2], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(m[:3, 3], [1, 2, 3], atol=1e-12)
    np.testing.assert_allclose(m[3], [0, 0, 0, 1])
    # a non-orthogonal up is re-orthogonalised
    m = tf.look_at([0, 0, 0], [0, 0, 1], [0, 1, 1])
    np.testing.assert_allclose(m[:3, :3].T @ m[:3, :3], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(m[:3, 0], [1, 0, 0], atol=1e-12)  # left = y x z = +x
    np.testing.assert_allclose(m[:3, 1], [0, 1, 0], atol=1e-12)


def test_look_at_degenerate():
    with pytest.raises(ValueError, match="same point"):
        tf.look_at([1, 1, 1], [1, 1, 1])
    with pytest.raises(ValueError, match="parallel"):
        tf.look_at([0, 0, 0], [0, 2, 0], [0, 1, 0])


def test_from_spec_is_T_R_S():
    m = tf.from_spec([{"translate": [1, 2, 3]}, {"rotate": {"axis": [0, 0, 1], "angle": 90}}, {"scale": 2}])
    # (1,0,0) -> scale (2,0,0) -> rotate 90 deg about z (counter-clockwise) (0,2,0) -> translate (1,4,3)
    np.testing.assert_allclose(tf.apply_points(m, np.array([[1.0, 0, 0]])), [[1, 4, 3]], atol=1e-6)
    np.testing.assert_allclose(
        m, tf.translate([1, 2, 3]) @ tf.rotate([0, 0, 1], 90) @ tf.scale(2), atol=1e-12)
    # a different order gives a different answer: scale applied last scales the translation too
    m2 = tf.from_spec([{"scale": 2}, {"translate": [1, 2, 3]}])
    np.testing.assert_allclose(tf.apply_points(m2, np.zeros((1, 3))), [[2, 4, 6]], atol=1e-6)


def test_rotate_is_right_handed():
    np.testing.assert_allclose(tf.rotate([1, 0, 0], 90)[:3, :3] @ [0, 1, 0], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(tf.rotate([0, 1, 0], 90)[:3, :3] @ [0, 0, 1], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(tf.rotate([0, 0, 2], 90)[:3, :3] @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_from_spec_forms():
    np.testing.assert_array_equal(tf.from_spec(None), np.eye(4))
    np.testing.assert_array_equal(tf.from_spec(np.arange(16).reshape(4, 4)), np.arange(16).reshape(4, 4))
    np.testing.assert_array_equal(tf.from_spec(list(range(16))), np.arange(16).reshape(4, 4))
    np.testing.assert_allclose(tf.from_spec({"translate": [1, 2, 3]})[:3, 3], [1, 2, 3])
    np.testing.assert_allclose(tf.from_spec([{"scale": [1, 2, 3]}]), np.diag([1, 2, 3, 1.0]))
    la = tf.from_spec([{"look_at": {"origin": [0, 0, 3.9], "target": [0, 0, 0], "up": [0, 1, 0]}}])
    np.testing.assert_allclose(la, tf.look_at([0, 0, 3.9], [0, 0, 0]))
    with pytest.raises(ValueError, match="shear"):
        tf.from_spec([{"shear": 1}])
    with pytest.raises(ValueError, match="translate"):
        tf.from_spec([{"translate": [1, 2]}])


def test_apply_normals_uses_inverse_transpose():
    m = tf.scale([1, 4, 1])
    # the plane x + y = 0 has normal (1,1,0); after scaling y by 4 its normal is (4,1,0)/|.|
    n = tf.apply_normals(m, np.array([[1.0, 1.0, 0.0]]))
    np.testing.assert_allclose(n[0], np.array([4, 1, 0]) / math.sqrt(17), atol=1e-6)


# -- camera -------------------------------------------------------------------------


@pytest.mark.parametrize("axis, w, h, tx_over_t, ty_over_t", [
    ("x", 32, 16, 1.0, 0.5),
    ("y", 32, 16, 2.0, 1.0),
    ("smaller", 32, 16, 2.0, 1.0),  # landscape: the smaller side is y
    ("larger", 32, 16, 1.0, 0.5),
    ("smaller", 16, 32, 1.0, 2.0),  # portrait: the smaller side is x
    ("larger", 16, 32, 0.5, 1.0),
    ("diagonal", 30, 40, 0.6, 0.8),  # tan(fov/2) spans the half diagonal (3-4-5)
    ("x", 20, 20, 1.0, 1.0),
])
def test_camera_basis_fov_axis(axis, w, h, tx_over_t, ty_over_t):
    fov = 50.0
    cam = Camera.look_at([0, 0, 3.9], [0, 0, 0], fov=fov, fov_axis=axis)
    origin, forward, right, up = cam.basis(w, h)
    t = math.tan(math.radians(fov) / 2)
    np.testing.assert_allclose(origin, [0, 0, 3.9])
    np.testing.assert_allclose(forward, [0, 0, -1], atol=1e-12)
    # the image's right is -left: +x in the world for this camera; up is +y
    np.testing.assert_allclose(right / np.linalg.norm(right), [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(up / np.linalg.norm(up), [0, 1, 0], atol=1e-12)
    assert np.linalg.norm(right) == pytest.approx(t * tx_over_t)
    assert np.linalg.norm(up) == pytest.approx(t * ty_over_t)
    # pixels are square
    assert np.linalg.norm(right) / np.linalg.norm(up) == pytest.approx(w / h)


def test_camera_basis_ignores_scale_in_to_world():
    cam = Camera(tf.look_at([0, 0, 0], [0, 0, 1]) @ tf.scale(3), fov=90)
    _, forward, right, up = cam.basis(10, 10)
    np.testing.assert_allclose(forward, [0, 0, 1], atol=1e-12)
    assert np.linalg.norm(right) == pytest.approx(1.0)
    assert np.linalg.norm(up) == pytest.approx(1.0)


def test_camera_validation():
    with pytest.raises(ValueError, match="fov"):
        Camera(fov=180)
    with pytest.raises(ValueError, match="fov_axis"):
        Camera(fov_axis="z")
    with pytest.raises(ValueError, match="width"):
        Film(0, 10)


# -- load_dict ------------------------------------------------------------------------


def test_rectangle_with_area_emitter():
    scene = load_dict(_scene(lamp={
        "type": "rectangle", "to_world": [{"translate": [0, 2, 0]}],
        "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1, 2, 3]}},
    }))
    lamp = _mesh(scene, "lamp")
    assert lamp.emission == (1.0, 2.0, 3.0)
    assert lamp.triangle_count == 2 and scene.triangle_count == 2
    assert scene.emitter_count == 2
    np.testing.assert_allclose(lamp.positions[:, 2], 0.0)  # rectangle: [-1, 1]^2 at z = 0
    np.testing.assert_allclose(np.sort(lamp.positions[:, 1]), [1, 1, 3, 3])
    np.testing.assert_allclose(_geometric_normals(lamp), [[0, 0, 1]] * 2, atol=1e-6)
    assert scene.materials == [Diffuse((0.0, 0.0, 0.0))]  # no bsdf: Mitsuba 3 makes an emitter's shape black
    # scalar radiance
    scene = load_dict(_scene(lamp={**RECT, "emitter": {"type": "area", "radiance": 5}}))
    assert scene.meshes[0].emission == (5.0, 5.0, 5.0)


def test_ref_bsdf_is_shared():
    scene = load_dict(_scene(
        b={**RECT, "bsdf": {"type": "ref", "id": "paint"}},  # referenced before its definition
        paint={"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.1, 0.2, 0.3]}},
        a={**RECT, "bsdf": {"type": "ref", "id": "paint"}},
        c={**RECT, "bsdf": {"type": "diffuse", "reflectance": 0.7}},
    ))
    assert len(scene.materials) == 2
    assert _mesh(scene, "a").material == _mesh(scene, "b").material
    assert scene.materials[_mesh(scene, "a").material] == Diffuse((0.1, 0.2, 0.3))
    assert scene.materials[_mesh(scene, "c").material] == Diffuse((0.7, 0.7, 0.7))


def test_bsdf_with_explicit_id():
    scene = load_dict(_scene(
        whatever={"type": "diffuse", "id": "wall", "reflectance": 0.25},
        s={**RECT, "bsdf": {"type": "ref", "id": "wall"}},
    ))
    assert scene.materials == [Diffuse((0.25, 0.25, 0.25))]


def test_twosided():
    scene = load_dict(_scene(
        s={**RECT, "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": 0.2}}},
        t={**RECT, "bsdf": {"type": "twosided", "material": {"type": "conductor", "material": "Au"}}},
        u={**RECT, "bsdf": {"type": "diffuse"}},
    ))
    assert scene.materials[0] == Diffuse((0.2, 0.2, 0.2), twosided=True)
    assert isinstance(scene.materials[1], Conductor) and scene.materials[1].twosided
    assert scene.materials[2].twosided is False


def test_twosided_with_two_bsdfs(caplog):
    """Mitsuba's twosided with two BSDFs: the first on the front, the second on the back; the same one twice
    is a plain two-sided material; a mask inside is dropped with a note (around the pair it stays);
    transmitting materials are refused, as Mitsuba does."""
    red = {"type": "diffuse", "reflectance": [0.8, 0.1, 0.1]}
    gold = {"type": "roughconductor", "material": "Au", "alpha": 0.2}
    with caplog.at_level(logging.WARNING, logger="pyclpt"):
        scene = load_dict(_scene(
            red=dict(red, id="red"),
            a={**RECT, "bsdf": {"type": "twosided", "front": {"type": "ref", "id": "red"}, "back": gold}},
            b={**RECT, "bsdf": {"type": "twosided", "x": {"type": "ref", "id": "red"},
                                "y": {"type": "ref", "id": "red"}}},
            c={**RECT, "bsdf": {"type": "mask", "opacity": 0.5, "bsdf": {
                "type": "twosided", "f": red, "k": {"type": "mask", "opacity": 0.3, "bsdf": {"type": "plastic"}}}}},
        ))
    pair, same, masked = scene.materials
    assert pair == TwoSided(Diffuse((0.8, 0.1, 0.1)), Conductor(*METALS["Au"], alpha=0.2, distribution="beckmann"))
    assert same == Diffuse((0.8, 0.1, 0.1), twosided=True)
    assert isinstance(masked, Mask) and masked.material == TwoSided(Diffuse((0.8, 0.1, 0.1)), Plastic())
    assert "c.bsdf.bsdf: a mask inside a twosided with two BSDFs is not supported" in caplog.text
    with pytest.raises(SceneDictError, match=r"s\.bsdf\.g: twosided: only materials without transmission"):
        load_dict(_scene(s={**RECT, "bsdf": {"type": "twosided", "f": red, "g": {"type": "dielectric"}}}))
    with pytest.raises(SceneDictError, match="twosided needs one or two nested BSDFs, got 3"):
        load_dict(_scene(s={**RECT, "bsdf": {"type": "twosided", "f": red, "g": red, "h": red}}))
    with pytest.raises(TypeError, match="twosided back: expected a reflecting material"):
        TwoSided(Diffuse(), Dielectric())


def test_anisotropic_roughness(caplog):
    """alpha_u / alpha_v of roughconductor and roughdielectric load as alpha (= alpha_u) and alpha_v (None when
    equal); roughplastic has only alpha in Mitsuba: the geometric mean, with a note."""
    with caplog.at_level(logging.WARNING, logger="pyclpt"):
        scene = load_dict(_scene(
            a={**RECT, "bsdf": {"type": "roughconductor", "alpha_u": 0.05, "alpha_v": 0.3, "distribution": "ggx"}},
            b={**RECT, "bsdf": {"type": "roughdielectric", "alpha_u": 0.2, "alpha_v": 0.0}},
            c={**RECT, "bsdf": {"type": "roughconductor", "alpha_u": 0.2, "alpha_v": 0.2}},
            d={**RECT, "bsdf": {"type": "roughplastic", "alpha_u": 0.1, "alpha_v": 0.4}},
        ))
    a, b, c, d = scene.materials
    assert (a.alpha, a.alpha_v, a.distribution, a.anisotropic) == (0.05, 0.3, "ggx", True)
    assert (b.alpha, b.alpha_v, b.anisotropic) == (0.2, 1e-4, True)  # Mitsuba clamps each to 1e-4
    assert (c.alpha, c.alpha_v, c.anisotropic) == (0.2, None, False)
    assert d.alpha == pytest.approx(0.2)
    assert "d.bsdf: anisotropic roughness (0.1, 0.4) not supported by roughplastic" in caplog.text
    assert "a.bsdf" not in caplog.text and "b.bsdf" not in caplog.text
    with pytest.raises(SceneDictError, match=r"s\.bsdf\.alpha_v: roughness must be in \[0, 4\]"):
        load_dict(_scene(s={**RECT, "bsdf": {"type": "roughconductor", "alpha_u": 0.1, "alpha_v": 5}}))
    with pytest.raises(ValueError, match="anisotropic roughness needs alpha"):
        Conductor(alpha=0.0, alpha_v=0.3)


def test_conductor_by_metal_name_and_by_eta_k():
    scene = load_dict(_scene(
        gold={**RECT, "bsdf": {"type": "conductor", "material": "Au"}},
        custom={**RECT, "bsdf": {"type": "conductor", "eta": {"type": "rgb", "value": [0.2, 0.9, 1.1]},
                                 "k": {"type": "rgb", "value": [3.9, 2.4, 2.1]}}},
        rough={**RECT, "bsdf": {"type": "roughconductor", "material": "Al", "alpha": 0.3}},
        mirror={**RECT, "bsdf": {"type": "conductor"}},
    ))
    gold, custom, rough, mirror = scene.materials
    assert gold == Conductor(*METALS["Au"])
    assert gold.eta == pytest.approx((0.143036, 0.375307, 1.442045))  # Mitsuba 3.9.1 scalar_rgb
    assert gold.alpha == 0.0
    assert custom.eta == (0.2, 0.9, 1.1) and custom.k == (3.9, 2.4, 2.1)
    assert rough.eta == METALS["Al"][0] and rough.alpha == pytest.approx(0.3)
    assert mirror.eta == (0.0, 0.0, 0.0) and mirror.k == (1.0, 1.0, 1.0)  # Mitsuba's default "none"


def test_dielectric():
    scene = load_dict(_scene(
        glass={**RECT, "bsdf": {"type": "dielectric", "int_ior": 1.33, "ext_ior": 1.0}},
        named={**RECT, "bsdf": {"type": "dielectric", "int_ior": "water", "ext_ior": "air"}},
        default={**RECT, "bsdf": {"type": "dielectric"}},
        tinted={**RECT, "bsdf": {"type": "twosided", "bsdf": {"type": "dielectric", "int_ior": 2.0}}},
    ))
    glass, named, default, tinted = scene.materials
    assert glass == Dielectric(1.33, 1.0)
    assert named.int_ior == pytest.approx(1.333) and named.ext_ior == pytest.approx(1.000277)
    assert default == Dielectric(1.5046, 1.000277)
    assert isinstance(tinted, Dielectric) and tinted.int_ior == 2.0  # twosided glass stays glass


def test_sphere_center_radius():
    scene = load_dict(_scene(ball={"type": "sphere", "center": [1, 2, 3], "radius": 0.5}))
    ball = scene.meshes[0]
    d = np.linalg.norm(ball.positions - np.array([1, 2, 3], np.float32), axis=1)
    np.testing.assert_allclose(d, 0.5, atol=1e-5)
    assert ball.positions[:, 0].max() == pytest.approx(1.5, abs=1e-5)
    assert ball.positions[:, 2].min() == pytest.approx(2.5, abs=1e-5)
    # shading normals point outward
    np.testing.assert_allclose(ball.normals, (ball.positions - [1, 2, 3]) / 0.5, atol=1e-4)
    # triangles face outward
    p = ball.positions[ball.indices].mean(axis=1) - [1, 2, 3]
    assert np.all(np.einsum("ij,ij->i", _geometric_normals(ball), p) > 0)


def test_flip_normals_reverses_winding():
    plain = load_dict(_scene(s={**RECT})).meshes[0]
    flipped = load_dict(_scene(s={**RECT, "flip_normals": True})).meshes[0]
    np.testing.assert_array_equal(flipped.indices, plain.indices[:, ::-1])
    np.testing.assert_allclose(_geometric_normals(flipped), -_geometric_normals(plain), atol=1e-6)
    np.testing.assert_allclose(flipped.normals, -plain.normals)
    np.testing.assert_allclose(_geometric_normals(flipped), [[0, 0, -1]] * 2, atol=1e-6)


def test_face_normals_drops_normals():
    assert load_dict(_scene(s={**RECT})).meshes[0].normals is not None
    assert load_dict(_scene(s={**RECT, "face_normals": True})).meshes[0].normals is None


def test_to_world_moves_normals():
    s = load_dict(_scene(s={**RECT, "to_world": [{"rotate": {"axis": [1, 0, 0], "angle": -90}},
                                                 {"scale": [2, 3, 1]}]})).meshes[0]
    np.testing.assert_allclose(s.normals, [[0, 1, 0]] * 4, atol=1e-6)
    np.testing.assert_allclose(np.abs(s.positions).max(axis=0), [2, 0, 3], atol=1e-6)


OBJ_TEXT = """\
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
f 1 2 3
f 1 3 4
"""


def test_obj_and_ply_from_files(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    (tmp_path / "quad.obj").write_text(OBJ_TEXT)
    tm = trimesh.Trimesh(vertices=[[0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 2]],
                         faces=[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], process=False)
    tm.export(tmp_path / "tet.ply")
    d = _scene(
        quad={"type": "obj", "filename": "quad.obj", "to_world": [{"translate": [0, 0, 5]}]},
        tet={"type": "ply", "filename": str(tmp_path / "tet.ply")},
    )
    scene = load_dict(d, base_dir=tmp_path)
    quad, tet = _mesh(scene, "quad"), _mesh(scene, "tet")
    assert quad.triangle_count == 2 and tet.triangle_count == 4
    np.testing.assert_allclose(quad.positions[:, 2], 5.0)
    np.testing.assert_allclose(_geometric_normals(quad), [[0, 0, 1]] * 2, atol=1e-6)
    np.testing.assert_allclose(np.sort(tet.positions.max(axis=0)), [2, 2, 2])
    # a scene file: relative names resolve against the file's folder
    (tmp_path / "scene.json").write_text(json.dumps(d))
    from_file = pyclpt.load(tmp_path / "scene.json")
    assert from_file.triangle_count == 6
    assert from_file.name == "scene"
    assert from_file.source == tmp_path / "scene.json"


def test_constant_environment():
    scene = load_dict(_scene(s={**RECT}, sky={"type": "constant",
                                               "radiance": {"type": "rgb", "value": [0.1, 0.2, 0.3]}}))
    assert scene.environment == (0.1, 0.2, 0.3)
    assert scene.emitter_count == 1
    assert load_dict(_scene(s={**RECT})).environment is None


def test_integrator_and_sensor_values():
    to_world = [{"look_at": {"origin": [1, 2, 3], "target": [0, 0, 0], "up": [0, 1, 0]}}]
    scene = load_dict(_scene(
        integrator={"type": "path", "max_depth": 5},
        sensor={"type": "perspective", "fov": 30, "fov_axis": "y", "to_world": to_world,
                "film": {"type": "hdrfilm", "width": 40, "height": 30},
                "sampler": {"type": "independent", "sample_count": 7}},
        s={**RECT},
    ))
    assert scene.max_depth == 5
    assert (scene.film.width, scene.film.height) == (40, 30)
    assert scene.spp == 7
    assert scene.camera.fov == 30 and scene.camera.fov_axis == "y"
    np.testing.assert_allclose(scene.camera.to_world, tf.look_at([1, 2, 3], [0, 0, 0]))
    # Mitsuba's defaults when absent
    plain = load_dict(_scene(s={**RECT}))
    assert plain.max_depth == -1 and plain.spp == 64
    sensor_only = load_dict(_scene(sensor={"type": "perspective"}, s={**RECT}))
    assert (sensor_only.film.width, sensor_only.film.height) == (768, 576)
    assert sensor_only.camera.fov == 45.0 and sensor_only.camera.fov_axis == "x"


# -- load_dict errors name the element ------------------------------------------------------


@pytest.mark.parametrize("elements, needles", [
    ({"blob": {"type": "blobby"}}, ["blob", "blobby"]),
    ({"s": {**RECT, "bsdf": {"type": "plasticky"}}}, ["s.bsdf", "plasticky"]),
    ({"s": {**RECT, "bsdf": {"type": "ref", "id": "nope"}}}, ["s.bsdf", "nope"]),
    ({"mat": {"type": "diffuse", "reflectance": [1, 2]}, "s": {**RECT, "bsdf": {"type": "ref", "id": "mat"}}},
     ["mat.reflectance"]),
    ({"s": {**RECT, "bsdf": {"type": "diffuse", "reflectance": "red"}}}, ["s.bsdf.reflectance"]),
    ({"s": {**RECT, "bsdf": {"type": "diffuse", "reflectance": {"type": "bitmap"}}}},
     ["s.bsdf.reflectance", "bitmap"]),
    ({"s": {**RECT, "bsdf": {"type": "diffuse", "reflectance": [0.5, float("nan"), 0.5]}}},
     ["s.bsdf.reflectance"]),
    ({"s": {**RECT, "bsdf": {"type": "conductor", "material": "Unobtainium"}}}, ["s.bsdf.material", "Unobtainium"]),
    ({"s": {**RECT, "bsdf": {"type": "roughconductor", "alpha": -0.5}}}, ["s.bsdf.alpha"]),
    ({"s": {**RECT, "bsdf": {"type": "dielectric", "int_ior": -1}}}, ["s.bsdf", "-1"]),
    ({"s": {**RECT, "bsdf": {"type": "dielectric", "int_ior": "unobtainium"}}}, ["s.bsdf.int_ior"]),
    ({"s": {**RECT, "bsdf": "white"}}, ["s.bsdf"]),
    ({"mesh": {"type": "obj", "filename": "missing.obj"}}, ["mesh.filename", "missing.obj", "not found"]),
    ({"mesh": {"type": "obj"}}, ["mesh", "filename"]),
    ({"lamp": {**RECT, "emitter": {"type": "area", "radiance": -1}}}, ["lamp", "negative"]),
    ({"lamp": {**RECT, "emitter": {"type": "point"}}}, ["lamp.emitter", "area"]),
    ({"tri": {"type": "mesh", "positions": [[0, 0, 0], [float("nan"), 0, 0], [0, 1, 0]], "indices": [[0, 1, 2]]}},
     ["tri", "vertex 1", "NaN"]),
    ({"tri": {"type": "mesh", "positions": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "indices": [[0, 1, 3]]}},
     ["tri", "triangle 0"]),
    ({"tri": {"type": "mesh", "positions": [[0, 0, 0]]}}, ["tri", "indices"]),
    ({"tri": {"type": "mesh", "positions": [[0, 0], [1, 0]], "indices": [[0, 1, 2]]}}, ["tri"]),
    ({"s": {**RECT, "to_world": [{"translate": [0, float("nan"), 0]}]}}, ["s.to_world", "translate"]),
    ({"s": {**RECT, "to_world": [{"rotate": {"angle": 90}}]}}, ["s.to_world"]),
    ({"ball": {"type": "sphere", "center": [0, 0]}}, ["ball.center"]),
    ({"ball": {"type": "sphere", "radius": "big"}}, ["ball.radius", "big"]),
    ({"sensor": {"type": "radiancemeter"}, "s": {**RECT}}, ["sensor", "radiancemeter"]),
    ({"sensor": {"type": "perspective", "fov": 200}, "s": {**RECT}}, ["sensor", "fov"]),
    ({"sensor": {"type": "perspective", "film": {"width": 0}}, "s": {**RECT}}, ["sensor.film", "width"]),
    ({"x": 3}, ["x", "expected a dict"]),
    ({}, ["no shapes"]),
])
def test_load_dict_errors_name_the_element(elements, needles):
    with pytest.raises(SceneDictError) as info:
        load_dict(_scene(**elements), origin="my-scene.json")
    msg = str(info.value)
    assert isinstance(info.value, ValueError)
    assert msg.startswith("my-scene.json: ")
    assert msg.count("my-scene.json") == 1, msg  # the origin is not repeated
    for needle in needles:
        assert needle in msg, (needle, msg)


def test_top_level_must_be_scene():
    with pytest.raises(SceneDictError, match="type 'scene'"):
        load_dict({"type": "shape"})


def test_nan_vertex_in_obj_names_shape(tmp_path):
    (tmp_path / "bad.obj").write_text(OBJ_TEXT.replace("v 1 0 0", "v nan 0 0"))
    with pytest.raises(SceneDictError, match="badmesh") as info:
        load_dict(_scene(badmesh={"type": "obj", "filename": "bad.obj"}), base_dir=tmp_path, origin="o.json")
    assert str(info.value).count("o.json") == 1


def test_unused_parameters_one_warning(caplog):
    d = _scene(
        mat={"type": "diffuse", "reflectance": 0.5, "foo": 1},
        s={**RECT, "bsdf": {"type": "ref", "id": "mat"}, "bar": 2},
        sensor={"type": "perspective", "baz": 3, "film": {"width": 8, "height": 8, "qux": 4}},
        integrator={"type": "path", "max_depth": 3, "hide_emitters": True},
    )
    with warnings.catch_warnings(), caplog.at_level(logging.WARNING, logger="pyclpt"):
        warnings.simplefilter("error")  # reported through logging, never warnings
        load_dict(d)
    records = [r for r in caplog.records if r.name.startswith("pyclpt")]
    assert len(records) == 1, [r.getMessage() for r in records]
    assert records[0].levelno == logging.WARNING and records[0].name == "pyclpt.scene.mitsuba_dict.scene"
    msg = records[0].getMessage()
    assert "\n" not in msg and msg.startswith("scene: not used by pyclpt (5): "), msg  # one line
    entries = msg.split(": not used by pyclpt (5): ")[1].split("; ")
    assert len(entries) == 5, entries
    for key in ("mat.foo", "s.bar", "sensor.baz", "sensor.film.qux", "integrator.hide_emitters"):
        assert any(e.startswith(key) for e in entries), (key, msg)


def test_no_warning_for_clean_dict(caplog):
    with warnings.catch_warnings(), caplog.at_level(logging.WARNING, logger="pyclpt"):
        warnings.simplefilter("error")
        load_dict(_scene(s={**RECT, "bsdf": {"type": "diffuse", "reflectance": 0.3}}))
        pyclpt.load("cornell-box")
    assert not caplog.records, caplog.text


# -- built-in scenes ----------------------------------------------------------------------


def test_cornell_box_summary(cornell_box):
    s = cornell_box
    assert s.name == "cornell-box"
    # 5 walls + light (2 triangles each) + 2 cubes (12 each)
    assert s.triangle_count == 36
    assert len(s.meshes) == 8
    assert len(s.materials) == 3
    assert (s.film.width, s.film.height) == (256, 256)
    assert s.spp == 64
    assert s.max_depth == 8
    assert s.environment is None
    assert s.emitter_count == 2
    white, green, red = (0.885809, 0.698859, 0.666422), (0.105421, 0.37798, 0.076425), (0.570068, 0.0430135, 0.0443706)
    assert s.materials[_mesh(s, "floor").material] == Diffuse(white)
    assert s.materials[_mesh(s, "green-wall").material] == Diffuse(green)
    assert s.materials[_mesh(s, "red-wall").material] == Diffuse(red)
    assert _mesh(s, "light").material == _mesh(s, "floor").material == _mesh(s, "small-box").material


def test_cornell_box_camera_matches_mitsuba(cornell_box):
    cam = cornell_box.camera
    assert cam.fov == pytest.approx(39.3077)
    assert cam.fov_axis == "smaller"
    np.testing.assert_allclose(cam.to_world, [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 3.9], [0, 0, 0, 1]],
                               atol=1e-12)


def test_cornell_box_light_matches_mitsuba(cornell_box):
    light = _mesh(cornell_box, "light")
    assert light.emission == pytest.approx((18.387, 13.9873, 6.75357))
    assert light.triangle_count == 2
    got = sorted(map(tuple, np.round(light.positions.astype(np.float64), 5)))
    want = sorted((x, 0.99, z) for x in (-0.23, 0.23) for z in (0.01 - 0.19, 0.01 + 0.19))
    np.testing.assert_allclose(got, want, atol=1e-5)
    # emits downwards (front side = counter-clockwise winding), shading normals agree
    np.testing.assert_allclose(_geometric_normals(light), [[0, -1, 0]] * 2, atol=1e-5)
    np.testing.assert_allclose(light.normals, [[0, -1, 0]] * 4, atol=1e-5)


@pytest.mark.parametrize("name, normal, plane_axis, plane_value", [
    ("floor", (0, 1, 0), 1, -1.0),
    ("ceiling", (0, -1, 0), 1, 1.0),
    ("back", (0, 0, 1), 2, -1.0),
    ("green-wall", (-1, 0, 0), 0, 1.0),
    ("red-wall", (1, 0, 0), 0, -1.0),
])
def test_cornell_box_walls_face_inward(cornell_box, name, normal, plane_axis, plane_value):
    wall = _mesh(cornell_box, name)
    np.testing.assert_allclose(_geometric_normals(wall), [normal] * 2, atol=1e-6)
    np.testing.assert_allclose(wall.positions[:, plane_axis], plane_value, atol=1e-6)
    others = [a for a in range(3) if a != plane_axis]
    np.testing.assert_allclose(np.abs(wall.positions[:, others]), 1.0, atol=1e-6)


@pytest.mark.parametrize("name, center, half_height", [
    ("small-box", (0.335, -0.7, 0.38), 0.3),
    ("large-box", (-0.33, -0.4, -0.28), 0.61),
])
def test_cornell_box_cubes(cornell_box, name, center, half_height):
    box = _mesh(cornell_box, name)
    assert box.triangle_count == 12
    np.testing.assert_allclose(box.positions.mean(axis=0), center, atol=1e-5)
    # as in Mitsuba, the small box rests on the floor (y = -1) and the large one sinks 0.01 below it
    assert box.positions[:, 1].min() == pytest.approx(center[1] - half_height, abs=1e-5)
    assert box.positions[:, 1].min() == pytest.approx(-1.0, abs=0.011)
    assert box.positions[:, 1].max() == pytest.approx(center[1] + half_height, abs=1e-5)
    # triangles face outward
    c = box.positions[box.indices].mean(axis=1) - np.array(center)
    assert np.all(np.einsum("ij,ij->i", _geometric_normals(box), c) > 0)


def test_cornell_box_small_box_rotation(cornell_box):
    # Mitsuba rotates the small box by -17 degrees about +y: its local +x face normal becomes
    # (cos 17, 0, sin 17)
    box = _mesh(cornell_box, "small-box")
    n = _geometric_normals(box)
    want = np.array([math.cos(math.radians(17)), 0, math.sin(math.radians(17))])
    assert np.any(np.all(np.abs(n - want) < 1e-5, axis=1))


def test_load_unknown_scene_lists_builtins():
    with pytest.raises(FileNotFoundError) as info:
        pyclpt.load("nope")
    msg = str(info.value)
    assert "'nope'" in msg
    assert "cornell-box" in msg and "cornell-bunny" in msg


def test_load_bad_files(tmp_path):
    (tmp_path / "broken.json").write_text('{"type": "scene",\n  "x": }')
    with pytest.raises(SceneDictError, match=r"broken\.json:2: invalid JSON"):
        pyclpt.load(tmp_path / "broken.json")
    (tmp_path / "scene.xml").write_text("<scene/>")
    with pytest.raises(SceneDictError, match=r"\.xml"):
        pyclpt.load(tmp_path / "scene.xml")


def test_cornell_bunny_without_shared_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("PYCLPT_SCENES", str(tmp_path))
    with pytest.raises(FileNotFoundError) as info:
        pyclpt.load("cornell-bunny")
    msg = str(info.value)
    assert "PYCLPT_SCENES" in msg
    assert "bunny" in msg


def test_builtin_scenes_have_descriptions():
    scenes = builtin_scenes()
    assert {"cornell-box", "cornell-bunny"} <= set(scenes)
    for name, desc in scenes.items():
        assert isinstance(desc, str) and len(desc) > 10, name
    assert "Mitsuba" in scenes["cornell-box"]
    assert re.search("bunny", scenes["cornell-bunny"], re.I)
