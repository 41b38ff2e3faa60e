"""Gradients of where instances are (cl/gradients/geometry.h, -DGRAD_INSTANCES): an instance's ``to_world``
differentiated by the interior term (its triangles' points move by dT T^-1 x, their normals turn with the inverse
transpose, the gradient summed per instance record), on scenes whose visibility does not change (a floor much
larger than the view, instanced, under a point light out of view), against same-seed central differences through
``params.update()`` (as tests/test_interior.py), and reverse mode against forward mode along the tangent."""
from __future__ import annotations

import numpy as np
import pytest
from gradient_scenes import update_differences

import pyclpt
from pyclpt.gradients.placement import vertex_normals
from pyclpt.scene import transform as tf

W = H = 24


def _floor_group(smooth: bool, n: int = 16, size: float = 6.0) -> pyclpt.Mesh:
    """The floor in object space: a flat square (two triangles) or a smooth-shaded height field with its vertex
    normals (z = 0.08 sin 1.7x cos 1.3y)."""
    if not smooth:
        p = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32) * size
        return pyclpt.Mesh("floor", p, np.array([[0, 1, 2], [0, 2, 3]], np.int32), 0)
    x = np.linspace(-size, size, n + 1)
    gx, gy = np.meshgrid(x, x)
    p = np.stack([gx, gy, 0.08 * np.sin(1.7 * gx) * np.cos(1.3 * gy)], -1).reshape(-1, 3).astype(np.float32)
    a = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).reshape(-1)
    f = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)]).astype(np.int32)
    return pyclpt.Mesh("floor", p, f, 0, normals=vertex_normals(p, f))


def _instanced_floor(smooth: bool, pose: np.ndarray) -> pyclpt.Scene:
    """The floor's group placed by ``pose`` (instance "floor_i") and again far out of view (instance "other", the
    same group: its record stays still), a plain mesh (a small square out of view) beside them, a point light."""
    group = pyclpt.ShapeGroup("g", [_floor_group(smooth)])
    square = pyclpt.Mesh("aside", np.array([[20, 20, 0], [21, 20, 0], [21, 21, 0]], np.float32),
                         np.array([[0, 1, 2]], np.int32), 0)
    camera = pyclpt.Camera(tf.look_at([0.3, 0.2, 3.0], [0, 0, 0], [0, 1, 0]), fov=40)
    scene = pyclpt.Scene([square], [pyclpt.Diffuse((0.5, 0.6, 0.7))], camera, pyclpt.Film(W, H),
                         lights=[pyclpt.PointLight((-2.0, 0.5, 2.0), (10.0, 10.0, 10.0))])
    scene.groups = {"g": group}
    scene.instances = [pyclpt.Instance("g", pose, "floor_i"),
                       pyclpt.Instance("g", tf.translate([0, 0, -40.0]) @ pose, "other")]
    return scene


#: A turn about y, a translation and a non-uniform scale (the normals turn by the inverse transpose).
TANGENT = np.array([[0.2, 0.0, 0.3, 0.5], [0.0, -0.3, 0.0, 0.4], [-0.3, 0.0, 0.1, 0.3], [0, 0, 0, 0]])


@pytest.mark.parametrize("smooth", [False, True], ids=["flat", "smooth"])
def test_instance_to_world_interior(smooth):
    """An instanced floor's to_world (skewed and scaled: the normals turn by the inverse transpose): forward mode
    equals same-seed central differences through params.update() pixel by pixel (1e-2 of the largest at the 95th
    percentile, the differences' own noise at a smooth triangle's edge about 2e-2) and in total within 2 %;
    reverse mode equals forward mode along the tangent (1e-3)."""
    pose = tf.rotate([0, 0, 1], 20) @ np.diag([1.0, 1.3, 0.8, 1.0])
    scene = _instanced_floor(smooth, pose)
    params = pyclpt.traverse(scene)
    name = "floor_i.to_world"
    assert name in params.differentiable and "other.to_world" in params.differentiable
    fd, fwd = update_differences(scene, params, name, TANGENT, 1e-3)
    assert np.abs(fd).max() > 0.03
    err = np.abs(fwd - fd).max(-1)
    assert np.quantile(err, 0.95) < 1e-2 * np.abs(fd).max(), (np.quantile(err, 0.95), np.abs(fd).max())
    grad = np.random.default_rng(1).random((H, W, 3)).astype(np.float32)
    assert float((fwd * grad).sum()) == pytest.approx(float((fd * grad).sum()), rel=0.02)
    back = pyclpt.render_backward(scene, grad, spp=16, seed=3, max_depth=2, params=[name], boundary=False)
    g = back[name].astype(np.float64)
    assert np.all(g[3] == 0)
    assert float((g * TANGENT).sum()) == pytest.approx(float((fwd * grad).sum()), rel=1e-3)
    other = pyclpt.render_backward(scene, grad, spp=16, seed=3, max_depth=2, params=["other.to_world"],
                                   boundary=False)["other.to_world"]
    assert np.all(other == 0)  # out of view, though the same group


@pytest.mark.parametrize("smooth", [False, True], ids=["flat", "smooth"])
def test_instance_to_world_mirrored(smooth):
    """A mirroring instance (det < 0: surface_at's normal against its world edges' cross product) of the floor:
    forward mode equals the central differences, reverse mode forward mode."""
    scene = _instanced_floor(smooth, tf.rotate([0, 0, 1], 20) @ np.diag([-1.0, 1.3, 0.8, 1.0]))
    params = pyclpt.traverse(scene)
    fd, fwd = update_differences(scene, params, "floor_i.to_world", TANGENT, 1e-3)
    err = np.abs(fwd - fd).max(-1)
    assert np.quantile(err, 0.95) < 1e-2 * np.abs(fd).max(), (np.quantile(err, 0.95), np.abs(fd).max())
    grad = np.random.default_rng(2).random((H, W, 3)).astype(np.float32)
    assert float((fwd * grad).sum()) == pytest.approx(float((fd * grad).sum()), rel=0.02)
    back = pyclpt.render_backward(scene, grad, spp=16, seed=3, max_depth=2, params=["floor_i.to_world"],
                                  boundary=False)["floor_i.to_world"]
    assert float((back.astype(np.float64) * TANGENT).sum()) == pytest.approx(float((fwd * grad).sum()), rel=1e-3)


# ---- the boundary terms see instances (pyclpt/gradients/flatten.py) ----------------------------------------------

SQ_W, SQ_FOV, SQ_DIST, SQ_BG = 48, 40.0, 5.0, 0.25


def _black_square(instanced: bool) -> pyclpt.Scene:
    """A black square (0.8 x 0.6 half-sides) over a constant background, as a plain mesh or an instance."""
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": SQ_FOV, "fov_axis": "x",
                    "to_world": tf.look_at([0, 0, SQ_DIST], [0, 0, 0], [0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": SQ_W, "height": SQ_W, "rfilter": {"type": "box"}}},
         "env": {"type": "constant", "radiance": {"type": "rgb", "value": [SQ_BG] * 3}}}
    square = {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}}}
    if instanced:
        d["g"] = {"type": "shapegroup", "id": "g", "s": square}
        d["sq"] = {"type": "instance", "shape": {"type": "ref", "id": "g"}, "to_world": tf.scale([0.8, 0.6, 1.0])}
    else:
        d["sq"] = {**square, "to_world": tf.scale([0.8, 0.6, 1.0])}
    return pyclpt.load_dict(d)


def test_instance_silhouette_moving_over_the_background():
    """An instanced black square moving over a constant background, through render_backward (both terms): d/dx of
    the left half's red sum = L_background x the square's height in pixels x pixels per unit (exact), as for the
    same square as a plain mesh; forward mode along a move and a stretch equals reverse mode."""
    scene = _black_square(True)
    g = np.zeros((SQ_W, SQ_W, 3), np.float32)
    g[:, : SQ_W // 2, 0] = 1.0
    s = (SQ_W / 2) / (SQ_DIST * np.tan(np.radians(SQ_FOV / 2)))
    kw = dict(spp=4, seed=1, max_depth=1, edge_samples=1 << 15)
    back = pyclpt.render_backward(scene, g, params=["sq.to_world"], **kw)["sq.to_world"]
    assert back[0, 3] == pytest.approx(SQ_BG * 1.2 * s * s, rel=2e-3)
    plain = pyclpt.render_backward(_black_square(False), g, params=["sq.to_world"], **kw)["sq.to_world"]
    assert back[0, 3] == pytest.approx(plain[0, 3], rel=1e-4)
    d = np.zeros((4, 4))
    d[0, 3], d[1, 1] = 1.0, 0.3
    fwd = pyclpt.render_forward(scene, "sq.to_world", d, **kw)
    assert float((fwd * g).sum()) == pytest.approx(float((back * d).sum()), rel=1e-4)


OCC = tf.translate([-2, 0, 1.5]) @ tf.rotate([0, 0, 1], 25.0) @ tf.scale(0.3)


def _shadow_scene(instanced: bool, light: str = "point", size: int = 32) -> pyclpt.Scene:
    """tests/test_shadows.py's scene: a black square occluder out of view between a light (a point, or a 0.5 x 0.5
    area light) and a floor (a plain mesh); the occluder a plain mesh or an instance."""
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": 40.0, "fov_axis": "x",
                    "to_world": tf.look_at([0, 0, 3.0], [0, 0, 0], [0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}}},
         "floor": {"type": "rectangle", "to_world": tf.scale(6.0),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5] * 3}}}}
    if light == "point":
        d["light"] = {"type": "point", "position": [-4.0, 0.0, 3.0], "intensity": {"type": "rgb", "value": [20.0] * 3}}
    elif light == "spot":
        d["light"] = {"type": "spot", "to_world": tf.look_at([-4.0, 0.0, 3.0], [0, 0, 0], [0, 1, 0]),
                      "cutoff_angle": 30.0, "beam_width": 10.0, "intensity": {"type": "rgb", "value": [20.0] * 3}}
    else:
        d["light"] = {"type": "rectangle",
                      "to_world": tf.translate([-4.0, 0.0, 3.0]) @ tf.rotate([0, 1, 0], 180 - 53) @ tf.scale(0.25),
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [80.0] * 3}}}
    occluder = {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0] * 3}}}
    if instanced:
        d["g"] = {"type": "shapegroup", "id": "g", "s": occluder}
        d["occluder"] = {"type": "instance", "shape": {"type": "ref", "id": "g"}, "to_world": OCC}
    else:
        d["occluder"] = {**occluder, "to_world": OCC}
    return pyclpt.load_dict(d)


@pytest.mark.parametrize("light", ["point", "spot", "area"])
def test_instanced_scene_gradients_equal_the_plain_scene(light):
    """Every geometry parameter of an instanced scene (the occluder an instance), through render_backward
    (interior and boundary terms: silhouettes, hard shadows of the point and spot lights, soft shadows of the area
    light),
    equals the same scene with the occluder a plain mesh (the same samples: the boundary terms' host side sees the
    instance's triangles in world space): the floor's pose and vertices, the sensor's, the light's, and the
    occluder's, the instance's
    gradient G_T chained to the plain mesh's pose (the identity there, moving world points: dT = dM T, so
    G_M = G_T T^T); forward mode equals reverse mode along a tangent."""
    names = ["floor.to_world", "floor.vertex_positions", "sensor.to_world"]
    names += {"point": ["light.position"], "spot": ["light.to_world"]}.get(light, [])
    size = 16 if light == "area" else 32
    grad = np.random.default_rng(5).random((size, size, 3)).astype(np.float32)
    kw = dict(spp=4, seed=2, max_depth=2, edge_samples=1 << 12, edge_spp=4)
    inst = pyclpt.render_backward(_shadow_scene(True, light, size), grad, params=names + ["occluder.to_world"], **kw)
    plain = pyclpt.render_backward(_shadow_scene(False, light, size), grad, params=names + ["occluder.to_world"],
                                   **kw)
    for name in names:
        assert np.abs(inst[name] - plain[name]).max() <= 1e-4 * np.abs(plain[name]).max(), name
    occ = (inst["occluder.to_world"].astype(np.float64) @ OCC.T)[:3]
    assert np.abs(occ).max() > 1.0
    assert np.abs(occ - plain["occluder.to_world"][:3]).max() <= 1e-4 * np.abs(occ).max()
    scene = _shadow_scene(True, light, size)
    tangent = np.zeros((4, 4))
    tangent[:3, 3] = [1.0, 0.5, -0.2]
    tangent[:3, :3] = [[0.0, -0.3, 0.0], [0.3, 0.0, 0.0], [0.0, 0.0, 0.1]]
    back = pyclpt.render_backward(scene, grad, params=["occluder.to_world"], **kw)["occluder.to_world"]
    fwd = pyclpt.render_forward(scene, "occluder.to_world", tangent, **kw)
    assert float((fwd * grad).sum()) == pytest.approx(float((back * tangent).sum()), rel=1e-3)


def test_mirrored_instance_outline():
    """A white square over a constant background as a mirroring instance (x scaled by -0.8: the same square, its
    normal the transformed one, still facing the camera) and as a plain one (x scaled by 0.8): the boundary
    term of its x move (L_background - L_square) x height in pixels x pixels per unit, 5.2, is the same for both
    (within the edge samples' noise; the flattened mirror keeps its front by reversing its winding, else its outline
    would jump to black: 52)."""
    def scene(sx: float) -> pyclpt.Scene:
        d = {"type": "scene",
             "sensor": {"type": "perspective", "fov": SQ_FOV, "fov_axis": "x",
                        "to_world": tf.look_at([0, 0, SQ_DIST], [0, 0, 0], [0, 1, 0]),
                        "film": {"type": "hdrfilm", "width": SQ_W, "height": SQ_W, "rfilter": {"type": "box"}}},
             "env": {"type": "constant", "radiance": {"type": "rgb", "value": [SQ_BG] * 3}},
             "g": {"type": "shapegroup", "id": "g",
                   "s": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb",
                                                                                          "value": [0.9] * 3}}}},
             "sq": {"type": "instance", "shape": {"type": "ref", "id": "g"},
                    "to_world": tf.translate([0.1, 0, 0]) @ np.diag([sx, 0.6, 1.0, 1.0])}}
        return pyclpt.load_dict(d)

    g = np.zeros((SQ_W, SQ_W, 3), np.float32)
    g[:, : SQ_W // 2, 0] = 1.0
    kw = dict(spp=4, seed=1, max_depth=2, params=["sq.to_world"], edge_samples=1 << 15)
    mirrored = pyclpt.render_backward(scene(-0.8), g, **kw)["sq.to_world"][0, 3]
    plain = pyclpt.render_backward(scene(0.8), g, **kw)["sq.to_world"][0, 3]
    assert mirrored == pytest.approx(plain, rel=0.05) and 4.5 < plain < 6.0, (mirrored, plain)
