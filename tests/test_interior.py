"""The interior term of moving geometry (cl/gradients/geometry.h, through render_backward and render_forward):
shading that follows moving surfaces and lights, on scenes whose visibility does not change (no outline moves in
the image or in any light), so that the interior term is the whole derivative.

With the same seed, the renders on either side of a small step take the same samples, so central differences
of the image are the derivative of the estimator itself: a gradient that differs from them by more than the
step's own error is wrong, pixel by pixel where the integrand is smooth (direct light). Indirect light through a
moved surface is compared over seeds. Mutants of the method (tests/mutate.py, "geometry-"): the far end's
cosine, the first hit sliding along its camera ray, the frame turning with the normal and the area Jacobian; a
moving mirror's reflected ray turning with its normal, its origin, its normal's adjoint and its Fresnel factor."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from gradient_scenes import update_differences

import pyclpt
from pyclpt.scene import transform as tf

W = H = 24
ROT_Y = np.array([[0, 0, 1, 0], [0, 0, 0, 0], [-1, 0, 0, 0], [0, 0, 0, 0]], np.float64)  # d R_y(a) / da at 0


def _floor_scene(move: np.ndarray | None = None, light: str = "point", light_move: np.ndarray | None = None,
                 bsdf: dict | None = None, ceiling: bool = False) -> pyclpt.Scene:
    """A floor much larger than the view under a light out of the camera's view (camera looking down from 3):
    no edge of anything in the image or in the light the floor receives. ``move``: a 4x4 applied to the floor,
    ``light_move`` to the light; ``ceiling``: a white ceiling at height 4 for indirect light."""
    move = np.eye(4) if move is None else move
    light_move = np.eye(4) if light_move is None else light_move
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": 40, "fov_axis": "x",
                    "to_world": tf.look_at([0, 0, 3], [0, 0, 0], [0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"}}},
         "floor": {"type": "rectangle", "to_world": move @ tf.scale(30.0),
                   "bsdf": bsdf or {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.6, 0.7]}}}}
    if light == "point":
        pos = (light_move @ np.array([-2.0, 0.5, 2.0, 1.0]))[:3]
        d["light"] = {"type": "point", "position": pos.tolist(), "intensity": {"type": "rgb", "value": [10.0] * 3}}
    elif light == "spot":  # its falloff (10 to 25 degrees) in view
        d["light"] = {"type": "spot", "to_world": light_move @ tf.look_at([0.5, 0.3, 2.0], [0, 0, 0], [0, 1, 0]),
                      "cutoff_angle": 25.0, "beam_width": 10.0,
                      "intensity": {"type": "rgb", "value": [30.0, 20.0, 10.0]}}
    else:
        frame = tf.translate([-2.0, 0.5, 2.0]) @ tf.rotate([0, 1, 0], 150) @ tf.scale(0.3)
        d["light"] = {"type": "rectangle", "to_world": light_move @ frame,
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [40.0] * 3}}}
    if ceiling:
        up = tf.translate([0, 0, 4]) @ tf.rotate([1, 0, 0], 180) @ tf.scale(30.0)
        d["ceiling"] = {"type": "rectangle", "to_world": up,
                        "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8] * 3}}}
    return pyclpt.load_dict(d)


def _central(make, tangent: np.ndarray, h: float, spp: int, seed: int, depth: int) -> np.ndarray:
    """(render(M(h)) - render(M(-h))) / 2h, M(s) = I + s tangent, a rotation for a rotation's generator, the same
    seed on both sides."""
    def moved(s: float) -> np.ndarray:
        m = np.eye(4) + s * tangent
        k = tangent[:3, :3]
        if np.any(k) and np.allclose(k, -k.T):  # a rotation's generator: the rotation (Rodrigues)
            m[:3, :3] = np.eye(3) + np.sin(s) * k + (1 - np.cos(s)) * (k @ k)
        return pyclpt.render(make(m), spp=spp, seed=seed, max_depth=depth).astype(np.float64)
    return (moved(h) - moved(-h)) / (2 * h)


def _backward_along(scene: pyclpt.Scene, name: str, tangent: np.ndarray, grad: np.ndarray, **kw) -> float:
    g = pyclpt.render_backward(scene, grad, params=[name], boundary=False, **kw)[name]
    return float((g.astype(np.float64) * tangent).sum())


@pytest.mark.parametrize("motion", ["translate", "rotate"])
def test_floor_moving_under_a_point_light(motion):
    """Direct light from a point light on a moving floor (its first hits slide along the camera rays): forward
    mode equals the same-seed central differences pixel by pixel (to 1e-3 of the largest), reverse mode equals
    forward mode along the tangent."""
    tangent = np.zeros((4, 4))
    if motion == "translate":
        tangent[2, 3] = 1.0
    else:
        tangent = ROT_Y.copy()
    scene = _floor_scene()
    fwd = pyclpt.render_forward(scene, "floor.to_world", tangent, spp=16, seed=3, max_depth=2,
                                boundary=False).astype(np.float64)
    fd = _central(lambda m: _floor_scene(m), tangent, 1e-2, 16, 3, 2)
    assert np.abs(fwd - fd).max() < 1e-3 * np.abs(fd).max()
    grad = np.random.default_rng(1).random((H, W, 3)).astype(np.float32)
    back = _backward_along(scene, "floor.to_world", tangent, grad, spp=16, seed=3, max_depth=2)
    assert back == pytest.approx(float((fwd * grad).sum()), rel=1e-4)


def test_floor_rotating_under_an_area_light():
    """The issue's interior-only case: a plane rotating under an area light, against same-seed central
    differences: the image sum within 0.5 %, 6x6-pixel blocks within 2 % of the largest (single pixels jump in
    the differences, where a BSDF sample that turns with the floor crosses the light's edge); forward = backward."""
    scene = _floor_scene(light="area")
    fwd = pyclpt.render_forward(scene, "floor.to_world", ROT_Y, spp=64, seed=3, max_depth=2,
                                boundary=False).astype(np.float64)
    fd = _central(lambda m: _floor_scene(m, light="area"), ROT_Y, 0.005, 64, 3, 2)
    assert fwd.sum() == pytest.approx(fd.sum(), rel=5e-3)
    blocks = [x.reshape(H // 6, 6, W // 6, 6, 3).sum(axis=(1, 3)) for x in (fwd, fd)]
    assert np.abs(blocks[0] - blocks[1]).max() < 0.02 * np.abs(blocks[1]).max()
    grad = np.ones((H, W, 3), np.float32)
    assert _backward_along(scene, "floor.to_world", ROT_Y, grad, spp=64, seed=3, max_depth=2) == pytest.approx(
        float(fwd.sum()), rel=1e-4)


@pytest.mark.parametrize("light", ["point", "area"])
def test_moving_lights(light):
    """A point light's position and an area light's pose, each axis: the image sum's derivative equals the
    same-seed central differences (2e-3 relative), in both modes; the area light's growth (its area Jacobian:
    the same radiance from a larger emitter) too."""
    scene = _floor_scene(light=light)
    name = "light.position" if light == "point" else "light.to_world"
    ones = np.ones((H, W, 3), np.float32)
    back = pyclpt.render_backward(scene, ones, spp=32, seed=4, max_depth=2, params=[name], boundary=False)[name]
    tangents = []
    for k in range(3):
        t = np.zeros((4, 4))
        t[k, 3] = 1.0
        tangents.append(t)
    if light == "area":
        stretch = np.zeros((4, 4))
        stretch[0, 0] = 1.0  # stretched along x about the origin: the light moves and grows
        tangents.append(stretch)
    for t in tangents:
        fd = _central(lambda m: _floor_scene(light=light, light_move=m), t, 1e-2, 32, 4, 2).sum()
        along = t[:3, 3] if light == "point" else t
        fwd = pyclpt.render_forward(scene, name, along, spp=32, seed=4, max_depth=2, boundary=False).sum()
        assert fwd == pytest.approx(fd, rel=2e-3)
        assert float((back.astype(np.float64) * along).sum()) == pytest.approx(float(fwd), rel=1e-4)


@pytest.mark.parametrize("bsdf", [
    {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.6, 0.7]}},
    {"type": "roughconductor", "alpha": 0.3},
    {"type": "roughplastic", "alpha": 0.2, "diffuse_reflectance": {"type": "rgb", "value": [0.5, 0.3, 0.2]}},
], ids=["diffuse", "roughconductor", "roughplastic"])
def test_indirect_light_through_a_moving_floor(bsdf):
    """Light from a point light bounced off a ceiling onto a tilting floor of three materials (depth 3: the
    floor's BSDF turns with it, the ceiling's points see the floor move): the image sum's derivative against
    central differences, both averaged over two seeds at 256 spp, within 2 %; forward = backward."""
    scene = _floor_scene(bsdf=bsdf, ceiling=True)
    fwd, fd = [], []
    for seed in (5, 6):
        fwd.append(pyclpt.render_forward(scene, "floor.to_world", ROT_Y, spp=256, seed=seed, max_depth=3,
                                         boundary=False).astype(np.float64).sum(axis=(0, 1)))
        fd.append(_central(lambda m: _floor_scene(m, bsdf=bsdf, ceiling=True), ROT_Y, 0.005, 256, seed, 3)
                  .sum(axis=(0, 1)))
    f, d = np.mean(fwd, axis=0), np.mean(fd, axis=0)
    assert np.allclose(f, d, rtol=0.02), (f, d)
    ones = np.ones((H, W, 3), np.float32)
    back = _backward_along(scene, "floor.to_world", ROT_Y, ones, spp=256, seed=6, max_depth=3)
    assert back == pytest.approx(float(fwd[1].sum()), rel=2e-3)


def test_vertex_positions_and_pose_agree():
    """A flat mesh's vertex_positions gradient chained through a pose is the pose's gradient (the interior term
    is computed per vertex; the pose's gradient is its chain)."""
    scene = _floor_scene(light="area")
    scene.meshes[0].normals = None  # the rectangle's normals are its face's: flat either way
    grad = np.random.default_rng(2).random((H, W, 3)).astype(np.float32)
    g = pyclpt.render_backward(scene, grad, spp=16, seed=1, max_depth=2, boundary=False,
                               params=["floor.vertex_positions", "floor.to_world"])
    gv = g["floor.vertex_positions"].reshape(-1, 3).astype(np.float64)
    p = scene.meshes[0].positions.astype(np.float64)
    assert np.allclose(g["floor.to_world"][:3, 3], gv.sum(0), rtol=1e-5, atol=1e-6)
    assert np.allclose(g["floor.to_world"][:3, :3], gv.T @ p, rtol=1e-4, atol=1e-4 * np.abs(gv.T @ p).max())


def _bumpy_floor(n: int = 24, size: float = 6.0) -> pyclpt.Scene:
    """A smooth-shaded height field (z = 0.08 sin 1.7x cos 1.3y, its angle-weighted vertex normals, as update()
    writes them) much larger than the view, under a point light out of view: nothing in view or in the light
    has an outline, and the shading is the vertex normals'."""
    from pyclpt.gradients.placement import vertex_normals

    x = np.linspace(-size, size, n + 1)
    gx, gy = np.meshgrid(x, x)
    p = np.stack([gx, gy, 0.08 * np.sin(1.7 * gx) * np.cos(1.3 * gy)], -1).reshape(-1, 3).astype(np.float32)
    a = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).reshape(-1)
    f = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)]).astype(np.int32)
    mesh = pyclpt.Mesh("floor", p, f, 0, normals=vertex_normals(p, f))
    camera = pyclpt.Camera(tf.look_at([0.3, 0.2, 3.0], [0, 0, 0], [0, 1, 0]), fov=40)
    return pyclpt.Scene([mesh], [pyclpt.Diffuse((0.5, 0.6, 0.7))], camera, pyclpt.Film(W, H),
                        lights=[pyclpt.PointLight((-2.0, 0.5, 2.0), (10.0, 10.0, 10.0))])


@pytest.mark.parametrize("name", ["floor.to_world", "floor.vertex_positions"])
def test_smooth_shaded_floor(name):
    """A smooth-shaded floor sliding under the camera (to_world: a translation and a turn; its shading normals
    pass under the pixels: the hits' barycentrics move) and deformed (vertex_positions: the normals update()
    recomputes follow): forward mode equals same-seed central differences through params.update() pixel by
    pixel (to 1e-2 of the largest at the 95th percentile, the differences' own noise at a triangle's edge being
    about 2e-2), and in total within 2 %; reverse mode equals forward mode along the tangent."""
    scene = _bumpy_floor()
    params = pyclpt.traverse(scene)
    base = np.asarray(params[name], np.float64)
    if name.endswith("to_world"):
        tangent = 0.3 * ROT_Y
        tangent[0, 3], tangent[1, 3] = 1.0, 0.5
    else:
        p = base.reshape(-1, 3)
        tangent = np.zeros_like(p)
        tangent[:, 2] = np.cos(0.9 * p[:, 0] + 0.4 * p[:, 1])
        tangent = tangent.reshape(-1)
    fd, fwd = update_differences(scene, params, name, tangent, 1e-3)
    err = np.abs(fwd - fd).max(-1)
    assert np.quantile(err, 0.95) < 1e-2 * np.abs(fd).max(), (np.quantile(err, 0.95), np.abs(fd).max())
    grad = np.random.default_rng(1).random((H, W, 3)).astype(np.float32)
    assert float((fwd * grad).sum()) == pytest.approx(float((fd * grad).sum()), rel=0.02)
    back = pyclpt.render_backward(scene, grad, spp=16, seed=3, max_depth=2, params=[name], boundary=False)[name]
    assert float((back.astype(np.float64) * tangent.reshape(back.shape)).sum()) == pytest.approx(
        float((fwd * grad).sum()), rel=1e-3)


def _spot_angles(scene: pyclpt.Scene) -> np.ndarray:
    """(H, W): the angle in degrees from the spot light's axis of each pixel centre's point on the floor (z = 0)."""
    o, f, r, u = scene.camera.basis(W, H)
    sx, sy = np.meshgrid(2 * (np.arange(W) + 0.5) / W - 1, 1 - 2 * (np.arange(H) + 0.5) / H)
    d = f + sx[..., None] * r + sy[..., None] * u
    p = o - (o[2] / d[..., 2])[..., None] * d
    wi = np.asarray(scene.lights[0].position) - p
    wi /= np.linalg.norm(wi, axis=-1, keepdims=True)
    return np.degrees(np.arccos(-wi @ np.asarray(scene.lights[0].direction)))


@pytest.mark.parametrize("motion", ["translate", "turn"])
def test_spot_light_moving(motion):
    """A spot light over the floor, its falloff (10 to 25 degrees from the axis) in view, its to_world moved (its
    position: 1 / r^2 and the falloff's angle) or turned about its position (the falloff's axis). Forward mode
    equals same-seed central differences through params.update() pixel by pixel, to 1e-3 of the largest, away
    from the two rings where the falloff has a kink (pixels within 1.5 degrees of them: there the differences
    straddle it, 2 % off); reverse mode equals forward mode along the tangent."""
    scene = _floor_scene(light="spot")
    params = pyclpt.traverse(scene)
    name = "light.to_world"
    base = np.asarray(params[name], np.float64)
    tangent = np.zeros((4, 4))
    if motion == "translate":
        tangent[:3, 3] = [0.4, -0.3, 0.2]
    else:
        tangent[:3, :3] = np.array([[0, 0, 1], [0, 0, 0], [-1, 0, 0]], np.float64) @ base[:3, :3]
    fd, fwd = update_differences(scene, params, name, tangent, 3e-4)
    angle = _spot_angles(scene)
    smooth = (np.abs(angle - 10.0) > 1.5) & (np.abs(angle - 25.0) > 1.5)
    assert np.abs(fd[smooth]).max() > 1.0 and (angle[smooth] > 10).sum() > 100
    assert np.abs(fwd - fd)[smooth].max() < 1e-3 * np.abs(fd).max(), (np.abs(fwd - fd)[smooth].max(), np.abs(fd).max())
    grad = np.random.default_rng(1).random((H, W, 3)).astype(np.float32)
    back = pyclpt.render_backward(scene, grad, spp=16, seed=3, max_depth=2, params=[name], boundary=False)[name]
    assert float((back.astype(np.float64) * tangent).sum()) == pytest.approx(float((fwd * grad).sum()), rel=1e-3)


def test_normals_update_writes_are_differentiated():
    """pyclpt.gradients.normals against central differences in float64: the angle-weighted normals of moved
    positions and the normals a pose carries; each adjoint is its tangent's transpose."""
    from pyclpt.gradients import normals as nm
    from pyclpt.gradients.placement import vertex_normals
    from pyclpt.scene.shapes import sphere

    rng = np.random.default_rng(4)
    s = sphere(rings=6, segments=10)
    f = s.indices
    used = np.unique(f)
    p = s.positions.astype(np.float64) + 0.05 * rng.standard_normal(s.positions.shape)
    m, n = nm.angle_weighted(p, f)
    assert np.abs(n[used] - vertex_normals(p, f)[used]).max() < 1e-6
    dp, g = rng.standard_normal(p.shape), rng.standard_normal(p.shape)
    h = 1e-6
    fd = (nm.angle_weighted(p + h * dp, f)[1] - nm.angle_weighted(p - h * dp, f)[1]) / (2 * h)
    jvp = nm.angle_weighted_jvp(p, f, dp)
    assert np.abs(jvp - fd).max() < 1e-6 * np.abs(fd).max()
    assert float((g * jvp).sum()) == pytest.approx(float((nm.angle_weighted_vjp(p, f, g) * dp).sum()), rel=1e-9)
    mat = np.eye(4)
    mat[:3, :3] = [[1.2, 0.1, 0.0], [0.3, 0.9, 0.2], [0.0, 0.1, 1.1]]
    dm = rng.standard_normal((4, 4))
    rest = n[used]
    gn = g[used]

    def carried(x: np.ndarray) -> np.ndarray:  # tf.apply_normals in float64: what update() does with a pose
        u = rest @ np.linalg.inv(x[:3, :3])
        return u / np.linalg.norm(u, axis=1, keepdims=True)

    assert np.abs(carried(mat) - tf.apply_normals(mat, rest)).max() < 1e-6
    fd = (carried(mat + h * dm) - carried(mat - h * dm)) / (2 * h)
    jvp = nm.transformed_jvp(mat, rest, dm)
    assert np.abs(jvp - fd).max() < 1e-6 * np.abs(fd).max()
    assert float((gn * jvp).sum()) == pytest.approx(float((nm.transformed_vjp(mat, rest, gn) * dm).sum()), rel=1e-9)


def test_what_is_not_differentiated_says_why():
    """Textured meshes (plain or instanced) and thin lenses are listed with the reason; render_backward refuses
    them; the default parameter set leaves geometry out (it is named to be differentiated)."""
    scene = _floor_scene()
    params = pyclpt.traverse(scene)
    assert "floor.to_world" in params.differentiable and "floor.vertex_positions" in params.differentiable
    assert "sensor.to_world" in params.differentiable and "sensor.x_fov" in params.differentiable
    g = pyclpt.render_backward(scene, np.ones((H, W, 3), np.float32), spp=1, seed=1, max_depth=2)
    assert not any(n.endswith((".to_world", ".position", ".vertex_positions")) for n in g)
    textured = _floor_scene(bsdf={"type": "diffuse", "reflectance": {"type": "checkerboard"}})
    assert "textured" in pyclpt.traverse(textured).unsupported()["floor.to_world"]
    with pytest.raises(ValueError, match="textured"):
        pyclpt.render_backward(textured, np.ones((H, W, 3), np.float32), spp=1, seed=1, params=["floor.to_world"])
    lens = _floor_scene()
    lens.camera = dataclasses.replace(lens.camera, kind="thinlens", aperture_radius=0.05, focus_distance=3.0)
    assert "perspective" in pyclpt.traverse(lens).unsupported()["sensor.to_world"]
    instanced = pyclpt.load_dict({  # instances are differentiated (tests/test_instance_gradients.py) unless textured
        "type": "scene", "floor": {"type": "rectangle"},
        "group": {"type": "shapegroup", "id": "group", "ball": {"type": "sphere", "radius": 0.5}},
        "left": {"type": "instance", "shape": {"type": "ref", "id": "group"}, "to_world": tf.translate([-1, 0, 0])},
        "tgroup": {"type": "shapegroup", "id": "tgroup",
                   "box": {"type": "cube", "bsdf": {"type": "diffuse", "reflectance": {"type": "checkerboard"}}}},
        "right": {"type": "instance", "shape": {"type": "ref", "id": "tgroup"}, "to_world": tf.translate([1, 0, 0])}})
    params = pyclpt.traverse(instanced)
    for name in ("floor.to_world", "left.to_world"):
        assert name in params.differentiable, (name, params.unsupported().get(name))
    assert "textured" in params.unsupported()["right.to_world"]
    instanced.groups["tgroup"].meshes[0].material = instanced.materials.index(instanced.materials[0])
    instanced.materials = [instanced.materials[0]]
    params = pyclpt.traverse(instanced)
    for name in ("floor.to_world", "left.to_world", "right.to_world", "sensor.to_world"):
        assert name in params.differentiable, (name, params.unsupported().get(name))


def _lit_square(m: np.ndarray | None = None) -> pyclpt.Scene:
    """A diffuse square turned 20 degrees, lit by a point light from the camera's side, over a constant sky."""
    m = np.eye(4) if m is None else m
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 40, "fov_axis": "x",
                   "to_world": tf.look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 32, "height": 32, "rfilter": {"type": "box"}}},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": [0.25] * 3}},
        "light": {"type": "point", "position": [1.0, 1.0, 4.0], "intensity": {"type": "rgb", "value": [30.0] * 3}},
        "shape": {"type": "rectangle", "to_world": m @ tf.rotate([0, 1, 0], 20) @ tf.scale([0.8, 0.6, 1.0]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.5, 0.4]}}},
    })


def test_both_terms_make_the_derivative():
    """The square moving towards the camera: its outline grows over the sky (the boundary term) and its shading
    changes as it nears the light (the interior term). Their sum, by render_forward and render_backward, equals
    central differences of 1,024-spp renders (two seeds, the edge moving about a pixel) within 3 %; either term
    alone is far off (the interior alone: about 0.7 of it)."""
    t = np.zeros((4, 4))
    t[2, 3] = 1.0
    scene = _lit_square()
    full = pyclpt.render_forward(scene, "shape.to_world", t, spp=64, seed=1, max_depth=2, edge_samples=1 << 16)
    inner = pyclpt.render_forward(scene, "shape.to_world", t, spp=64, seed=1, max_depth=2, boundary=False)
    h, fd = 0.02, 0.0
    for seed in (7, 8):
        plus = pyclpt.render(_lit_square(np.eye(4) + h * t), spp=1024, seed=seed, max_depth=2).astype(np.float64)
        minus = pyclpt.render(_lit_square(np.eye(4) - h * t), spp=1024, seed=seed, max_depth=2).astype(np.float64)
        fd += (plus - minus).sum() / (2 * h) / 2
    assert float(full.sum()) == pytest.approx(fd, rel=0.03)
    assert abs(float(inner.sum()) - fd) > 0.2 * abs(fd)
    back = pyclpt.render_backward(scene, np.ones((32, 32, 3), np.float32), spp=64, seed=1, max_depth=2,
                                  params=["shape.to_world"], edge_samples=1 << 16)["shape.to_world"]
    assert float(back[2, 3]) == pytest.approx(float(full.sum()), rel=1e-3)


@pytest.mark.parametrize("name", ["sensor.to_world", "sensor.x_fov"])
def test_moving_camera(name):
    """The camera moving sideways and zooming over a glossy floor under an area light (its rays' hits slide and
    their incident directions turn): the image sum's derivative against same-seed central differences within
    2 % (the differences' own spread: BSDF samples crossing the light's edge), forward = backward. The lit square's
    outline moves too when the camera nears it or zooms: the boundary term joins, against 1,024-spp differences
    within 3 %."""
    glossy = {"type": "roughconductor", "alpha": 0.3}
    scene = _floor_scene(light="area", bsdf=glossy)
    if name.endswith("to_world"):
        tangent = np.zeros((4, 4))
        tangent[0, 3] = 1.0

        def moved(s, make=lambda: _floor_scene(light="area", bsdf=glossy)):
            out = make()
            out.camera.to_world = out.camera.to_world + s * tangent
            return out
        h = 1e-2
    else:
        tangent = np.ones(1)

        def moved(s, make=lambda: _floor_scene(light="area", bsdf=glossy)):
            out = make()
            out.camera.fov = 40.0 + s
            return out
        h = 0.2
    fwd = pyclpt.render_forward(scene, name, tangent, spp=64, seed=3, max_depth=2).astype(np.float64).sum()
    fd = sum((pyclpt.render(moved(s), spp=64, seed=3, max_depth=2).astype(np.float64).sum() * k
              for s, k in ((h, 1), (-h, -1)))) / (2 * h)
    assert fwd == pytest.approx(fd, rel=0.02)
    ones = np.ones((H, W, 3), np.float32)
    back = pyclpt.render_backward(scene, ones, spp=64, seed=3, max_depth=2, params=[name])[name]
    assert float((back * tangent).sum()) == pytest.approx(fwd, rel=1e-4)
    if name.endswith("to_world"):  # towards the square (sideways, its two edges' terms nearly cancel)
        tangent = np.zeros((4, 4))
        tangent[2, 3] = -1.0
    square = _lit_square()
    full = pyclpt.render_forward(square, name, tangent, spp=64, seed=1, max_depth=2).astype(np.float64).sum()
    fd = 0.0
    for seed in (7, 8):
        for s, k in ((h, 1), (-h, -1)):
            out = moved(s, _lit_square)
            fd += k * pyclpt.render(out, spp=1024, seed=seed, max_depth=2).astype(np.float64).sum() / (4 * h)
    assert full == pytest.approx(fd, rel=0.03)


def _soft_shadow(move: np.ndarray | None = None, camera: np.ndarray | None = None) -> pyclpt.Scene:
    """tests/test_shadows.py's soft shadow (a black square between a rectangle light and a floor, out of view),
    the floor moved by ``move`` (a 4x4), the camera's to_world moved by ``camera`` (added)."""
    from test_shadows import _soft_scene

    scene = _soft_scene(size=24)
    if move is not None:
        floor = next(m for m in scene.meshes if m.name == "floor")
        floor.positions = (floor.positions.astype(np.float64) @ move[:3, :3].T + move[:3, 3]).astype(np.float32)
    if camera is not None:
        scene.camera.to_world = scene.camera.to_world + camera
    return scene


@pytest.mark.parametrize("name", ["floor.to_world", "sensor.to_world"])
def test_receiver_moving_under_a_soft_shadow(name):
    """The floor rising under the square's soft shadow, and the camera moving sideways over it: the shading points
    move against the static occluder's outline (and against the light behind it, whose points move with the
    light in the interior term: the outline's motion relative to them is the boundary term's). Interior plus
    boundary (256 shading points a pixel, the mean of eight seeds: one seed's spread is about 6 % here) against
    central differences of 4,096-spp renders over two seeds (h = 0.03) within 6 %; forward = backward."""
    t = np.zeros((4, 4))
    t[2 if name.startswith("floor") else 0, 3] = 1.0
    scene = _soft_shadow()
    kw = dict(spp=64, max_depth=2, edge_spp=256)
    fulls = [pyclpt.render_forward(scene, name, t, seed=seed, **kw).astype(np.float64).sum() for seed in range(1, 9)]
    full = float(np.mean(fulls))
    h, fd = 0.03, 0.0
    for seed in (7, 8):
        for s, k in ((h, 1), (-h, -1)):
            moved = _soft_shadow(np.eye(4) + s * t) if name.startswith("floor") else _soft_shadow(camera=s * t)
            fd += k * pyclpt.render(moved, spp=4096, seed=seed, max_depth=2).astype(np.float64).sum() / (4 * h)
    assert full == pytest.approx(fd, rel=0.06)
    back = pyclpt.render_backward(scene, np.ones((24, 24, 3), np.float32), params=[name], seed=1, **kw)[name]
    assert float((back * t).sum()) == pytest.approx(fulls[0], rel=1e-4)


def test_receiver_moving_under_a_hard_shadow():
    """The floor of tests/test_shadows.py rising under the square's hard shadow from a point light: the outline
    slides along the light's rays with the floor (the hard-shadow term's receiver part) while the floor brightens
    as it nears the light (the interior term, about -0.16 of the total, of the other sign). Their sum against
    central differences of 1,024-spp renders over two seeds (h = 0.03) within 3 %; forward = backward."""
    from test_shadows import _scene

    def floor_at(dz: float) -> pyclpt.Scene:
        scene = _scene()
        floor = next(m for m in scene.meshes if m.name == "floor")
        floor.positions = floor.positions + np.float32([0.0, 0.0, dz])
        return scene

    t = np.zeros((4, 4))
    t[2, 3] = 1.0
    scene = floor_at(0.0)
    kw = dict(spp=16, seed=1, max_depth=2, edge_samples=1 << 15)
    full = pyclpt.render_forward(scene, "floor.to_world", t, **kw).astype(np.float64).sum()
    h, fd = 0.03, 0.0
    for seed in (7, 8):
        for s, k in ((h, 1), (-h, -1)):
            fd += k * pyclpt.render(floor_at(s), spp=1024, seed=seed, max_depth=2).astype(np.float64).sum() / (4 * h)
    assert full == pytest.approx(fd, rel=0.03)
    back = pyclpt.render_backward(scene, np.ones((48, 48, 3), np.float32), params=["floor.to_world"], **kw)
    assert float(back["floor.to_world"][2, 3]) == pytest.approx(full, rel=1e-4)


def test_a_moving_camera_over_textures_is_refused():
    """What slides under the pixels as the camera moves is not differentiated where it jumps or is a map of the sky:
    a checkerboard floor or an environment map lists the sensor's parameters with the reason (a bilinear bitmap
    does not: tests/test_shadows.py::test_the_camera_moving_over_a_textured_floor)."""
    textured = _floor_scene(bsdf={"type": "diffuse", "reflectance": {"type": "checkerboard"}})
    assert "checkerboard" in pyclpt.traverse(textured).unsupported()["sensor.to_world"]
    sky = _floor_scene()
    sky.environment = pyclpt.Envmap(np.ones((4, 8, 3), np.float32))
    assert "environment map" in pyclpt.traverse(sky).unsupported()["sensor.x_fov"]


def _veiled_scene(instanced: bool) -> pyclpt.Scene:
    """A floor under an area light and a ceiling (indirect bounces), seen through a stochastic mask (opacity 0.5: its
    random numbers decide every hit on it); ``instanced``: the mask a ball in a group placed twice, and a diffuse
    box in another group (instance "box_i"), so that hits carry packed instance ids."""
    masked = {"type": "mask", "opacity": 0.5,
              "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.5, 0.3]}}}
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": 60, "to_world": tf.look_at([0, 1.5, 4], [0, 0.6, 0], [0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": 20, "height": 20, "rfilter": {"type": "box"}}},
         "env": {"type": "constant", "radiance": {"type": "rgb", "value": [0.3] * 3}},
         "floor": {"type": "rectangle", "to_world": tf.scale(5) @ tf.rotate([1, 0, 0], -90),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.6, 0.7]}}},
         "ceiling": {"type": "rectangle", "to_world": tf.translate([0, 3, 0]) @ tf.scale(2) @ tf.rotate([1, 0, 0], 90),
                     "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8] * 3}}},
         "light": {"type": "rectangle", "to_world": tf.translate([1, 2.9, 0]) @ tf.rotate([1, 0, 0], 90),
                   "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [8.0] * 3}}}}
    if instanced:
        d["g"] = {"type": "shapegroup", "id": "g",
                  "ball": {"type": "sphere", "center": [0, 0.6, 0], "radius": 0.6, "bsdf": masked}}
        d["k"] = {"type": "shapegroup", "id": "k", "box": {"type": "cube", "to_world": tf.scale(0.3)}}
        for name, x in (("ball_a", -0.8), ("ball_b", 0.8)):
            d[name] = {"type": "instance", "shape": {"type": "ref", "id": "g"}, "to_world": tf.translate([x, 0, 0])}
        d["box_i"] = {"type": "instance", "shape": {"type": "ref", "id": "k"}, "to_world": tf.translate([0, 0.3, 1.2])}
    else:
        d["veil"] = {"type": "rectangle", "to_world": tf.translate([0, 1.0, 1.0]) @ tf.rotate([1, 0, 0], -60),
                     "bsdf": masked}
    return pyclpt.load_dict(d)


@pytest.mark.parametrize("instanced", [False, True], ids=["flat", "instanced"])
def test_replay_reuses_the_primal_hits(instanced, monkeypatch):
    """The replay takes the closest hits of the primal walk's first bounces (-DREPLAY_HITS, cl/gradients/backward.cl)
    instead of tracing them again: the gradients of moving geometry are those of a replay that traces every bounce
    (REPLAY_HITS=0), up to float-atomic summation order, through a stochastic mask (its random numbers) and, in an
    instanced scene, through packed instance ids. A kept hit at the wrong bounce, or a miss taken for a hit, moves
    them by far more."""
    import pyclpt.gradients.replay as replay_module

    names = ["floor.to_world", "box_i.to_world"] if instanced else ["floor.to_world"]
    grad = np.random.default_rng(2).random((20, 20, 3)).astype(np.float32)

    def backward() -> dict[str, np.ndarray]:  # a scene of its own: a session (and kernels) of its own
        out = pyclpt.render_backward(_veiled_scene(instanced), grad, spp=8, seed=1, max_depth=6, params=names,
                                     boundary=False)
        return {n: out[n].astype(np.float64) for n in names}

    kept = backward()
    build = replay_module.build_program

    def without_kept_hits(device, files=(), **kw):
        if files and files[0] == "gradients/backward.cl":
            kw["defines"] = {**kw["defines"], "REPLAY_HITS": 0}
        return build(device, files, **kw)

    monkeypatch.setattr(replay_module, "build_program", without_kept_hits)
    traced = backward()
    for n in names:
        assert np.all(np.isfinite(kept[n])) and np.abs(kept[n]).max() > 0, n
        np.testing.assert_allclose(kept[n], traced[n], rtol=1e-4, atol=1e-4 * np.abs(traced[n]).max(), err_msg=n)


def _lifted_box(dx: float = 0.0) -> pyclpt.Scene:
    """The built-in Cornell box with its small box lifted 0.3 off the floor (so that moving it along x changes no
    contact) and moved by dx along x."""
    scene = pyclpt.load("cornell-box")
    box = next(m for m in scene.meshes if m.name == "small-box")
    p = box.positions.astype(np.float64) + [dx, 0.3, 0.0]
    box.positions = p.astype(np.float32)
    return scene


def test_the_light_after_the_first_bounce_has_outlines_too():
    """The Cornell box's small box moving along x at depth 3: what the walls and the floor receive after a bounce
    changes with its shadows there (the outlines in the light that later vertices of the paths receive:
    soft_sample_chunks(later=True), path_vertices / vertex_radiance). Interior + camera silhouettes + soft shadows
    (24 seeds of 64 shading points a pixel, at 24x24) against central differences (h = 0.01, 4096 spp, two seeds):
    6.8 here; 5.5 with them (one standard error 1.3), 0.3 without (a mutant: the first-bounce outlines alone; at depth
    8 they missed the box's x derivative by a factor of -8, docs/differentiable.md)."""
    from pyclpt.gradients import edges, shadows

    name, size, depth = "small-box.to_world", 24, 3
    scene = _lifted_box()
    t = np.zeros((4, 4))
    t[0, 3] = 1.0
    kw = dict(width=size, height=size, max_depth=depth)

    def soft(later: bool) -> float:
        sample = shadows.soft_sample_chunks
        try:
            if not later:
                shadows.soft_sample_chunks = lambda *a, **k: sample(*a, **{**k, "later": False})
            return float(np.mean([shadows.soft_shadow_boundary_forward(scene, name, t, spp=64, seed=s, **kw).sum()
                                  for s in range(24)]))
        finally:
            shadows.soft_sample_chunks = sample

    rest = float(np.mean([pyclpt.render_forward(scene, name, t, spp=64, seed=s, boundary=False, **kw).sum()
                          + edges.primary_boundary_forward(scene, name, t, samples=65536, seed=s, **kw).sum()
                          for s in range(4)]))
    h, fd = 0.01, 0.0
    for seed in (1, 2):
        for s, k in ((h, 1), (-h, -1)):
            fd += k * pyclpt.render(_lifted_box(s), spp=4096, seed=seed, **kw).astype(np.float64).sum() / (4 * h)
    with_later, without = rest + soft(True), rest + soft(False)
    assert abs(with_later - fd) < 0.35 * abs(fd), (with_later, without, fd)
    assert abs(without - fd) > 0.7 * abs(fd), (with_later, without, fd)


def test_the_later_outlines_forward_equal_backward():
    """The later vertices' soft-shadow samples (depth 4, the lifted box of the test above) give the same derivative
    in forward and reverse mode, for the box's pose and for the camera's (which leaves the later vertices where they
    are: their receiver terms are the box's alone), and they are there: samples attached to their surfaces, with
    jumps."""
    from pyclpt.gradients import shadows

    scene = _lifted_box()
    size = 16
    grad = np.random.default_rng(3).random((size, size, 3)).astype(np.float32)
    kw = dict(spp=16, seed=2, max_depth=4)
    ss = shadows.sample_soft_edges(scene, [6], size, size, receivers=[6], **kw)
    assert ss.attached.sum() > 100 and np.all(np.any(ss.jump[ss.attached] != 0, axis=1))
    rng = np.random.default_rng(4)
    for name in ("small-box.to_world", "sensor.to_world"):
        back = shadows.soft_shadow_boundary(scene, grad, [name], **kw)[name]
        tangent = rng.normal(size=back.shape)
        tangent[3] = 0
        image = shadows.soft_shadow_boundary_forward(scene, name, tangent, width=size, height=size, **kw)
        want = float((back * tangent).sum())
        assert float((image * grad).sum()) == pytest.approx(want, rel=1e-4, abs=1e-4), name


@pytest.mark.parametrize("name", ["small-box.to_world", "light.to_world"])
def test_only_the_paths_that_meet_a_moving_mesh_are_replayed(name, monkeypatch):
    """With the vertices of the moving meshes named (differentiate._moving_vertices), the backward kernel replays only
    the paths with a vertex or a light sample on one of their triangles and scatters no other mesh's vertex adjoints
    (geometry.h, geo_moving_prim): the Cornell box's small box, and its light (an emitter that moves: paths that only
    sample it count), get the gradients of a pass that replays every path, up to float-atomic summation order; a
    range that leaves the mesh out gives it none."""
    import pyclpt.gradients.differentiate as differentiate

    scene = _lifted_box()
    grad = np.random.default_rng(6).random((16, 16, 3)).astype(np.float32)

    def backward() -> np.ndarray:
        return pyclpt.render_backward(scene, grad, spp=8, seed=1, max_depth=5, params=[name], boundary=False,
                                      width=16, height=16)[name].astype(np.float64)

    some = backward()
    monkeypatch.setattr(differentiate, "_moving_vertices", lambda scene, chosen: (0, 2**31 - 1))
    every = backward()
    assert np.abs(some).max() > 0
    np.testing.assert_allclose(some, every, rtol=1e-4, atol=1e-4 * np.abs(every).max())
    monkeypatch.setattr(differentiate, "_moving_vertices", lambda scene, chosen: (0, 0))
    assert np.all(backward() == 0)


# ---- a moving planar mirror in the interior term (geometry.h: geo_hit_kind, geo_mirror_ray) --------------------

#: A perfect mirror (``conductor``'s default: reflectance 1 at every angle) at 45 degrees through the origin, normal
#: (1, 0, 1) / sqrt 2, filling the view of a camera at z = 5 (tests/test_edges.py's 45-degree mirror): the camera
#: sees, as from (-5, 0, 0), a diffuse wall at x = 6 lit by a point light between the two. No outline in view.
MIRROR_POSE = tf.rotate([0, 1, 0], 45) @ tf.scale(5.0)
MIRROR_NORMAL = np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0)
ROT_X = np.array([[0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 0]], np.float64)  # d R_x(a) / da at 0
MIRROR_DEPTH = 3  # camera -> mirror -> the wall and its light sample


def _mirror_room_dict(move: np.ndarray | None = None, camera: np.ndarray | None = None, metal: str = "none",
                      instanced: bool = False) -> dict:
    """The mirror posed by ``move`` @ MIRROR_POSE, the camera by ``camera`` @ its look_at, 32 x 32; ``metal``: the
    mirror's conductor (none: a perfect mirror; "Au": gold, its Fresnel reflectance changing with the angle);
    ``instanced``: the mirror an instance of a shapegroup (its to_world the instance's)."""
    move = np.eye(4) if move is None else move
    camera = np.eye(4) if camera is None else camera
    mirror = {"type": "rectangle", "bsdf": {"type": "conductor", "material": metal}}
    shapes = {"group": {"type": "shapegroup", "id": "group", "m": mirror},
              "mirror": {"type": "instance", "shape": {"type": "ref", "id": "group"}, "to_world": move @ MIRROR_POSE}
              } if instanced else {"mirror": {**mirror, "to_world": move @ MIRROR_POSE}}
    return {
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 40, "fov_axis": "x",
                   "to_world": camera @ tf.look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 32, "height": 32, "rfilter": {"type": "box"}}},
        **shapes,
        "wall": {"type": "rectangle", "to_world": tf.translate([6, 0, 0]) @ tf.rotate([0, 1, 0], -90) @ tf.scale(30.0),
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.6, 0.7]}}},
        "light": {"type": "point", "position": [3.0, 2.0, 2.0], "intensity": {"type": "rgb", "value": [30.0] * 3}},
    }


def _mirror_room(move: np.ndarray | None = None, camera: np.ndarray | None = None, metal: str = "none"
                 ) -> pyclpt.Scene:
    """The scene of :func:`_mirror_room_dict`."""
    return pyclpt.load_dict(_mirror_room_dict(move, camera, metal))


def _mirror_tangent(motion: str) -> tuple[str, np.ndarray, float]:
    """(parameter, tangent, step) of a motion of the mirror room."""
    t = np.zeros((4, 4))
    if motion == "translate":  # the mirror along its normal
        t[:3, 3] = MIRROR_NORMAL
        return "mirror.to_world", t, 1e-2
    if motion in ("rotate", "rotate-gold"):  # the mirror about the y axis through its centre (in its plane)
        return "mirror.to_world", ROT_Y.copy(), 3e-3
    t = 0.3 * ROT_X  # the camera: a tilt about the origin (its rays turn) and a translation
    t[:3, 3] = [1.0, 0.5, -0.3]
    return "sensor.to_world", t, 3e-3


@pytest.mark.parametrize("motion", ["translate", "rotate", "camera", "rotate-gold"])
def test_moving_mirror_interior_term(motion):
    """What the camera sees in a moving mirror, and through a mirror from a moving camera: the mirror's point slides
    along the camera ray on its moving plane and reflects it about its normal, and the wall's point slides along the
    reflected ray, which moves with both; a gold mirror's Fresnel reflectance changes with the angle as it turns.
    Forward mode equals same-seed central differences pixel by pixel (to 2e-3 of the largest; the image sum to
    1e-3), reverse mode equals forward mode along the tangent (a random image gradient). With the mirror held still
    (before), both were 0."""
    name, tangent, h = _mirror_tangent(motion)
    metal = "Au" if motion.endswith("gold") else "none"
    scene = _mirror_room(metal=metal)
    kw = dict(spp=16, seed=3, max_depth=MIRROR_DEPTH)
    make = ((lambda m: _mirror_room(camera=m, metal=metal)) if name.startswith("sensor")
            else (lambda m: _mirror_room(m, metal=metal)))
    fd = _central(make, tangent, h, 16, 3, MIRROR_DEPTH)
    if name.startswith("sensor"):  # the sensor's to_world is its matrix (a mesh's, a pose applied on the left)
        tangent = tangent @ np.asarray(scene.camera.to_world, np.float64)
    fwd = pyclpt.render_forward(scene, name, tangent, boundary=False, **kw).astype(np.float64)
    assert np.abs(fd).max() > 0.1
    assert np.abs(fwd - fd).max() < 2e-3 * np.abs(fd).max(), (np.abs(fwd - fd).max(), np.abs(fd).max())
    assert fwd.sum() == pytest.approx(fd.sum(), rel=1e-3)
    grad = np.random.default_rng(1).random((32, 32, 3)).astype(np.float32)
    back = _backward_along(scene, name, tangent, grad, **kw)
    assert back == pytest.approx(float((fwd * grad).sum()), rel=1e-4)


def test_smooth_shaded_mirror_vertices():
    """A smooth-shaded mirror, bent (one corner pushed 0.4 along the normal, the vertex normals update() writes:
    they differ, and the mirror reflects about their interpolation), its four vertices moved along a random tangent:
    the reflection turns with the vertex normals (their motion and the point's slide over them). Forward mode
    equals same-seed central differences through params.update() pixel by pixel (to 3e-3 of the largest at the
    95th percentile; the image sum to 2e-3), reverse mode equals forward mode along the tangent."""
    from pyclpt.gradients.placement import vertex_normals

    scene = _mirror_room()
    mesh = scene.meshes[0]
    p = mesh.positions.astype(np.float64)
    p[1] += 0.4 * MIRROR_NORMAL
    p = p.astype(np.float32)
    scene.meshes[0] = dataclasses.replace(mesh, positions=p, normals=vertex_normals(p, mesh.indices))
    params = pyclpt.traverse(scene)
    name = "mirror.vertex_positions"
    base = np.asarray(params[name], np.float64)
    tangent = np.random.default_rng(0).normal(size=base.shape) * 0.3
    kw = dict(spp=16, seed=3, max_depth=MIRROR_DEPTH)

    def render(s: float) -> np.ndarray:
        params.update({name: (base + s * tangent).astype(np.float32)})
        return pyclpt.render(scene, **kw).astype(np.float64)

    h = 1e-3
    fd = (render(h) - render(-h)) / (2 * h)
    params.update({name: base.astype(np.float32)})
    fwd = pyclpt.render_forward(scene, name, tangent, boundary=False, **kw).astype(np.float64)
    err = np.abs(fwd - fd).max(-1)
    assert np.abs(fd).max() > 0.05
    assert np.quantile(err, 0.95) < 3e-3 * np.abs(fd).max(), (np.quantile(err, 0.95), np.abs(fd).max())
    assert fwd.sum() == pytest.approx(fd.sum(), rel=2e-3)
    grad = np.random.default_rng(1).random((32, 32, 3)).astype(np.float32)
    back = pyclpt.render_backward(scene, grad, params=[name], boundary=False, **kw)[name]
    assert float((back.astype(np.float64) * tangent.reshape(back.shape)).sum()) == pytest.approx(
        float((fwd * grad).sum()), rel=1e-3)


def _instanced_mirror_room(move: np.ndarray | None = None) -> pyclpt.Scene:
    """:func:`_mirror_room` with a gold mirror that is an instance of a shapegroup (posed by ``move`` @ MIRROR_POSE)."""
    return pyclpt.load_dict(_mirror_room_dict(move, metal="Au", instanced=True))


def test_moving_instanced_mirror():
    """The gold mirror as an instance of a shapegroup, its instance's to_world turned as in
    test_moving_mirror_interior_term: the mirror's point, normal and Fresnel factor move through the instance's
    record (their adjoints to its 12 floats); forward mode equals same-seed central differences pixel by pixel (to
    2e-3 of the largest), forward = backward."""
    name, tangent, h = _mirror_tangent("rotate")
    scene = _instanced_mirror_room()
    kw = dict(spp=16, seed=3, max_depth=MIRROR_DEPTH)
    fd = _central(_instanced_mirror_room, tangent, h, 16, 3, MIRROR_DEPTH)
    tangent = tangent @ np.asarray(pyclpt.traverse(scene)[name], np.float64)  # an instance's to_world: its matrix
    fwd = pyclpt.render_forward(scene, name, tangent, boundary=False, **kw).astype(np.float64)
    assert np.abs(fwd - fd).max() < 2e-3 * np.abs(fd).max(), (np.abs(fwd - fd).max(), np.abs(fd).max())
    assert fwd.sum() == pytest.approx(fd.sum(), rel=1e-3)
    grad = np.random.default_rng(1).random((32, 32, 3)).astype(np.float32)
    assert _backward_along(scene, name, tangent, grad, **kw) == pytest.approx(float((fwd * grad).sum()), rel=1e-4)


def _ortho_floor(camera: np.ndarray | None = None) -> pyclpt.Scene:
    """_floor_scene's floor under its point light seen by an orthographic camera (a 2 x 2 view, no outline in
    view), tilted 20 degrees about x; ``camera`` (a 4x4) applied to its to_world."""
    camera = np.eye(4) if camera is None else camera
    scene = _floor_scene()
    scene.camera = pyclpt.Camera(camera @ tf.look_at([0, 0, 3], [0, 0, 0], [0, 1, 0]) @ tf.rotate([1, 0, 0], 20),
                                 kind="orthographic")
    return scene


@pytest.mark.parametrize("motion", ["translate", "rotate", "scale"])
def test_moving_orthographic_camera(motion):
    """An orthographic camera (rays along its forward axis from the film rectangle: their origins move with the
    film coordinates) moving over a floor lit by a point light, no outline in view: its to_world translated
    sideways, turned about y and scaled (the rectangle grows): forward mode equals same-seed central differences
    pixel by pixel (to 1e-3 of the largest), reverse mode equals forward mode along the tangent."""
    tangent = np.zeros((4, 4))
    if motion == "translate":
        tangent[0, 3], tangent[1, 3] = 1.0, 0.5
    elif motion == "rotate":
        tangent = 0.5 * ROT_Y
    else:
        tangent[0, 0] = tangent[1, 1] = 1.0
    scene = _ortho_floor()
    params = pyclpt.traverse(scene)
    assert "sensor.to_world" in params.differentiable and "sensor.x_fov" not in params.differentiable
    base = np.asarray(scene.camera.to_world, np.float64)
    fwd = pyclpt.render_forward(scene, "sensor.to_world", tangent @ base, spp=16, seed=3, max_depth=2,
                                boundary=False).astype(np.float64)
    fd = _central(_ortho_floor, tangent, 1e-2, 16, 3, 2)
    assert np.abs(fd).max() > 0.01
    assert np.abs(fwd - fd).max() < 1e-3 * np.abs(fd).max(), (np.abs(fwd - fd).max(), np.abs(fd).max())
    grad = np.random.default_rng(1).random((H, W, 3)).astype(np.float32)
    back = _backward_along(scene, "sensor.to_world", tangent @ base, grad, spp=16, seed=3, max_depth=2)
    # to float rounding of the terms summed (the reverse mode's atomics add them in any order): the turn's sum
    # cancels to a tenth of its terms' magnitude
    assert back == pytest.approx(float((fwd * grad).sum()), rel=1e-4, abs=1e-4 * float(np.abs(fwd * grad).sum()))
