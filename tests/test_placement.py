"""Parameters that move things (pyclpt/gradients/placement.py): vertex positions, a shape's pose, an
instance's, a spot light's and the sensor's to_world, the sensor's x_fov, a point light's position; each
through traverse() and update(), checked against the same scene built moved, with the kernels not
compiled again and the gradient renderer's copy of the scene refreshed (BVH rebuilt)."""
from __future__ import annotations

import copy

import numpy as np
import pytest

import pyclpt
from pyclpt.device.program import compile_seconds
from pyclpt.gradients import differentiate, placement
from pyclpt.scene import transform as tf
from pyclpt.scene.shapes import sphere

KW = dict(spp=2, seed=3, width=24, height=24)


def _moved(scene: pyclpt.Scene, mesh: str, m: np.ndarray) -> pyclpt.Scene:
    """A deep copy of ``scene`` with ``mesh``'s positions (and normals) transformed by ``m``."""
    out, m = copy.deepcopy(scene), np.asarray(m, np.float64)
    for me in out.meshes:
        if me.name == mesh:
            me.positions = tf.apply_points(m, me.positions.astype(np.float64)).astype(np.float32)
            if me.normals is not None:
                me.normals = tf.apply_normals(m, me.normals)
    return out


def test_moving_parameters_are_listed():
    """A mesh's pose and vertices (with or without vertex normals: tests/test_interior.py) and the sensor's are
    differentiated when named; the others say why not."""
    params = pyclpt.traverse(pyclpt.load("cornell-box"))
    assert "small-box.to_world" in params.differentiable
    assert "small-box.vertex_positions" in params.differentiable
    for name in ("sensor.to_world", "sensor.x_fov"):
        assert name in params.differentiable
    assert params["small-box.to_world"].shape == (4, 4)
    np.testing.assert_array_equal(params["small-box.to_world"], np.eye(4))


def test_a_pose_moves_a_shape_as_a_scene_built_moved():
    """small-box.to_world through update(): the image of the same scene built with the box moved, bit for
    bit (the BVH is built for the new positions), and not the image before."""
    scene = pyclpt.load("cornell-box")
    before = pyclpt.render(scene, **KW)
    m = (tf.translate([0.08, 0.0, -0.05]) @ tf.rotate([0, 1, 0], 20)).astype(np.float32)  # values are float32
    expected = pyclpt.render(_moved(scene, "small-box", m), **KW)
    params = pyclpt.traverse(scene)
    original = params["small-box.vertex_positions"]
    params["small-box.to_world"] = m
    assert params.update() == ["small-box.to_world"]
    np.testing.assert_array_equal(pyclpt.render(scene, **KW), expected)
    assert np.abs(expected - before).max() > 0.05
    # vertex_positions reads the moved positions; setting them back (world space) undoes the move
    params["small-box.vertex_positions"] = original
    params.update()  # the box's normals are recomputed from its positions: the same up to rounding
    np.testing.assert_allclose(pyclpt.render(scene, **KW), before, atol=1e-6)
    np.testing.assert_allclose(params["small-box.to_world"], m, atol=1e-6)  # the pose stays


def test_vertex_normals_are_recomputed_when_the_mesh_has_them():
    s = sphere(rings=24, segments=48)
    n = placement.vertex_normals(s.positions, s.indices)
    unit = s.positions / np.linalg.norm(s.positions, axis=1, keepdims=True)
    used = np.unique(s.indices)  # (the generator leaves a pole vertex unused)
    assert np.min(np.sum(n * unit, axis=1)[used]) > 0.997  # a sphere's normals are its positions
    mesh = pyclpt.Mesh("ball", s.positions * 2, s.indices, 0, normals=s.normals)
    scene = pyclpt.Scene([mesh], [pyclpt.Diffuse()], pyclpt.Camera.look_at([0, 0, 6], [0, 0, 0]), pyclpt.Film(8, 8))
    params = pyclpt.traverse(scene)
    squashed = (s.positions * [2.0, 2.0, 0.5]).astype(np.float32)
    params["ball.vertex_positions"] = squashed.reshape(-1)
    params.update()
    np.testing.assert_array_equal(mesh.positions, squashed)
    np.testing.assert_allclose(mesh.normals, placement.vertex_normals(squashed, s.indices))
    assert mesh.normals[0] @ [0, 0, 1] > 0.99  # the pole's normal still points along +z


def test_positions_and_pose_of_one_mesh_in_one_update_refused():
    scene = pyclpt.load("cornell-box")
    params = pyclpt.traverse(scene)
    params["small-box.to_world"] = tf.translate([0.1, 0, 0])
    params["small-box.vertex_positions"] = params["small-box.vertex_positions"] + 0.1
    with pytest.raises(ValueError, match="small-box.to_world and small-box.vertex_positions"):
        params.update()
    with pytest.raises(ValueError, match="small-box.to_world"):
        params.update({"small-box.to_world": np.diag([1.0, 0.0, 1.0, 1.0])})  # singular
    np.testing.assert_array_equal(params["small-box.to_world"], np.eye(4))


def test_sensor_to_world_and_x_fov():
    scene = pyclpt.load("cornell-box")
    params = pyclpt.traverse(scene)
    assert params["sensor.x_fov"][0] == pytest.approx(scene.camera.fov)  # a square film: any axis
    m = (scene.camera.to_world @ tf.translate([0.05, 0.02, 0.0]) @ tf.rotate([0, 1, 0], 3)).astype(np.float32)
    moved = copy.deepcopy(scene)
    moved.camera.to_world, moved.camera.fov, moved.camera.fov_axis = m, 30.0, "x"
    params.update({"sensor.to_world": m, "sensor.x_fov": 30.0})
    np.testing.assert_array_equal(pyclpt.render(scene, **KW), pyclpt.render(moved, **KW))
    # a fov along y reads as the horizontal one of the film's aspect
    scene.camera.fov, scene.camera.fov_axis = 40.0, "y"
    aspect = scene.film.width / scene.film.height
    x_fov = 2 * np.degrees(np.arctan(np.tan(np.radians(20.0)) * aspect))
    assert pyclpt.traverse(scene)["sensor.x_fov"][0] == pytest.approx(x_fov, rel=1e-5)


def _lights_and_instances() -> dict:
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": 60, "to_world": tf.look_at([0, 3, 6], [0, 0.5, 0]),
                    "film": {"type": "hdrfilm", "width": 24, "height": 24}},
         "group": {"type": "shapegroup", "id": "group", "ball": {"type": "sphere", "center": [0, 0.5, 0],
                                                                 "radius": 0.5}},
         "floor": {"type": "rectangle", "to_world": tf.scale(6) @ tf.rotate([1, 0, 0], -90)},
         "bulb": {"type": "point", "position": [1.0, 3.0, 1.0], "intensity": {"type": "rgb", "value": [20, 20, 20]}},
         "spot": {"type": "spot", "to_world": tf.look_at([-2, 3, 0], [0, 0, 0]), "cutoff_angle": 30,
                  "intensity": {"type": "rgb", "value": [30, 30, 30]}},
         "left": {"type": "instance", "shape": {"type": "ref", "id": "group"}, "to_world": tf.translate([-1, 0, 0])},
         "right": {"type": "instance", "shape": {"type": "ref", "id": "group"}, "to_world": tf.translate([1, 0, 0])}}
    return d


def test_lights_and_instances_move():
    d = _lights_and_instances()
    scene = pyclpt.load_dict(d)
    params = pyclpt.traverse(scene)
    np.testing.assert_allclose(params["spot.to_world"][:3, 3], [-2, 3, 0])
    moves = {"bulb.position": [0.5, 2.5, -1.0], "right.to_world": tf.translate([1.2, 0.3, 0]) @ tf.scale(0.7),
             "spot.to_world": tf.look_at([-2, 3, 1], [0.5, 0, 0])}
    moves = {k: np.asarray(v, np.float32).astype(np.float64) for k, v in moves.items()}  # values are float32
    params.update(moves)
    d["bulb"]["position"] = moves["bulb.position"]
    d["right"]["to_world"] = moves["right.to_world"]
    d["spot"]["to_world"] = moves["spot.to_world"]
    np.testing.assert_array_equal(pyclpt.render(scene, **KW), pyclpt.render(pyclpt.load_dict(d), **KW))


def test_gradient_renderer_rebuilds_its_bvh_without_compiling():
    """render_backward after a pose update: its kept copy of the scene gets the new BVH (refitted: the result
    equals a fresh copy's up to rounding) and no kernel is compiled for it."""
    differentiate.clear_cache()
    scene = pyclpt.load("cornell-box")
    grad = np.ones((16, 16, 3), np.float32)
    kw = dict(spp=2, seed=1, width=16, height=16, params=["white.reflectance.value"])
    before = pyclpt.render_backward(scene, grad, **kw)["white.reflectance.value"]
    params = pyclpt.traverse(scene)
    compiled = compile_seconds()
    params.update({"large-box.to_world": tf.translate([0.0, 0.3, 0.0])})
    moved = pyclpt.render_backward(scene, grad, **kw)["white.reflectance.value"]
    assert compile_seconds() == compiled
    differentiate.clear_cache()  # a fresh copy builds its BVH; the refitted tree gives the same paths, up to ties
    np.testing.assert_allclose(moved, pyclpt.render_backward(scene, grad, **kw)["white.reflectance.value"], rtol=1e-5)
    assert not np.array_equal(moved, before)


def test_refresh_geometry_keeps_the_kernels_of_a_renderer():
    scene = pyclpt.load("cornell-box")
    r = pyclpt.Renderer(scene, width=16, height=16, integrator="wavefront")
    r.render(spp=1, seed=2)
    params = pyclpt.traverse(scene)
    params.update({"light.to_world": tf.translate([0.0, -0.05, 0.1])})
    compiled = compile_seconds()
    uploaded = r.scene_buffers.refresh_geometry()
    assert {"BVH nodes", "triangles", "lights"} <= set(uploaded)  # the moved emitter: a new BVH, its records
    assert "materials" not in uploaded
    img = r.render(spp=1, seed=2)
    assert compile_seconds() == compiled
    np.testing.assert_array_equal(img, pyclpt.render(scene, spp=1, seed=2, width=16, height=16))


@pytest.mark.parametrize("device_class", ["cpu", "gpu"])
def test_refit_keeps_the_tree_and_contains_the_moved_triangles(device_class):
    """refit_bvh: with the positions unchanged, the BVH bit for bit; moved, the same links (the tree kept)
    and boxes that hold their triangles and children (the unions, as a build computes them)."""
    from pyclpt.accel.bvh import build_bvh, layout_settings, refit_bvh
    from pyclpt.buffers.scene import concat_meshes
    P, T, _, _ = concat_meshes(pyclpt.load("cornell-box").meshes)
    built = build_bvh(P, T, settings=layout_settings(device_class), use_cache=False)
    same = refit_bvh(built, P, T)
    np.testing.assert_array_equal(same.nodes, built.nodes)
    np.testing.assert_array_equal(same.tris, built.tris)
    moved = tf.apply_points(tf.rotate([0, 1, 0], 40) @ tf.scale([1, 2, 1]), P.astype(np.float64))
    r = refit_bvh(built, moved, T)
    lo, hi, links = r.children()
    np.testing.assert_array_equal(links, built.children()[2])
    verts = moved[T[r.tri_order]]  # (T, 3, 3) in leaf order
    for n in range(r.node_count):
        for c in range(r.width):
            link = int(links[n, c])
            if link >= 0:  # an inner child: exactly the union of its children
                clo, chi, _ = lo[link], hi[link], links[link]
                np.testing.assert_array_equal(lo[n, c], clo.min(0))
                np.testing.assert_array_equal(hi[n, c], chi.max(0))
            elif link & 31:
                first = (link & 0x7FFFFFFF) >> 5
                v = verts[first:first + (link & 31)].reshape(-1, 3)
                assert np.all(v >= lo[n, c]) and np.all(v <= hi[n, c])
    with pytest.raises(ValueError, match="holds 36 triangles, the mesh 35"):
        refit_bvh(built, moved, T[:-1])


def test_refresh_refits_and_builds_again_when_the_boxes_grow(monkeypatch, caplog):
    from pyclpt.accel import bvh as bvh_mod
    from pyclpt.buffers import scene as buffers_scene
    scene = pyclpt.load("cornell-box")
    r = pyclpt.Renderer(scene, width=16, height=16)
    links = r.scene_buffers.arrays.bvh.children()[2].copy()
    params = pyclpt.traverse(scene)
    params.update({"large-box.to_world": tf.translate([0.4, 0.0, 0.3]) @ tf.rotate([0, 1, 0], 50)})
    r.scene_buffers.refresh_geometry()  # refitted: the same tree
    np.testing.assert_array_equal(r.scene_buffers.arrays.bvh.children()[2], links)
    fresh = pyclpt.render(scene, spp=1, seed=4, width=16, height=16)
    np.testing.assert_array_equal(r.render(spp=1, seed=4), fresh)
    monkeypatch.setattr(buffers_scene, "REBUILD_GROWTH", 0.0)  # every refit "too loose": built again
    params.update({"large-box.to_world": np.eye(4)})
    with caplog.at_level("INFO", logger="pyclpt"):
        r.scene_buffers.refresh_geometry()
    assert "building it again" in caplog.text
    assert r.scene_buffers.built_area_ratio == bvh_mod.box_area_ratio(r.scene_buffers.arrays.bvh)
    np.testing.assert_array_equal(r.render(spp=1, seed=4), pyclpt.render(scene, spp=1, seed=4, width=16, height=16))
