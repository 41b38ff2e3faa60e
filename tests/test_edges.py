"""The boundary term of primary visibility (pyclpt/gradients/edges.py) against exact answers: a square
emitter moving over a constant background, a sphere's silhouette growing with its radius, and a
mutant (the edge normal flipped) that the first kills; silhouette extraction on a closed mesh."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

import pyclpt
from pyclpt.gradients import edges
from pyclpt.scene import transform as tf
from pyclpt.scene.shapes import sphere

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # the examples of docs/differentiable.md: bench/evaluations/ beside pyclpt/
    sys.path.insert(0, str(REPO))
from bench.evaluations import inverse_pose, inverse_shape  # noqa: E402

W = H = 48
FOV = 40.0
DIST = 5.0
L_SHAPE, L_BG = 1.0, 0.25


def _scene(shape: dict) -> pyclpt.Scene:
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": FOV, "fov_axis": "x",
                   "to_world": tf.look_at([0, 0, DIST], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"}}},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": [L_BG] * 3}},
        "shape": {**shape, "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}},
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [L_SHAPE] * 3}}},
    })


def _pixels_per_unit() -> float:
    return (W / 2) / (DIST * math.tan(math.radians(FOV / 2)))


def _left_half() -> np.ndarray:
    g = np.zeros((H, W, 3), np.float32)
    g[:, : W // 2, 0] = 1.0  # the red channel of the image's left half
    return g


@pytest.mark.parametrize("flip", [False, True])
def test_square_moving_over_the_background(flip, monkeypatch):
    """d/dx of the left half's red sum = -(L_square - L_background) x the square's height in pixels x
    pixels per unit: the left edge sweeps the half, the right one stays outside it. The flipped edge
    normal (a mutant of the method) must fail."""
    scene = _scene({"type": "rectangle", "to_world": tf.scale([0.8, 0.6, 1.0])})
    if flip:
        real = edges.Projection.normal_velocity
        monkeypatch.setattr(edges.Projection, "normal_velocity", lambda self, p, n: real(self, p, -n))
    g = edges.primary_boundary(scene, _left_half(), ["shape.to_world", "shape.vertex_positions"],
                               samples=1 << 15, seed=1)
    s = _pixels_per_unit()
    exact = -(L_SHAPE - L_BG) * (1.2 * s) * s
    dx = g["shape.to_world"][0, 3]
    if flip:
        assert abs(dx - exact) > 0.5 * abs(exact)
        return
    assert dx == pytest.approx(exact, rel=2e-3)
    assert g["shape.vertex_positions"].reshape(-1, 3)[:, 0].sum() == pytest.approx(dx, rel=1e-5)
    assert abs(g["shape.to_world"][1, 3]) < 1e-3 * abs(exact)  # moving up sweeps no more of the left half


def test_sphere_silhouette_against_its_radius():
    """A sphere mesh of radius r at distance D on the axis: the image sum grows with r at (L_sphere - L_bg)
    d(area)/dr, the area of the projected disc pi rho^2, rho = pixels per unit x D tan(asin(r / D)) (a
    cone's tangent circle); the mesh's polygon outline is within 0.3% of the circle's at this tessellation."""
    r = 1.0
    mesh = sphere(rings=64, segments=128)
    scene = _scene({"type": "rectangle"})
    scene.meshes[0] = pyclpt.Mesh("ball", (mesh.positions * r).astype(np.float32), mesh.indices,
                                  scene.meshes[0].material, emission=scene.meshes[0].emission)
    g = edges.primary_boundary(scene, np.ones((H, W, 3), np.float32), ["ball.vertex_positions"], samples=1 << 15,
                               seed=2)
    gv = g["ball.vertex_positions"].reshape(-1, 3).astype(np.float64)
    d_radius = float((gv * mesh.positions).sum())  # positions = r x unit: d/dr = sum g . unit
    k = _pixels_per_unit() * DIST
    rho = k * math.tan(math.asin(r / DIST))
    drho = k / DIST / (1 - (r / DIST) ** 2) ** 1.5
    exact = 3 * (L_SHAPE - L_BG) * 2 * math.pi * rho * drho
    assert d_radius == pytest.approx(exact, rel=1e-2)


def test_silhouette_edges_of_a_closed_mesh():
    """A cube seen from a corner's direction: 6 silhouette edges (the hexagon), no boundary edges, whether its
    vertices are shared or split at its edges as the loader makes them (its edges are found by position; by index,
    each of its faces' 24 edges was a boundary edge, and the hexagon counted twice)."""
    box = pyclpt.load_dict({"type": "scene", "sensor": {"type": "perspective",
                            "to_world": tf.look_at([4, 3, 5], [0, 0, 0], [0, 1, 0]),
                            "film": {"type": "hdrfilm", "width": 32, "height": 32}},
                            "box": {"type": "cube", "to_world": tf.scale(0.5)}})
    mesh = box.meshes[0]
    p = mesh.positions
    # weld the cube's per-face vertices so that its edges are shared (the loader splits them for normals)
    uniq, inv = np.unique(p.round(6), axis=0, return_inverse=True)
    welded = pyclpt.Mesh("w", uniq.astype(np.float32), inv.reshape(-1)[mesh.indices], 0)
    pairs, count = edges.mesh_edges(welded, np.array([4.0, 3.0, 5.0]))
    assert len(pairs) == 6 and np.all(count == 2)
    split, count = edges.mesh_edges(mesh, np.array([4.0, 3.0, 5.0]))
    assert len(split) == 6 and np.all(count == 2)
    assert {tuple(sorted(e)) for e in inv.reshape(-1)[split]} == {tuple(sorted(e)) for e in pairs}


def test_forward_mode_agrees_with_reverse_mode():
    """For the same seed and size, sum(forward image x image gradient) = sum(reverse gradient x tangent), for
    a vertex tangent and a pose tangent; the forward image of the square's x move is its left and right
    edges, of opposite signs."""
    scene = _scene({"type": "rectangle", "to_world": tf.rotate([0, 0, 1], 20) @ tf.scale([0.8, 0.6, 1.0])})
    rng = np.random.default_rng(5)
    grad = rng.random((H, W, 3)).astype(np.float32)
    kw = dict(samples=4096, seed=3)
    back = edges.primary_boundary(scene, grad, ["shape.vertex_positions", "shape.to_world"], **kw)
    tv = rng.normal(size=back["shape.vertex_positions"].shape)
    fwd = edges.primary_boundary_forward(scene, "shape.vertex_positions", tv, **kw)
    assert float((fwd * grad).sum()) == pytest.approx(float((back["shape.vertex_positions"] * tv).sum()), rel=1e-4)
    tm = np.zeros((4, 4))
    tm[0, 3], tm[1, 1] = 1.0, 0.5  # move along x, stretch along y
    fwd = edges.primary_boundary_forward(scene, "shape.to_world", tm, **kw)
    assert float((fwd * grad).sum()) == pytest.approx(float((back["shape.to_world"] * tm).sum()), rel=1e-4)
    dx = edges.primary_boundary_forward(scene, "shape.to_world", np.eye(4)[[0]].T @ np.eye(4)[[3]], **kw)[..., 0]
    assert dx[:, : W // 2].sum() < 0 < dx[:, W // 2:].sum()  # the left edge uncovers, the right covers


def test_camera_translation_is_the_scene_moved_the_other_way():
    """Moving the sensor by +x in world space (its to_world's translation column) is the square moved by -x
    (the background is a constant environment: invariant): the gradients are opposite; forward mode agrees."""
    scene = _scene({"type": "rectangle", "to_world": tf.scale([0.8, 0.6, 1.0])})
    kw = dict(samples=1 << 14, seed=4)
    g = edges.primary_boundary(scene, _left_half(), ["sensor.to_world", "shape.to_world"], **kw)
    assert g["sensor.to_world"][0, 3] == pytest.approx(-g["shape.to_world"][0, 3], rel=1e-3)
    tm = np.zeros((4, 4))
    tm[0, 3] = 1.0
    fwd = edges.primary_boundary_forward(scene, "sensor.to_world", tm, **kw)
    assert float((fwd * _left_half()).sum()) == pytest.approx(float(g["sensor.to_world"][0, 3]), rel=1e-4)


def test_recover_a_pose_and_the_camera_from_an_image():
    """bench/evaluations/inverse_pose.py: the L plate's translation within 0.02, its angle within 1 degree and the
    camera's translation within 0.02 in 60 Adam steps (48x48, 16 spp), from errors of 0.35, 25 degrees and 0.3."""
    h = inverse_pose.recover(steps=60)
    pose, truth = np.array(h["pose"]), np.array(h["truth_pose"])
    assert np.abs(pose[:2] - truth[:2]).max() < 0.02
    assert abs(pose[2] - truth[2]) * 50 < 1.0
    assert np.abs(np.array(h["camera"]) - np.array(h["truth_camera"])).max() < 0.02
    assert h["losses"][-1] < 0.05 * h["losses"][0]


def test_recover_a_shape_from_five_views():
    """bench/evaluations/inverse_shape.py at a tiny size: a sphere mesh moves towards the target ellipsoid's surface
    (the mean relative radial distance down to 0.6 of the sphere's in 40 steps at 24x24, which bounds what its
    silhouettes resolve; 0.19 of it at 40x40 in 150 steps, docs/differentiable.md) and the images' loss falls."""
    h = inverse_shape.recover(steps=40, width=24, height=24, samples=4096, rings=8, segments=16, lr=0.04)
    assert h["vertex_error"][-1] < 0.6 * h["vertex_error"][0], h["vertex_error"][::10]
    assert h["losses"][-1] < 0.2 * h["losses"][0]


@pytest.mark.parametrize("kind, size", [("box", 0.0), ("tent", 1.0), ("tent", 1.5), ("gaussian", 0.5),
                                        ("gaussian", 0.3)])
def test_filter_weights_reach_every_pixel_of_the_filter(kind, size):
    """_filter_weights (ceil(2 radius) pixels a row from the first centre inside the radius) gives every pixel
    the dense evaluation of the filter gives, near the borders too: points anywhere, pixels on integer and
    half-integer offsets."""
    from pyclpt.buffers.rfilter import filter_eval

    rf = pyclpt.ReconstructionFilter(kind, **({"radius": size} if kind == "tent" else
                                             {"stddev": size} if kind == "gaussian" else {}))
    w, h = 7, 5
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.uniform(-1, [w + 1, h + 1], (400, 2)), rng.integers(0, 6, (40, 2)) * 0.5])
    pixels, weights, _ = edges._filter_weights(rf, x, w, h)
    got = np.zeros((len(x), h * w))
    np.add.at(got, (np.repeat(np.arange(len(x)), pixels.shape[1]), np.maximum(pixels, 0).ravel()),
              np.where(pixels >= 0, weights, 0.0).ravel())
    radius = {"box": 0.5, "tent": rf.radius, "gaussian": 4.0 * rf.stddev}[kind]
    grid = np.linspace(-radius, radius, 40001)
    norm = float(np.trapezoid(filter_eval(rf, grid), grid)) if kind != "box" else 1.0
    wx = filter_eval(rf, x[:, :1] - (np.arange(w) + 0.5)) / norm  # (N, w)
    wy = filter_eval(rf, x[:, 1:] - (np.arange(h) + 0.5)) / norm  # (N, h)
    dense = (wy[:, :, None] * wx[:, None, :]).reshape(len(x), -1)
    np.testing.assert_allclose(got, dense, rtol=0, atol=1e-12)
