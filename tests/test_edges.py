"""The boundary term of primary visibility (pyclpt/gradients/edges.py) against exact answers: a square
emitter moving over a constant background, a sphere's silhouette growing with its radius, and a
mutant (the edge normal flipped) that the first kills; silhouette extraction on a closed mesh."""
from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import pytest

import pyclpt
from pyclpt.gradients import edges, mirrors
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


def _scene(shape: dict, size: tuple[int, int] = (W, H), **others: dict) -> pyclpt.Scene:
    """An emitting ``shape`` (L_SHAPE, black otherwise) over the constant environment (L_BG), seen by a camera at
    DIST on +z looking at the origin, with the shapes ``others`` by name."""
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": FOV, "fov_axis": "x",
                   "to_world": tf.look_at([0, 0, DIST], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": size[0], "height": size[1], "rfilter": {"type": "box"}}},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": [L_BG] * 3}},
        **others,
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


# ---- outlines seen in a planar mirror ---------------------------------------------------------------------------

MIRROR_DEPTH = 3  # camera -> mirror -> the square's emission


def _mirror_scene(mirror: np.ndarray, square: np.ndarray, size: int = W) -> pyclpt.Scene:
    """The camera of :func:`_scene` before a perfect mirror (``conductor``'s default, eta 0 and k 1: reflectance 1 at
    every angle) posed by ``mirror``, and the emitting square posed by ``square`` out of the camera's view, seen
    only in the mirror, over the constant environment."""
    return _scene({"type": "rectangle", "to_world": square}, (size, size),
                  mirror={"type": "rectangle", "to_world": mirror, "bsdf": {"type": "conductor"}})


def test_square_seen_in_a_mirror(monkeypatch):
    """A mirror at 45 degrees through the origin (normal (1, 0, 1) / sqrt 2) turns the camera's view to +x: the
    square at x = 5 facing it is seen as from the virtual camera at (-5, 0, 0), 10 away, face on. Moving the square
    along +z moves its reflection along -x, to the left: d/dz of the left half's red sum = (L_square - L_background)
    x its height in pixels x pixels per unit at depth 10 (the left edge sweeps the half). The square is out of the
    camera's direct view: without the reflected outlines the term is 0. render_backward has it (its interior term
    is 0: the radiances are constant)."""
    scene = _mirror_scene(tf.rotate([0, 1, 0], 45) @ tf.scale(5.0),
                          tf.translate([5, 0, 0]) @ tf.rotate([0, 1, 0], -90) @ tf.scale(0.6))
    (plane,) = edges.mirror_planes(scene)
    assert plane.mesh == 0 and abs(abs(plane.normal @ np.array([1, 0, 1])) - math.sqrt(2)) < 1e-6
    names = ["shape.to_world", "shape.vertex_positions"]
    g = edges.primary_boundary(scene, _left_half(), names, samples=1 << 14, seed=1, max_depth=MIRROR_DEPTH)
    s = (W / 2) / (10 * math.tan(math.radians(FOV / 2)))
    exact = (L_SHAPE - L_BG) * (1.2 * s) * s
    assert g["shape.to_world"][2, 3] == pytest.approx(exact, rel=2e-3)
    assert g["shape.vertex_positions"].reshape(-1, 3)[:, 2].sum() == pytest.approx(exact, rel=1e-5)
    assert abs(g["shape.to_world"][1, 3]) < 1e-3 * exact  # moving up sweeps no more of the left half
    whole = pyclpt.render_backward(scene, _left_half(), spp=1, seed=5, max_depth=MIRROR_DEPTH,
                                   params=["shape.to_world"], edge_samples=1 << 12)  # the interior term is 0
    assert whole["shape.to_world"][2, 3] == pytest.approx(exact, rel=2e-3)
    monkeypatch.setattr(edges, "mirror_planes", lambda scene: [])
    direct = edges.primary_boundary(scene, _left_half(), names, samples=1 << 14, seed=1, max_depth=MIRROR_DEPTH)
    assert not direct["shape.to_world"].any()


#: A tilted mirror (no axis in its plane) and the square where the camera's reflected axis meets it, turned.
TILT = tf.rotate([1, 0, 0], 15) @ tf.rotate([0, 1, 0], 40)


def _tilted_scene(size: int = 32) -> pyclpt.Scene:
    m = TILT[:3, :3] @ np.array([0.0, 0.0, 1.0])
    axis = (np.eye(3) - 2 * np.outer(m, m)) @ np.array([0.0, 0.0, -1.0])  # the view axis, reflected
    at = 6.0 * axis + np.array([0.3, -0.2, 0.1])
    return _mirror_scene(TILT @ tf.scale(6.0), tf.look_at(at, [0, 0, 0], [0, 1, 0]) @ tf.rotate([0, 0, 1], 20)
                         @ tf.scale(0.7), size)


def test_tilted_mirror_against_finite_differences():
    """The square seen in a tilted mirror, a ramp-weighted image sum (x + 2 y) / 32: its derivative along a
    translation of the square and one of the camera (its to_world's last column), the boundary term (4 seeds of
    16,384 edge samples) against central differences of 2,048-spp renders (h = 0.3, 4 common seeds) within 3 %.
    The camera's term is taken where the camera sees the edge (its reflection), the square's through the
    reflection."""
    from pyclpt.gradients.parameters import traverse

    yy, xx = np.mgrid[0:32, 0:32]
    weight = np.zeros((32, 32, 3))
    weight[..., 0] = (xx + 2 * yy) / 32
    moves = {"shape.to_world": np.array([1.0, 0.5, -0.3]), "sensor.to_world": np.array([0.4, -0.6, 0.2])}
    scene = _tilted_scene()
    terms = [edges.primary_boundary(scene, weight, list(moves), samples=1 << 14, seed=s, max_depth=MIRROR_DEPTH)
             for s in range(4)]
    h = 0.3
    for name, d in moves.items():
        term = np.mean([float(t[name][:3, 3] @ d) for t in terms])
        sums = {}
        for sign in (1, -1):
            moved = _tilted_scene()
            params = traverse(moved)
            pose = np.asarray(params[name], np.float64).copy()
            pose[:3, 3] += sign * h * d
            params[name] = pose
            params.update()
            sums[sign] = [float((pyclpt.render(moved, spp=2048, seed=seed, max_depth=MIRROR_DEPTH) * weight).sum())
                          for seed in range(4)]
        fd = np.mean(np.subtract(sums[1], sums[-1])) / (2 * h)
        assert term == pytest.approx(fd, rel=0.03), (name, term, fd)


def test_forward_mode_agrees_with_reverse_mode_in_a_mirror():
    """sum(forward image x image gradient) = sum(reverse gradient x tangent) for the square seen in the tilted
    mirror: a vertex tangent, a pose tangent and the camera's; the forward images are not empty."""
    scene = _tilted_scene()
    rng = np.random.default_rng(7)
    grad = rng.random((32, 32, 3)).astype(np.float32)
    kw = dict(samples=4096, seed=3, max_depth=MIRROR_DEPTH)
    back = edges.primary_boundary(scene, grad, ["shape.vertex_positions", "shape.to_world"], **kw)
    cam = edges.primary_boundary(scene, grad, ["sensor.to_world"], **kw)["sensor.to_world"]
    tm = np.zeros((4, 4))
    tm[:3, 3], tm[1, 1] = [0.3, -1.0, 0.5], 0.5
    for name, tangent, want in (
            ("shape.vertex_positions", (tv := rng.normal(size=back["shape.vertex_positions"].shape)),
             float((back["shape.vertex_positions"] * tv).sum())),
            ("shape.to_world", tm, float((back["shape.to_world"] * tm).sum())),
            ("sensor.to_world", tm, float((cam * tm).sum()))):
        fwd = edges.primary_boundary_forward(scene, name, tangent, **kw)
        assert np.abs(fwd).sum() > 0
        assert float((fwd * grad).sum()) == pytest.approx(want, rel=1e-4), name


def test_mirror_planes():
    """A flat rectangle of smooth conductor is one mirror plane; a box six; a sphere (curved), a rough conductor's
    or a diffuse box, a bump-mapped mirror none; a thin dielectric's reflection in a mask counts."""
    def scene(shape: dict, bsdf: dict) -> pyclpt.Scene:
        return pyclpt.load_dict({"type": "scene", "sensor": {"type": "perspective"}, "s": {**shape, "bsdf": bsdf}})

    smooth = {"type": "conductor"}
    assert len(mirrors.mirror_planes(scene({"type": "rectangle", "to_world": TILT}, smooth))) == 1
    box = mirrors.mirror_planes(scene({"type": "cube", "to_world": TILT @ tf.scale([1, 2, 3])}, smooth))
    assert len(box) == 6 and all(len(p.faces) == 2 for p in box)
    normals = np.abs(np.array([p.normal for p in box]) @ TILT[:3, :3])  # the box's own axes
    assert np.allclose(np.sort(normals.max(1)), 1.0)
    assert mirrors.mirror_planes(scene({"type": "sphere"}, smooth)) == []
    assert mirrors.mirror_planes(scene({"type": "cube"}, {"type": "roughconductor", "alpha": 0.1})) == []
    assert mirrors.mirror_planes(scene({"type": "cube"}, {"type": "diffuse"})) == []
    masked = {"type": "mask", "opacity": 0.5, "bsdf": {"type": "thindielectric"}}
    assert len(mirrors.mirror_planes(scene({"type": "rectangle"}, masked))) == 1
    bumped = {"type": "bumpmap", "bsdf": smooth, "texture": {"type": "checkerboard"}}
    assert mirrors.mirror_planes(scene({"type": "rectangle"}, bumped)) == []


# ---- a planar mirror that moves: the outlines it shows move with it -------------------------------------------


def _ramp(size: int = 32) -> np.ndarray:
    """The red channel's weights (x + 2 y) / size of the tilted-mirror tests."""
    yy, xx = np.mgrid[0:size, 0:size]
    weight = np.zeros((size, size, 3))
    weight[..., 0] = (xx + 2 * yy) / size
    return weight


def _flat_mirror(scene: pyclpt.Scene) -> pyclpt.Scene:
    """``scene`` with its mirror (mesh 0) flat-shaded: no vertex normals, the renderer reflects about its faces'."""
    scene.meshes[0] = dataclasses.replace(scene.meshes[0], normals=None)
    return scene


def _render_moved(name: str, value: np.ndarray, seed: int, spp: int, flat: bool = False) -> float:
    """The ramp-weighted sum of the tilted-mirror scene rendered with parameter ``name`` set to ``value``."""
    from pyclpt.gradients.parameters import traverse

    moved = _tilted_scene()
    if flat:
        _flat_mirror(moved)
    params = traverse(moved)
    params[name] = value
    params.update()
    return float((pyclpt.render(moved, spp=spp, seed=seed, max_depth=MIRROR_DEPTH) * _ramp()).sum())


def _skew(a: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def test_moving_mirror_against_finite_differences(monkeypatch):
    """The still square seen in the tilted mirror, the mirror moved by its to_world: translated along its normal and
    turned about its own x axis (through the origin). The ramp-weighted sum's derivatives, the boundary term (4 seeds
    of 16,384 edge samples) against central differences of 4,096-spp renders (4 common seeds; steps 0.15 and 1.5
    degrees) within 3 %; render_backward (1 spp: the interior term is 0, the radiances constant) within 3 % too.
    Without the mirror's own motion (the outlines it shows held where they are), both are 0: its outline is out of
    view."""
    from pyclpt.gradients.parameters import traverse

    scene = _tilted_scene()
    (plane,) = edges.mirror_planes(scene)
    pose = np.asarray(traverse(scene)["mirror.to_world"], np.float64)
    axis = TILT[:3, 0]
    translate, turn = np.zeros((4, 4)), np.zeros((4, 4))
    translate[:3, 3] = plane.normal
    turn[:3] = _skew(axis) @ pose[:3]  # d/dangle of rotate(axis, angle) @ pose, per radian
    steps = {"translate": (0.15, lambda s: pose + s * 0.15 * translate),
             "turn": (math.radians(1.5), lambda s: tf.rotate(axis, s * 1.5) @ pose)}
    terms = [edges.primary_boundary(scene, _ramp(), ["mirror.to_world"], samples=1 << 14, seed=s,
                                    max_depth=MIRROR_DEPTH)["mirror.to_world"] for s in range(4)]
    whole = pyclpt.render_backward(scene, _ramp().astype(np.float32), spp=1, seed=7, max_depth=MIRROR_DEPTH,
                                   params=["mirror.to_world"], edge_samples=1 << 14)["mirror.to_world"]
    monkeypatch.setattr(edges, "reflection_velocity",
                        lambda proj, q, bary, point, normal, shading: (np.zeros((len(point), 3, 3)),) * 2)
    still = edges.primary_boundary(scene, _ramp(), ["mirror.to_world"], samples=1 << 14, seed=0,
                                   max_depth=MIRROR_DEPTH)["mirror.to_world"]
    for label, tangent in (("translate", translate), ("turn", turn)):
        h, at = steps[label]
        fd = np.mean([(_render_moved("mirror.to_world", at(1), s, 4096) - _render_moved("mirror.to_world", at(-1), s,
                                                                                         4096)) / (2 * h)
                      for s in range(4)])
        term = np.mean([float((t * tangent).sum()) for t in terms])
        assert term == pytest.approx(fd, rel=0.03), (label, term, fd)
        assert float((whole * tangent).sum()) == pytest.approx(fd, rel=0.03), (label, fd)
        assert abs(float((still * tangent).sum())) < 1e-3 * abs(fd), label


@pytest.mark.parametrize("flat", [False, True])
def test_moving_mirror_vertices(flat):
    """The mirror's vertex_positions: all four moved together along its normal is its to_world's translation (to
    1e-5); one corner moved alone along the normal bends the mirror, against central differences of renders (4 common
    seeds of 2,048 spp, step 0.3) within 3 %. Flat-shaded, each triangle reflects about its own plane (the corner
    tilts its triangle); smooth-shaded, about the vertex normals update() recomputes (the corner tilts the normals
    around it): the two differ by a factor of 6 here."""
    from pyclpt.gradients.parameters import traverse

    scene = _tilted_scene()
    if flat:
        _flat_mirror(scene)
    (plane,) = edges.mirror_planes(scene)
    terms = [edges.primary_boundary(scene, _ramp(), ["mirror.vertex_positions", "mirror.to_world"],
                                    samples=1 << 14, seed=s, max_depth=MIRROR_DEPTH) for s in range(4)]
    for t in terms:
        gv = t["mirror.vertex_positions"].reshape(-1, 3).astype(np.float64)
        assert float(gv.sum(0) @ plane.normal) == pytest.approx(float(t["mirror.to_world"][:3, 3] @ plane.normal),
                                                               rel=1e-5)
    rest = np.asarray(traverse(scene)["mirror.vertex_positions"], np.float64).reshape(-1, 3)
    h, corner = 0.3, 1
    step = np.zeros_like(rest)
    step[corner] = h * plane.normal
    fd = np.mean([(_render_moved("mirror.vertex_positions", (rest + step).reshape(-1), s, 2048, flat)
                   - _render_moved("mirror.vertex_positions", (rest - step).reshape(-1), s, 2048, flat)) / (2 * h)
                  for s in range(4)])
    term = np.mean([float(t["mirror.vertex_positions"].reshape(-1, 3)[corner] @ plane.normal) for t in terms])
    assert term == pytest.approx(fd, rel=0.03), (term, fd)


@pytest.mark.parametrize("flat", [False, True])
def test_forward_mode_agrees_with_reverse_mode_for_a_moving_mirror(flat):
    """sum(forward image x image gradient) = sum(reverse gradient x tangent) for the mirror's to_world and
    vertex_positions (random tangents: it bends, stretches and turns), flat- and smooth-shaded; the forward images
    are not empty."""
    scene = _tilted_scene()
    if flat:
        _flat_mirror(scene)
    rng = np.random.default_rng(11)
    grad = rng.random((32, 32, 3)).astype(np.float32)
    kw = dict(samples=4096, seed=3, max_depth=MIRROR_DEPTH)
    names = ["mirror.vertex_positions", "mirror.to_world"]
    back = edges.primary_boundary(scene, grad, names, **kw)
    for name in names:
        tangent = rng.normal(size=back[name].shape)
        fwd = edges.primary_boundary_forward(scene, name, tangent, **kw)
        assert np.abs(fwd).sum() > 0
        assert float((fwd * grad).sum()) == pytest.approx(float((back[name] * tangent).sum()), rel=1e-4), name


ORTHO_HALF = 1.5  # the orthographic camera's half-extent (world units) of its 48 x 48 film


def _ortho_scene() -> pyclpt.Scene:
    """_scene's square (half-extents 0.6 x 0.45) seen by an orthographic camera on the +z axis, to_world scaled
    by ORTHO_HALF: rays along -z from the 3 x 3 film rectangle, 16 pixels a unit."""
    scene = _scene({"type": "rectangle", "to_world": tf.scale([0.6, 0.45, 1.0])})
    scene.camera = pyclpt.Camera(tf.look_at([0, 0, DIST], [0, 0, 0], [0, 1, 0]) @ tf.scale([ORTHO_HALF] * 3),
                                 kind="orthographic")
    return scene


def test_orthographic_camera_moving_over_a_square():
    """An orthographic camera moving sideways over the square (or the square the other way): the image sum does
    not change, a weighted one (the red channel times each pixel's column centre) by exactly -(L_square - L_bg) x
    the square's height in pixels x pixels per unit x (its right edge's column - its left edge's): each edge sweeps
    its column. Moving along its axis changes nothing (its film positions do not depend on depth: a perspective
    projection's would). Forward mode equals reverse mode along a tangent that also turns and scales the camera;
    render_backward (max_depth 1) gives the same (the interior term is 0: constant radiances), and so does max_depth
    2 (the shadows' boundary terms run under an orthographic camera too: nothing to add, the square is black)."""
    scene = _ortho_scene()
    ppu = (W / 2) / ORTHO_HALF
    left, right = W / 2 - 0.6 * ppu, W / 2 + 0.6 * ppu  # 14.4 and 33.6: inside columns 14 and 33
    weight = np.zeros((H, W, 3), np.float32)
    weight[..., 0] = np.arange(W) + 0.5
    kw = dict(samples=1 << 15, seed=1)
    both = edges.primary_boundary(scene, weight, ["sensor.to_world", "shape.to_world"], **kw)
    g = both["sensor.to_world"]
    exact = -(L_SHAPE - L_BG) * (0.9 * ppu) * ppu * (math.floor(right) - math.floor(left))
    assert g[0, 3] == pytest.approx(exact, rel=2e-3)
    assert both["shape.to_world"][0, 3] == pytest.approx(-exact, rel=2e-3)  # the square moved the other way
    assert abs(g[1, 3]) < 1e-3 * abs(exact)  # moving up: the horizontal edges sweep whole rows, each row's sum 0
    assert abs(g[2, 3]) < 1e-3 * abs(exact)  # along its axis
    ones = edges.primary_boundary(scene, np.ones((H, W, 3), np.float32), ["sensor.to_world"], **kw)["sensor.to_world"]
    assert abs(ones[0, 3]) < 1e-3 * abs(exact)
    tm = np.zeros((4, 4))
    tm[0, 3], tm[1, 3], tm[2, 3] = 1.0, 0.3, -0.5
    tm[:3, :3] = 0.4 * np.array([[0, -1, 0], [1, 0, 0], [0, 0, 0]]) + 0.2 * np.eye(3)  # turn about z, grow
    grad = np.random.default_rng(5).random((H, W, 3)).astype(np.float32)
    back = edges.primary_boundary(scene, grad, ["sensor.to_world"], **kw)["sensor.to_world"]
    fwd = edges.primary_boundary_forward(scene, "sensor.to_world", tm, **kw)
    assert float((fwd * grad).sum()) == pytest.approx(float((back * tm).sum()), rel=1e-4)
    full = pyclpt.render_backward(scene, weight, spp=4, seed=1, max_depth=1, params=["sensor.to_world"],
                                  edge_samples=1 << 15)["sensor.to_world"]
    assert float(full[0, 3]) == pytest.approx(exact, rel=2e-3)  # the interior term: 0 (constant radiances)
    deeper = pyclpt.render_backward(scene, weight, spp=4, seed=1, max_depth=2, params=["sensor.to_world"],
                                    edge_samples=1 << 15, edge_spp=1)["sensor.to_world"]
    assert float(deeper[0, 3]) == pytest.approx(float(full[0, 3]), rel=1e-5)  # the soft term: 0 (a black square)
