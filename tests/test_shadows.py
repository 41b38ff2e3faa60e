"""The boundary term of hard shadows (pyclpt/gradients/shadows.py) against exact answers: a square occluder out
of the camera's view casts its shadow from a point light onto a floor parallel to the film, so the image sum's
derivative is an integral over the shadow of the floor's radiance gradient; moving the occluder, the light and
the camera move that shadow at known rates. A mutant (the receiver's distance ratio dropped) must fail."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import pyclpt
from pyclpt.gradients import edges, shadows
from pyclpt.gradients.replay import SIDE_OCCLUDER
from pyclpt.scene import transform as tf
from pyclpt.scene.model import Mesh

W = H = 48
FOV, CAM_Z = 40.0, 3.0
LIGHT, INTENSITY, ALBEDO = np.array([-4.0, 0.0, 3.0]), 20.0, 0.5
OCC_Z, OCC_HALF, OCC_ANGLE = 1.5, 0.3, 25.0
NAMES = ["occluder.to_world", "occluder.vertex_positions", "sensor.to_world", "light.position"]


def _scene(**extra) -> pyclpt.Scene:
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": FOV, "fov_axis": "x",
                   "to_world": tf.look_at([0, 0, CAM_Z], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"}}},
        "light": {"type": "point", "position": LIGHT.tolist(), "intensity": {"type": "rgb", "value": [INTENSITY] * 3}},
        "floor": {"type": "rectangle", "to_world": tf.scale(6.0),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [ALBEDO] * 3}}},
        # out of the camera's view (x < -1.7 at depth 1.5, where the view is 0.55 wide on either side)
        "occluder": {"type": "rectangle",
                     "to_world": tf.translate([-2, 0, OCC_Z]) @ tf.rotate([0, 0, 1], OCC_ANGLE) @ tf.scale(OCC_HALF),
                     "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0] * 3}}},
        **extra,
    })


def _exact_occluder_x(k: float | None = None) -> float:
    """d(image sum)/d(occluder x): the light projects the occluder onto the floor scaled by 2 about the light (it
    is half-way down), so the shadow S is the square of half-side 0.6 at the origin and moves 2 per unit; the floor
    is parallel to the film at the camera's depth 3, k pixels per unit (an orthographic camera's: ``k``), so the
    sum is k^2 x the integral of the radiance L(q) = albedo I z_light / (pi r^3) over the lit floor, and its
    derivative -2 k^2 integral over S of dL/dq_x (per channel; 3 channels)."""
    k = (W / 2) / (CAM_Z * math.tan(math.radians(FOV / 2))) if k is None else k
    n = 1500
    u = (np.arange(n) + 0.5) / n * 2 - 1
    uu, vv = np.meshgrid(u, u)
    c, s = math.cos(math.radians(OCC_ANGLE)), math.sin(math.radians(OCC_ANGLE))
    half = 2 * OCC_HALF
    qx, qy = half * (c * uu - s * vv), half * (s * uu + c * vv)
    r = np.sqrt((qx - LIGHT[0]) ** 2 + (qy - LIGHT[1]) ** 2 + LIGHT[2] ** 2)
    dl_dx = -3 * ALBEDO * INTENSITY * LIGHT[2] * (qx - LIGHT[0]) / (math.pi * r ** 5)
    return -2 * k * k * float(dl_dx.sum()) * (2 * half / n) ** 2 * 3


@pytest.mark.parametrize("mutant", [False, True])
def test_hard_shadow_of_a_square_moving(mutant, monkeypatch):
    """The occluder's x move: the exact derivative; its y move: 0 (the shadow and the light's falloff are
    symmetric about the shadow's centre line); the light's x move and the camera's move the shadow at -1/2 the
    occluder's rate (q = 2 o - l on the floor; the image shifts against the camera), so -exact/2 for both; the
    vertices' gradients sum to the pose's translation. The primary term is 0: the occluder is out of view."""
    if mutant:  # the receiver's distance ratio sigma dropped (1), as a mistaken chain rule would
        real = shadows.receiver_motion
        monkeypatch.setattr(shadows, "receiver_motion", lambda *a: (np.ones(len(a[0])), real(*a)[1]))
    scene = _scene()
    g = shadows.shadow_boundary(scene, np.ones((H, W, 3), np.float32), NAMES, samples=1 << 14, seed=1, max_depth=2)
    exact = _exact_occluder_x()
    dx = g["occluder.to_world"][0, 3]
    if mutant:
        assert abs(dx - exact) > 0.05 * abs(exact)
        return
    assert dx == pytest.approx(exact, rel=2e-3)
    assert abs(g["occluder.to_world"][1, 3]) < 2e-3 * abs(exact)
    assert g["occluder.vertex_positions"].reshape(-1, 3)[:, 0].sum() == pytest.approx(dx, rel=1e-5)
    assert g["light.position"][0] == pytest.approx(-exact / 2, rel=2e-3)
    assert g["sensor.to_world"][0, 3] == pytest.approx(-exact / 2, rel=2e-3)
    primary = edges.primary_boundary(scene, np.ones((H, W, 3), np.float32), ["occluder.to_world"], samples=4096,
                                     seed=1, max_depth=2)
    assert np.all(primary["occluder.to_world"] == 0)


def test_weighted_pixels_follow_the_outline():
    """Only pixels on the shadow's outline carry the term: a gradient image that is 0 there gives 0, and the two
    halves of the image add up to the whole; moving the shadow right lights its left edge (+) and darkens its right
    edge (-), the left one brighter (nearer the light)."""
    scene = _scene()
    ones = np.ones((H, W, 3), np.float32)
    kw = dict(samples=1 << 13, seed=4, max_depth=2)
    whole = shadows.shadow_boundary(scene, ones, ["occluder.to_world"], **kw)["occluder.to_world"][0, 3]
    left = ones.copy()
    left[:, W // 2:] = 0
    lx = shadows.shadow_boundary(scene, left, ["occluder.to_world"], **kw)["occluder.to_world"][0, 3]
    rx = shadows.shadow_boundary(scene, ones - left, ["occluder.to_world"], **kw)["occluder.to_world"][0, 3]
    assert lx > 0 > rx and lx + rx == pytest.approx(whole, rel=1e-4)
    ring = np.zeros((H, W, 3), np.float32)
    ring[:4], ring[-4:], ring[:, :4], ring[:, -4:] = 1, 1, 1, 1  # the image's border: no outline there
    assert shadows.shadow_boundary(scene, ring, ["occluder.to_world"], **kw)["occluder.to_world"][0, 3] == 0


def test_no_delta_light_no_term_and_instances_refused():
    scene = _scene()
    scene.lights.clear()
    g = shadows.shadow_boundary(scene, np.ones((H, W, 3), np.float32), ["occluder.to_world"], samples=256, seed=0,
                                max_depth=2)
    assert np.all(g["occluder.to_world"] == 0)
    scene = _scene()
    scene.instances.append(object())  # any instance: the host ray caster does not handle them
    with pytest.raises(ValueError, match="instanced"):
        shadows.sample_shadow_edges(scene, [0], W, H, samples=16, seed=0)


def test_hard_shadow_of_a_directional_light():
    """The square's hard shadow under a directional light (parallel rays: the shadow is the square moved along
    them, sigma = 1; HardLight.origins starts the rays outside the scene): the image weighted by a ramp across it,
    d/d(occluder x) by shadow_boundary_forward (4 x 16,384 edge samples) -46.6 against central differences of
    1,024-spp renders (h = 0.01, two seeds) -45.5 and -46.3, within 4 %."""
    from pyclpt.scene.model import DirectionalLight

    def scene() -> pyclpt.Scene:
        sc = _scene()
        sc.lights = [DirectionalLight(direction=(0.8, 0.0, -0.6), irradiance=(2.0, 2.0, 2.0))]
        return sc

    name = "occluder.to_world"
    t = np.zeros((4, 4))
    t[0, 3] = 1.0
    ramp = np.tile(np.linspace(0, 1, W)[None, :, None], (H, 1, 3))
    term = np.mean([(shadows.shadow_boundary_forward(scene(), name, t, samples=16384, seed=s, max_depth=2)
                     * ramp).sum() for s in range(4)])
    h = 0.01
    fd = np.mean([((pyclpt.render(_moved(scene, name, h * t), spp=1024, max_depth=2, seed=seed).astype(np.float64)
                    - pyclpt.render(_moved(scene, name, -h * t), spp=1024, max_depth=2, seed=seed)) * ramp).sum()
                   / (2 * h) for seed in (1, 2)])
    assert term == pytest.approx(fd, rel=0.04), (term, fd)


def _soft_scene(dx: float = 0.0, size: int = 24) -> pyclpt.Scene:
    """The hard-shadow scene with a 0.5 x 0.5 area light (the point light's intensity, tilted to face the floor's
    centre) instead of the point light: the occluder casts a soft shadow."""
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": FOV, "fov_axis": "x",
                   "to_world": tf.look_at([0, 0, CAM_Z], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}}},
        "light": {"type": "rectangle",
                  "to_world": tf.translate(LIGHT.tolist()) @ tf.rotate([0, 1, 0], 180 - 53) @ tf.scale(0.25),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [INTENSITY / 0.25] * 3}}},
        "floor": {"type": "rectangle", "to_world": tf.scale(6.0),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [ALBEDO] * 3}}},
        "occluder": {"type": "rectangle",
                     "to_world": tf.translate([-2 + dx, 0, OCC_Z]) @ tf.rotate([0, 0, 1], OCC_ANGLE)
                     @ tf.scale(OCC_HALF),
                     "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0] * 3}}},
    })


@pytest.mark.parametrize("mutant", [False, True])
def test_soft_shadow_of_a_square_moving(mutant, monkeypatch):
    """The soft shadow of the square under an area light: d(image sum)/d(occluder x) by the secondary-visibility
    boundary term (512 shading points a pixel over two seeds) against central differences of 4,096-spp renders
    with the same seeds (h = 0.02; their spread over seeds and steps was 1-2%), within 6%; the sides of the
    edge swapped (a mutant) must fail. The hard-shadow term adds nothing here (no delta light)."""
    if mutant:
        monkeypatch.setattr(shadows, "SOFT_SIDE_EPS", -shadows.SOFT_SIDE_EPS)
    scene = _soft_scene()
    ones = np.ones((24, 24, 3), np.float32)
    term = np.mean([shadows.soft_shadow_boundary(scene, ones, ["occluder.to_world"], spp=256, seed=seed,
                                                 max_depth=2)["occluder.to_world"][0, 3] for seed in (0, 1)])
    if mutant:
        assert term < 0
        return
    h, spp = 0.02, 4096
    plus = pyclpt.render(_soft_scene(h), spp=spp, max_depth=2, seed=8, width=24, height=24).astype(np.float64)
    minus = pyclpt.render(_soft_scene(-h), spp=spp, max_depth=2, seed=8, width=24, height=24).astype(np.float64)
    fd = (plus.sum() - minus.sum()) / (2 * h)
    assert term == pytest.approx(fd, rel=0.06)
    hard = shadows.shadow_boundary(scene, ones, ["occluder.to_world"], samples=256, seed=0, max_depth=2)
    assert np.all(hard["occluder.to_world"] == 0)


def test_mesh_edges_once_with_their_triangles():
    """Two triangles of a square: five edges, the diagonal shared by both, the outline bounding one each."""
    scene = _scene()
    e = shadows.MeshEdges.of(scene.meshes[[m.name for m in scene.meshes].index("occluder")])
    assert len(e.v0) == 5
    assert (e.face_b >= 0).sum() == 1 and np.all(e.face_a >= 0)


def test_forward_mode_agrees_with_reverse_mode():
    """For the same seed and size, sum(forward image x image gradient) = sum(reverse gradient x tangent), for each
    parameter kind of both shadow terms (the soft one under the area light)."""
    rng = np.random.default_rng(7)
    scene = _scene()
    grad = rng.random((H, W, 3)).astype(np.float32)
    kw = dict(samples=2048, seed=3, max_depth=2)
    for name in NAMES:  # one name a call: the edges sampled are those that name moves (all for the sensor, a light)
        back = shadows.shadow_boundary(scene, grad, [name], **kw)
        tangent = rng.normal(size=np.shape(back[name]))
        if name.endswith("to_world"):
            tangent[3] = 0  # the last row of a pose stays (0, 0, 0, 1)
        image = shadows.shadow_boundary_forward(scene, name, tangent, width=W, height=H, **kw)
        want = float((back[name] * tangent).sum())
        assert float((image * grad).sum()) == pytest.approx(want, rel=1e-4, abs=1e-3), name
    soft = _soft_scene(size=16)
    grad = rng.random((16, 16, 3)).astype(np.float32)
    names = ["occluder.vertex_positions", "occluder.to_world"]
    back = shadows.soft_shadow_boundary(soft, grad, names, spp=8, seed=2, max_depth=2)
    assert np.any(back["occluder.vertex_positions"] != 0)
    for name in names:
        tangent = rng.normal(size=np.shape(back[name]))
        image = shadows.soft_shadow_boundary_forward(soft, name, tangent, width=16, height=16, spp=8, seed=2,
                                                     max_depth=2)
        want = float((back[name] * tangent).sum())
        assert float((image * grad).sum()) == pytest.approx(want, rel=1e-4, abs=1e-3), name


def _folded_scene(size: int) -> tuple[pyclpt.Scene, pyclpt.Scene, int]:
    """The soft scene with a grey occluder, as two meshes and with the floor and the occluder in one mesh
    ("folded", the floor's vertices first: their number is returned)."""
    two = _soft_scene(size=size)
    names = [m.name for m in two.meshes]
    floor, occ = two.meshes[names.index("floor")], two.meshes[names.index("occluder")]
    occ.material = floor.material  # grey: out of view and at depth 2 unseen, but one mesh has one material
    nf = floor.positions.shape[0]
    folded = Mesh("folded", np.concatenate([floor.positions, occ.positions]),
                  np.concatenate([floor.indices, occ.indices + nf]), floor.material,
                  None if floor.normals is None else np.concatenate([floor.normals, occ.normals]),
                  None if floor.uvs is None else np.concatenate([floor.uvs, occ.uvs]))
    one = dataclasses.replace(two, meshes=[m for m in two.meshes if m not in (floor, occ)] + [folded])
    return two, one, nf


def test_a_mesh_shadowing_itself_has_the_outlines_of_two_meshes():
    """A mesh's outlines on itself (self-shadowing): the soft scene's floor and occluder in one mesh give the soft
    term of the two meshes for the occluder's move along x (8 seeds of 64 shading points a pixel each, at 16 x 16:
    18.5 +- 0.8 as two meshes, 18.2 +- 0.7 as one; with the mesh's own edges left out, as before, 0), and the
    same in reverse mode as in forward mode."""
    two, one, nf = _folded_scene(16)
    n_occ = two.meshes[[m.name for m in two.meshes].index("occluder")].positions.shape[0]
    t_two = np.zeros((n_occ, 3))
    t_two[:, 0] = 1.0
    t_one = np.concatenate([np.zeros((nf, 3)), t_two])
    kw = dict(spp=64, max_depth=2)
    sums = {}
    for key, scene, name, t in (("two", two, "occluder.vertex_positions", t_two),
                                ("one", one, "folded.vertex_positions", t_one)):
        v = [float(shadows.soft_shadow_boundary_forward(scene, name, t.reshape(-1), seed=s, **kw).sum())
             for s in range(8)]
        sums[key] = (np.mean(v), np.std(v) / np.sqrt(len(v)))
    (a, sa), (b, sb) = sums["two"], sums["one"]
    assert a > 10 and abs(a - b) < 4 * np.hypot(sa, sb), sums
    grad = np.random.default_rng(5).random((16, 16, 3)).astype(np.float32)
    back = shadows.soft_shadow_boundary(one, grad, ["folded.vertex_positions"], seed=3, **kw)
    image = shadows.soft_shadow_boundary_forward(one, "folded.vertex_positions", t_one.reshape(-1), seed=3,
                                                 width=16, height=16, **kw)
    want = float((back["folded.vertex_positions"] * t_one.reshape(-1)).sum())
    assert float((image * grad).sum()) == pytest.approx(want, rel=1e-4, abs=1e-4)


def _moved(make, name: str, step: np.ndarray) -> pyclpt.Scene:
    """A new scene from ``make()`` with parameter ``name`` moved by ``step`` (its value's shape)."""
    from pyclpt.gradients.parameters import traverse

    scene = make()
    params = traverse(scene)
    params[name] = np.asarray(params[name], np.float64) + step
    params.update()
    return scene


def _bounce_scene(dx: float = 0.0, light: str = "point", size: int = 16) -> pyclpt.Scene:
    """A wall seen by the camera (nothing else in view), lit by a point, spot or directional light and by the floor,
    on which a black square casts a hard shadow out of view: the wall's light after a bounce has the shadow's
    outline."""
    source = {"point": {"type": "point", "position": [-4.0, 0.0, 3.0],
                        "intensity": {"type": "rgb", "value": [20.0] * 3}},
              "spot": {"type": "spot", "to_world": tf.look_at([-4.0, 0.0, 3.0], [0, 0, 0], [0, 0, 1]),
                       "cutoff_angle": 40.0, "intensity": {"type": "rgb", "value": [20.0] * 3}},
              "directional": {"type": "directional", "direction": [0.8, 0.0, -0.6],
                              "irradiance": {"type": "rgb", "value": [2.0] * 3}}}[light]
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 30.0, "fov_axis": "x",
                   "to_world": tf.look_at([-1.0, 0, 1.8], [2.0, 0, 1.8], [0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}}},
        "light": source,
        "floor": {"type": "rectangle", "to_world": tf.scale(6.0),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5] * 3}}},
        "wall": {"type": "rectangle",
                 "to_world": tf.translate([2.0, 0, 1.5]) @ tf.rotate([0, 1, 0], -90) @ tf.scale([1.5, 2.0, 1.0]),
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8] * 3}}},
        "occluder": {"type": "rectangle",
                     "to_world": tf.translate([-1.5 + dx, 0, 1.5]) @ tf.rotate([0, 0, 1], 25.0) @ tf.scale(0.5),
                     "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0] * 3}}},
    })


@pytest.mark.parametrize("light", ["point", "spot", "directional"])
def test_hard_shadows_after_a_bounce_against_finite_differences(light):
    """The square's hard shadow on the floor, seen by the camera only in the light the wall receives from the
    floor (depth 3): d(image sum)/d(square's x) is the later hard-shadow term (delta_shadow_boundary_forward, 8
    seeds of 64 shading points a pixel) plus the square's outline in the wall's incident light (the soft term),
    against central differences of 8,192-spp renders with common seeds (h = 0.05), within 6 %; without the later
    term it is off by more than half (the first bounce's hard-shadow term has nothing: the camera does not see the
    floor)."""
    scene = _bounce_scene(light=light)
    t = np.zeros((4, 4))
    t[0, 3] = 1.0
    delta, soft = _later_shadow_terms(scene, t)
    h, fd = 0.05, 0.0
    for seed in (1, 2):
        for sign in (1, -1):
            fd += sign * pyclpt.render(_bounce_scene(sign * h, light), spp=8192, max_depth=3,
                                       seed=seed).astype(np.float64).sum() / (4 * h)
    assert delta + soft == pytest.approx(fd, rel=0.06), (delta, soft, fd)
    assert abs(soft - fd) > 0.5 * abs(fd)
    first = shadows.shadow_boundary_forward(scene, "occluder.to_world", t, samples=1024, seed=0, max_depth=3)
    assert not first.any()


def test_the_floor_rising_under_a_hard_shadow_seen_after_a_bounce():
    """The floor of the bounce scene rising (its z): the interior term, the later hard-shadow term (the outline
    slides over the floor, P dr) and the soft term (the square's outline, still, over the moving floor that the
    wall sees behind it: a still shading point's pick among the still meshes' edges near a moving one,
    cl/gradients/edge_pick.h) give -0.50 (8 seeds of 64 shading points a pixel) against central differences of
    -0.52 (8,192 spp, h = 0.05, two common seeds), within 12 %; without the soft term's still edges (0 then) the
    sum is 40 % off, without the later hard-shadow term it has the other sign."""

    scene, name = _bounce_scene(), "floor.to_world"
    t = np.zeros((4, 4))
    t[2, 3] = 1.0
    kw = dict(spp=64, max_depth=3)
    interior = np.mean([pyclpt.render_forward(scene, name, t, seed=s, boundary=False, **kw).sum() for s in range(8)])
    delta = np.mean([shadows.delta_shadow_boundary_forward(scene, name, t, seed=s, **kw).sum() for s in range(8)])
    soft = np.mean([shadows.soft_shadow_boundary_forward(scene, name, t, seed=s, **kw).sum() for s in range(8)])
    h = 0.05
    fd = np.mean([(pyclpt.render(_moved(_bounce_scene, name, h * t), spp=8192, max_depth=3, seed=seed)
                   .astype(np.float64).sum()
                   - pyclpt.render(_moved(_bounce_scene, name, -h * t), spp=8192, max_depth=3, seed=seed)
                   .astype(np.float64).sum()) / (2 * h) for seed in (1, 2)])
    total = interior + delta + soft
    assert total == pytest.approx(fd, rel=0.12), (interior, delta, soft, fd)
    assert abs(total - soft - fd) > 0.25 * abs(fd) and soft < 0
    assert (total - delta) * fd < 0


def test_hard_shadows_after_a_bounce_forward_equal_backward():
    """delta_shadow_boundary (reverse) against its forward mode for the same seed and size: the occluder's vertices,
    the floor (the receiver: the outline slides over it), the point light's position; the sensor gets none."""
    scene = _bounce_scene()
    rng = np.random.default_rng(11)
    grad = rng.random((16, 16, 3)).astype(np.float32)
    kw = dict(spp=16, seed=4, max_depth=3)
    names = ["occluder.vertex_positions", "floor.to_world", "light.position", "sensor.to_world"]
    back = shadows.delta_shadow_boundary(scene, grad, names, **kw)
    assert np.all(back["sensor.to_world"] == 0) and np.any(back["light.position"] != 0)
    for name in names[:3]:
        tangent = rng.normal(size=np.shape(back[name]))
        if name.endswith("to_world"):
            tangent[3] = 0
        image = shadows.delta_shadow_boundary_forward(scene, name, tangent, width=16, height=16, **kw)
        want = float((back[name] * tangent).sum())
        assert want != 0 and float((image * grad).sum()) == pytest.approx(want, rel=1e-4, abs=1e-5), name


def _cube_scene(welded: bool) -> pyclpt.Scene:
    """A cube on view between the floor and two lights, a point light (hard shadows) and a rectangle light (soft
    ones); with ``welded``, the cube's 24 vertices (split at its edges, as a cube's normals and uvs are) merged
    into its 8 corners."""
    scene = _scene(area={"type": "rectangle",
                         "to_world": tf.translate([2.0, 1.0, 3.0]) @ tf.rotate([0, 1, 0], 180 + 34) @ tf.scale(0.3),
                         "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [30.0] * 3}}},
                   cube={"type": "cube", "to_world": tf.translate([0.2, 0.1, 0.5]) @ tf.rotate([1, 1, 0], 30)
                         @ tf.scale(0.25),
                         "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.3, 0.2]}}})
    if welded:
        i = [m.name for m in scene.meshes].index("cube")
        cube = scene.meshes[i]
        corners, weld = np.unique(cube.positions, axis=0, return_inverse=True)
        scene.meshes[i] = dataclasses.replace(cube, positions=corners, indices=weld.reshape(-1)[cube.indices].astype(
            np.int32), normals=None, uvs=None)
    return scene


def test_a_mesh_split_at_its_edges_has_the_outlines_of_the_welded_one():
    """A cube's vertices come four times over at its edges (one copy per face, for its normals and uvs). Its edges
    are found by position: the boundary terms of its pose (camera silhouettes and creases, hard and soft shadows)
    are those of the same cube with its 8 corners shared, for the same seed. Found by index, each face's edges were
    boundary edges and every outline counted twice: the soft shadows' term of the Cornell box's small box was 2.3
    times its value in y."""
    split, welded = _cube_scene(False), _cube_scene(True)
    assert len(split.meshes[[m.name for m in split.meshes].index("cube")].positions) == 24
    grad = np.random.default_rng(5).random((H, W, 3)).astype(np.float32)
    name = ["cube.to_world"]
    for term, kw in ((edges.primary_boundary, dict(samples=4096)), (shadows.shadow_boundary, dict(samples=4096)),
                     (shadows.soft_shadow_boundary, dict(spp=2))):
        a = term(split, grad, name, seed=4, max_depth=3, **kw)[name[0]]
        b = term(welded, grad, name, seed=4, max_depth=3, **kw)[name[0]]
        assert np.any(b != 0), term.__name__
        np.testing.assert_allclose(a, b, rtol=1e-3, atol=1e-3 * np.abs(b).max(), err_msg=term.__name__)


def test_edge_stride_matches_the_kernel():
    """MeshEdges.records writes the edge records cl/gradients/edge_pick.h reads, EDGE_STRIDE floats each."""
    import re

    from pyclpt.device.program import cl_dir

    text = (cl_dir() / "gradients" / "edge_pick.h").read_text()
    assert int(re.search(r"#define EDGE_STRIDE (\d+)", text).group(1)) == shadows.EDGE_STRIDE


def test_the_edge_pick_follows_the_angles_and_skips_the_occluders_side():
    """The vertex_radiance kernel at one point of the soft scene's floor, 20,000 samples: the edge it picks among
    every mesh's (the floor's own in the list, but seen edge-on from a point of its plane) follows the angles the
    silhouette edges subtend there (computed here in float64), the outline's measure it reports is the edge point's
    speed over that probability, and the side whose ray meets the picked edge's mesh at its faces first is 0 and
    marked (SIDE_OCCLUDER: the material form, not traced), the other one the light's when it meets the light."""
    from pyclpt.gradients.session import replay_for

    scene = _soft_scene()
    names = [m.name for m in scene.meshes]
    floor = names.index("floor")
    replay = replay_for(scene, width=24, height=24, max_depth=2)
    _, _, _, prim, hit = replay.path_vertices(np.array([[6.5, 12.5]]), 3)  # left of centre: under the shadow
    assert prim[0] >= 0
    records, offsets = [], np.cumsum([0] + [m.positions.shape[0] for m in scene.meshes]).astype(np.int32)
    for i, mesh in enumerate(scene.meshes):
        p, tri = mesh.positions.astype(np.float64), mesh.indices.astype(np.int64)
        records.append(shadows.MeshEdges.of(mesh).records(p, tri, np.cross(p[tri[:, 1]] - p[tri[:, 0]],
                                                                           p[tri[:, 2]] - p[tri[:, 0]]), i))
    rec = np.concatenate(records).astype(np.float64)
    n = 20000
    u = np.random.default_rng(2).random((n, 2)).astype(np.float32)
    samples = np.concatenate([np.tile(np.r_[hit[0, 1:], 6.5, 12.5, 0.0], (n, 1)), u, np.zeros((n, 1))],
                             axis=1)  # depth 0: film; a moving point picks among every mesh's edges
    blocks = np.cumsum([0] + [len(r) for r in records])
    blocks = np.stack([blocks[:-1], np.diff(blocks), np.ones(len(records))], axis=1).astype(np.int32)
    spheres = np.zeros((len(records), 4), np.float32)
    out = replay.vertex_radiance(np.full(n, prim[0]), samples, np.zeros(n), np.ones(n), rec, blocks, spheres,
                                 offsets, np.ones(len(records)), 5, shadows.SOFT_SIDE_EPS)
    # the point, and each edge's angle if it is a silhouette from it (the floor's own: none, x is in their plane)
    corners = np.concatenate([m.positions for m in scene.meshes]).astype(np.float64)[
        replay.scene.arrays.tri_vidx[prim[0]]]
    b = hit[0, 1:].astype(np.float64)
    x = (1 - b[0] - b[1]) * corners[0] + b[0] * corners[1] + b[1] * corners[2]
    da, db = rec[:, 0:3] - x, rec[:, 3:6] - x
    front_a, front_b = (rec[:, k:k + 3] @ x > rec[:, k + 3] for k in (6, 10))
    silhouette = (rec[:, 14] > 0.5) | (front_a != front_b)
    edge_on = np.any([np.abs(rec[:, k:k + 3] @ x - rec[:, k + 3]) <= 1e-5 * (np.abs(rec[:, k + 3]) + np.abs(x).max())
                      for k in (6, 10)], axis=0)
    assert np.all(edge_on[rec[:, 15] == floor])
    angle = np.where(silhouette & ~edge_on, np.arctan2(np.linalg.norm(np.cross(da, db), axis=1),
                                                       np.einsum("ec,ec->e", da, db)), 0.0)
    p_edge = angle / angle.sum()
    assert np.all(out.pick >= 0)
    counts = np.bincount(out.pick, minlength=len(rec)) / n
    assert counts[rec[:, 15] == floor].sum() == 0
    assert np.all(np.abs(counts - p_edge) <= 4 * np.sqrt(p_edge * (1 - p_edge) / n) + 1e-9), (counts, p_edge)
    # the measure: |w x dw/dt| / p(edge) at the edge point of parameter t
    e = out.pick
    a, ab, t = rec[e, 0:3], rec[e, 3:6] - rec[e, 0:3], u[:, 1].astype(np.float64)
    w, dist = shadows._unit(a + t[:, None] * ab - x)
    dw_dt = (ab - w * np.einsum("nc,nc->n", w, ab)[:, None]) / dist[:, None]
    speed = np.linalg.norm(np.cross(w, dw_dt), axis=1)
    np.testing.assert_allclose(out.outline[:, 0], speed / p_edge[e], rtol=2e-3)
    np.testing.assert_allclose(out.outline[:, 1], dist, rtol=1e-4)
    # the side meeting the picked edge's mesh first is marked and gives 0; with the other side on the light, that
    # side the light's
    on_mesh = out.first_prim == SIDE_OCCLUDER
    first_mesh = np.where(out.first_prim >= 0, np.searchsorted(
        offsets, replay.scene.arrays.tri_vidx[np.maximum(out.first_prim, 0), 0], side="right") - 1, -1)
    assert np.all(out.radiance[on_mesh] == 0)
    one = on_mesh[:, 0] != on_mesh[:, 1]
    passing = np.where(on_mesh[:, 0], 1, 0)  # the other side
    assert np.all(first_mesh[np.arange(n), passing][one] != rec[e, 15][one])  # the square is convex
    lit = one & (first_mesh[np.arange(n), passing] == names.index("light"))
    assert lit.sum() > 100 and np.all(out.radiance[lit, passing[lit]].sum(axis=1) > 0)
    assert np.all(out.radiance[~one] == 0)


def test_outlines_through_mirrors_are_said_to_be_left_out(caplog):
    """Where things move in a scene with a planar mirror (a smooth conductor rectangle), the gradient passes say that
    the camera's outlines seen in it are in the boundary terms, and which outlines are not: after two or more mirror
    bounces, seen in mirrors by other surfaces; through a curved mirror (a sphere), named. The planar mirror's own
    motion is in the boundary terms: moving it says the same. A reflectance's gradient says nothing."""
    scene = _bounce_scene()
    wall = next(m for m in scene.meshes if m.name == "wall")
    scene.materials[wall.material] = pyclpt.load_dict({"type": "scene", "m": {
        "type": "rectangle", "bsdf": {"type": "conductor"}}}).materials[0]
    t = np.zeros((4, 4))
    t[0, 3] = 1.0

    def warned(name: str) -> str:
        caplog.clear()
        with caplog.at_level("WARNING", logger="pyclpt"):
            pyclpt.render_forward(scene, name, t, spp=1, max_depth=3, boundary=False)
        (message,) = [r.getMessage() for r in caplog.records if "outlines" in r.getMessage()]
        return message

    message = warned("occluder.to_world")
    assert "camera's outlines seen in one planar mirror (wall)" in message
    assert "two or more mirror bounces" in message and "other surfaces than the camera" in message
    assert "curved" not in message and "moves" not in message
    assert warned("wall.to_world") == message
    ball = pyclpt.load_dict({"type": "scene", "ball": {"type": "sphere", "bsdf": {"type": "conductor"}}}).meshes[0]
    scene.meshes.append(dataclasses.replace(ball, material=wall.material, positions=ball.positions * 0.2))
    assert "curved mirrors or refracting glass (ball)" in warned("occluder.to_world")
    caplog.clear()
    with caplog.at_level("WARNING", logger="pyclpt"):
        pyclpt.render_backward(scene, np.ones((16, 16, 3), np.float32), spp=1, max_depth=3,
                               params=["floor.bsdf.reflectance.value"])
    assert not any("mirror" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("kind", ["thinlens"])
def test_geometry_under_other_cameras_is_refused_by_name(kind):
    """The boundary terms are written for pinhole and orthographic cameras: under a thin-lens camera every
    parameter that moves things (a mesh's positions and pose, a point light's position) is listed by
    params.unsupported() with the camera named, and render_backward refuses it by name rather than failing inside
    a boundary term; appearance stays differentiable. (An orthographic camera's: test_..._orthographic_camera.)"""
    sensor = {"type": kind, "to_world": tf.look_at([0, 0, CAM_Z], [0, 0, 0], [0, 1, 0]),
              "film": {"type": "hdrfilm", "width": 8, "height": 8}}
    if kind == "thinlens":
        sensor.update(fov=FOV, aperture_radius=0.05, focus_distance=CAM_Z)
    scene = pyclpt.load_dict({"type": "scene", "sensor": sensor,
                              "light": {"type": "point", "position": LIGHT.tolist(),
                                        "intensity": {"type": "rgb", "value": [INTENSITY] * 3}},
                              "floor": {"type": "rectangle", "to_world": tf.scale(6.0), "bsdf": {"type": "diffuse"}}})
    unsupported = pyclpt.traverse(scene).unsupported()
    for name in ("floor.vertex_positions", "floor.to_world", "light.position"):
        assert f"a {kind} camera" in unsupported[name], name
    with pytest.raises(ValueError, match=f"floor.to_world .a {kind} camera"):
        pyclpt.render_backward(scene, np.ones((8, 8, 3), np.float32), spp=1, params=["floor.to_world"])
    assert "floor.bsdf.reflectance.value" in pyclpt.traverse(scene).differentiable


def _textured_floor(filter_type: str = "bilinear") -> pyclpt.Scene:
    """A floor with a 16 x 16 random bitmap (bilinear unless told), larger than the view, under a point light."""
    texels = np.random.default_rng(3).random((16, 16, 3)).astype(np.float32) * 0.8 + 0.1
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 40, "fov_axis": "x",
                   "to_world": tf.look_at([0, 0, 3], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 32, "height": 32, "rfilter": {"type": "box"}}},
        "light": {"type": "point", "position": [-1.0, 0.5, 2.0], "intensity": {"type": "rgb", "value": [10.0] * 3}},
        "floor": {"type": "rectangle", "to_world": tf.scale(2.0),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "bitmap", "data": texels,
                                                              "filter_type": filter_type}}}})


def test_a_textured_floor_sliding_under_the_camera():
    """A bilinear texture moving with its surface: the camera's rays meet the floor at the same points while it
    slides along x, so the image changes only as the texture slides under them (the interior term: a sliding
    point's barycentrics move its texture coordinates, geometry.h's geo_bsdf_bary). Weighted by a random image
    gradient: forward mode -3.63 +- 0.19 (8 seeds of 256 spp) against central differences of 2,048-spp renders
    -3.60 (h = 0.02, two seeds), within 12 %; reverse mode equals forward mode. A nearest-filtered bitmap (its
    value jumps at texel edges: outlines of their own) is refused by name."""
    scene, name = _textured_floor(), "floor.to_world"
    assert name in pyclpt.traverse(scene).differentiable
    assert "nearest" in pyclpt.traverse(_textured_floor("nearest")).unsupported()[name]
    t = np.zeros((4, 4))
    t[0, 3] = 1.0
    grad = np.random.default_rng(1).random((32, 32, 3)).astype(np.float32)
    fw = [float((pyclpt.render_forward(scene, name, t, spp=256, seed=s, max_depth=2) * grad).sum()) for s in range(8)]
    back = pyclpt.render_backward(scene, grad, spp=256, seed=0, max_depth=2, params=[name])[name]
    assert float((back * t).sum()) == pytest.approx(fw[0], rel=1e-4)
    h = 0.02
    fd = np.mean([((pyclpt.render(_moved(_textured_floor, name, h * t), spp=2048, max_depth=2, seed=seed)
                    .astype(np.float64) - pyclpt.render(_moved(_textured_floor, name, -h * t), spp=2048, max_depth=2,
                                                        seed=seed)) * grad).sum() / (2 * h) for seed in (1, 2)])
    assert np.mean(fw) == pytest.approx(fd, rel=0.12), (np.mean(fw), fd)


def test_the_camera_moving_over_a_textured_floor():
    """The camera moving along x over the bilinear texture (its hits slide over the floor, geo_bsdf_bary through
    geo_camera_motion): forward mode -144.36 +- 0.19 (8 seeds of 256 spp; 4 here) against central differences of
    2,048-spp renders -144.31 and -144.33 (h = 0.02), within 0.6 %: the texture's share is about 3.6 (the floor
    sliding the other way, above), 2.5 %."""
    scene, name = _textured_floor(), "sensor.to_world"
    assert name in pyclpt.traverse(scene).differentiable
    t = np.zeros((4, 4))
    t[0, 3] = 1.0
    grad = np.random.default_rng(1).random((32, 32, 3)).astype(np.float32)
    fw = np.mean([float((pyclpt.render_forward(scene, name, t, spp=256, seed=s, max_depth=2) * grad).sum())
                  for s in range(4)])
    h = 0.02
    fd = np.mean([((pyclpt.render(_moved(_textured_floor, name, h * t), spp=2048, max_depth=2, seed=seed)
                    .astype(np.float64) - pyclpt.render(_moved(_textured_floor, name, -h * t), spp=2048, max_depth=2,
                                                        seed=seed)) * grad).sum() / (2 * h) for seed in (1, 2)])
    assert fw == pytest.approx(fd, rel=0.006), (fw, fd)


# ---- an orthographic camera: parallel rays along its axis from its film rectangle (camera_ray) ----

ORTHO_HALF = 1.2  # its half-extent in world units: the view is |x|, |y| < 1.2, the occluder (x < -1.6) out of it


def _orthographic(scene: pyclpt.Scene, at=(0.0, 0.0, CAM_Z), target=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0),
                  half: float = ORTHO_HALF) -> pyclpt.Scene:
    """``scene`` seen by an orthographic camera at ``at`` looking at ``target``, its to_world scaled by ``half``."""
    scene.camera = pyclpt.Camera(tf.look_at(list(at), list(target), list(up)) @ tf.scale([half] * 3),
                                 kind="orthographic")
    return scene


def _ortho_scene() -> pyclpt.Scene:
    """_scene seen straight down by an orthographic camera, with a black strip (0.1 x 0.8) hanging in view at z 2.5
    over the shadow's middle: it hides shadowed floor only (the image is the same), but a pinhole's view of the
    shadow's right side from the camera's origin would pass through it."""
    strip = {"type": "rectangle", "to_world": tf.translate([0.1, 0, 2.5]) @ tf.scale([0.05, 0.4, 1.0]),
             "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0] * 3}}}
    return _orthographic(_scene(strip=strip))


def _ortho_soft(dx: float = 0.0, size: int = 24) -> pyclpt.Scene:
    return _orthographic(_soft_scene(dx, size))


def _ortho_bounce(dx: float = 0.0, light: str = "point", size: int = 16) -> pyclpt.Scene:
    """_bounce_scene's wall seen by an orthographic camera (a 2 x 2 view of it, the floor and the square out of it)."""
    return _orthographic(_bounce_scene(dx, light, size), at=(-1.0, 0.0, 1.8), target=(2.0, 0.0, 1.8),
                         up=(0.0, 0.0, 1.0), half=1.0)


def _central_sum(make, name: str, t: np.ndarray, h: float, spp: int, seeds, max_depth: int = 2) -> float:
    """Central differences of the image sum of ``make()`` moved along ``t`` in ``name``, averaged over seeds."""
    return float(np.mean([(pyclpt.render(_moved(make, name, h * t), spp=spp, max_depth=max_depth, seed=seed)
                           .astype(np.float64).sum()
                           - pyclpt.render(_moved(make, name, -h * t), spp=spp, max_depth=max_depth, seed=seed)
                           .astype(np.float64).sum()) / (2 * h) for seed in seeds]))


def test_hard_shadow_under_an_orthographic_camera():
    """The square's hard shadow (test_hard_shadow_of_a_square_moving) seen straight down by an orthographic camera, k =
    20 pixels a unit everywhere (its rays are parallel: the outline's image length and speed scale by k, not by the
    depth): d(image sum)/d(occluder x) the exact 127.42 (pyclpt 127.47); the light's x and the camera's x move the
    shadow at -1/2 that rate (-63.87 against -63.71); the camera moving along its axis moves nothing (a pinhole's would
    zoom). The outline is seen along the camera's parallel rays (the strip in view hides its right side from the
    camera's origin: 310 if seen from there). render_backward at max_depth 2 (no longer refused; the interior and
    primary terms are 0: the occluder is out of view and black) gives the same, and render_forward along the move equals
    it."""
    scene = _ortho_scene()
    ones = np.ones((H, W, 3), np.float32)
    g = shadows.shadow_boundary(scene, ones, NAMES[:2], samples=1 << 14, seed=1, max_depth=2)
    exact = _exact_occluder_x((W / 2) / ORTHO_HALF)
    dx = g["occluder.to_world"][0, 3]
    assert dx == pytest.approx(exact, rel=2e-3)
    assert abs(g["occluder.to_world"][1, 3]) < 2e-3 * abs(exact)
    assert g["occluder.vertex_positions"].reshape(-1, 3)[:, 0].sum() == pytest.approx(dx, rel=1e-5)
    # every mesh's edges sampled (the floor's outline takes most): 4 x the samples for the same spread (0.3 %)
    g = shadows.shadow_boundary(scene, ones, NAMES[2:], samples=1 << 16, seed=1, max_depth=2)
    assert g["light.position"][0] == pytest.approx(-exact / 2, rel=5e-3)
    assert g["sensor.to_world"][0, 3] == pytest.approx(-exact / 2, rel=5e-3)
    assert abs(g["sensor.to_world"][2, 3]) < 1e-6 * abs(exact)
    name, t = "occluder.to_world", np.zeros((4, 4))
    t[0, 3] = 1.0
    kw = dict(spp=4, seed=1, max_depth=2, edge_samples=1 << 14)
    full = pyclpt.render_backward(scene, ones, params=[name], **kw)[name]
    assert full[0, 3] == pytest.approx(exact, rel=2e-3)
    assert float(pyclpt.render_forward(scene, name, t, **kw).astype(np.float64).sum()) == pytest.approx(
        float(full[0, 3]), rel=1e-4)


def test_soft_shadow_under_an_orthographic_camera():
    """The soft shadow of the square under the area light, seen straight down by an orthographic camera (24 x 24):
    d(image sum)/d(occluder x) by the soft term (4 seeds of 256 shading points a pixel) 30.4 against central differences
    of 4,096-spp renders (h = 0.02, two seeds) 31.6, within 6 %; the camera's film rectangle growing (its hits slide
    over the floor along its parallel rays, away from its axis) by render_forward (interior and boundary terms; 2 seeds)
    67.8 against 68.6, within 3 %; the floor rising (the camera's hits slide up its parallel rays: a pinhole's would
    slide outwards, -21.7 of soft term) the interior term 6.59 and the soft term 0.38 (16 seeds of 256) against 7.02
    (8,192 spp, h = 0.05, two seeds), within 10 %."""
    scene = _ortho_soft()
    ones = np.ones((24, 24, 3), np.float32)
    term = np.mean([shadows.soft_shadow_boundary(scene, ones, ["occluder.to_world"], spp=256, seed=seed,
                                                 max_depth=2)["occluder.to_world"][0, 3] for seed in range(4)])
    t = np.zeros((4, 4))
    t[0, 3] = 1.0
    fd = _central_sum(_ortho_soft, "occluder.to_world", t, 0.02, 4096, (8, 9))
    assert term == pytest.approx(fd, rel=0.06), (term, fd)
    name, grow = "sensor.to_world", np.asarray(scene.camera.to_world, np.float64) @ np.diag([1.0, 1.0, 0.0, 0.0])
    fw = np.mean([pyclpt.render_forward(scene, name, grow, spp=1024, seed=s, max_depth=2, edge_spp=256)
                  .astype(np.float64).sum() for s in (1, 2)])
    fd = _central_sum(_ortho_soft, name, grow, 0.02, 4096, (1, 2))
    assert fw == pytest.approx(fd, rel=0.03), (name, fw, fd)
    # the floor rising: the soft term is small (0.4 +- 0.3 over 16 seeds) beside the interior term (6.6)
    name, rise = "floor.to_world", np.zeros((4, 4))
    rise[2, 3] = 1.0
    interior = pyclpt.render_forward(scene, name, rise, spp=1024, seed=1, max_depth=2, boundary=False).sum()
    soft = np.mean([shadows.soft_shadow_boundary_forward(scene, name, rise, spp=256, seed=s, max_depth=2).sum()
                    for s in range(16)])
    fd = _central_sum(_ortho_soft, name, rise, 0.05, 8192, (1, 2))
    assert interior + soft == pytest.approx(fd, rel=0.1), (interior, soft, fd)


def test_orthographic_forward_mode_agrees_with_reverse_mode():
    """Under an orthographic camera, for the same seed and size, sum(forward image x image gradient) = sum(reverse
    gradient x tangent) for the hard-shadow term at the first surface seen (each parameter kind), the soft term (the
    occluder, the floor it falls on, the camera) and the hard shadows seen after a bounce (the occluder, the floor,
    the light; the camera gets none), which are not 0."""
    rng = np.random.default_rng(17)
    scene = _ortho_scene()
    grad = rng.random((H, W, 3)).astype(np.float32)

    def tangent_of(value: np.ndarray, name: str) -> np.ndarray:
        t = rng.normal(size=np.shape(value))
        if name.endswith("to_world"):
            t[3] = 0  # the last row of a pose stays (0, 0, 0, 1)
        return t

    kw = dict(samples=2048, seed=3, max_depth=2)
    for name in NAMES:
        back = shadows.shadow_boundary(scene, grad, [name], **kw)
        t = tangent_of(back[name], name)
        image = shadows.shadow_boundary_forward(scene, name, t, width=W, height=H, **kw)
        want = float((back[name] * t).sum())
        assert want != 0 and float((image * grad).sum()) == pytest.approx(want, rel=1e-4, abs=1e-3), name
    soft, grad = _ortho_soft(size=16), rng.random((16, 16, 3)).astype(np.float32)
    names = ["occluder.vertex_positions", "occluder.to_world", "floor.to_world", "sensor.to_world"]
    kw = dict(spp=8, seed=2, max_depth=2)
    for name in names:  # one name a call: the shading points that move and the edges they pick are that name's
        back = shadows.soft_shadow_boundary(soft, grad, [name], **kw)
        t = tangent_of(back[name], name)
        image = shadows.soft_shadow_boundary_forward(soft, name, t, width=16, height=16, **kw)
        want = float((back[name] * t).sum())
        assert want != 0 and float((image * grad).sum()) == pytest.approx(want, rel=1e-4, abs=1e-3), name
    bounce = _ortho_bounce()
    names = ["occluder.vertex_positions", "floor.to_world", "light.position", "sensor.to_world"]
    kw = dict(spp=16, seed=4, max_depth=3)
    back = shadows.delta_shadow_boundary(bounce, grad, names, **kw)
    assert np.all(back["sensor.to_world"] == 0)
    for name in names[:3]:
        t = tangent_of(back[name], name)
        image = shadows.delta_shadow_boundary_forward(bounce, name, t, width=16, height=16, **kw)
        want = float((back[name] * t).sum())
        assert want != 0 and float((image * grad).sum()) == pytest.approx(want, rel=1e-4, abs=1e-5), name


def test_orthographic_camera_moves_geometry_but_refuses_mirrors():
    """Under an orthographic camera a mesh's positions and pose and a point light's position are differentiable
    (the shadows' boundary terms run: no ValueError at max_depth 3, forward or reverse); a planar mirror in view
    (the floor made a smooth conductor) is refused by name in both modes: the camera's outlines seen in it are
    written for perspective cameras."""
    scene = _ortho_scene()
    params = pyclpt.traverse(scene)
    for name in ("floor.vertex_positions", "floor.to_world", "occluder.to_world", "light.position"):
        assert name in params.differentiable and name not in params.unsupported(), name
    ones = np.ones((8, 8, 3), np.float32)
    kw = dict(spp=1, max_depth=3, width=8, height=8, edge_samples=256, edge_spp=1)
    g = pyclpt.render_backward(scene, ones, params=["occluder.to_world", "light.position"], **kw)
    assert g["occluder.to_world"][0, 3] > 0
    assert pyclpt.render_forward(scene, "floor.to_world", np.eye(4), **kw).shape == (8, 8, 3)
    mirror = _ortho_scene()  # a new scene: a smooth conductor changes what the kernels are compiled for
    floor = next(m for m in mirror.meshes if m.name == "floor")
    mirror.materials[floor.material] = pyclpt.load_dict({"type": "scene", "m": {
        "type": "rectangle", "bsdf": {"type": "conductor"}}}).materials[0]
    with pytest.raises(ValueError, match="planar mirrors are implemented for perspective cameras"):
        pyclpt.render_backward(mirror, ones, params=["occluder.to_world"], **kw)
    with pytest.raises(ValueError, match="planar mirrors are implemented for perspective cameras"):
        pyclpt.render_forward(mirror, "occluder.to_world", np.eye(4), **kw)


def _later_shadow_terms(scene, t: np.ndarray) -> tuple[float, float]:
    """The occluder's d(image sum) along t at depth 3 by the later hard-shadow term (8 seeds of 64 shading points a
    pixel) and by the soft term (4 seeds)."""
    kw = dict(spp=64, max_depth=3)
    delta = np.mean([shadows.delta_shadow_boundary_forward(scene, "occluder.to_world", t, seed=s, **kw).sum()
                     for s in range(8)])
    soft = np.mean([shadows.soft_shadow_boundary_forward(scene, "occluder.to_world", t, seed=s, **kw).sum()
                    for s in range(4)])
    return float(delta), float(soft)


def test_hard_shadows_after_a_bounce_under_an_orthographic_camera():
    """The square's hard shadow on the floor seen by an orthographic camera only in the light the wall receives from
    the floor (depth 3): d(image sum)/d(square's x) by the later hard-shadow term 2.81 (8 seeds of 64 shading points
    a pixel) plus the soft term -0.30, against central differences of 8,192-spp renders 2.46 (h = 0.05, two common
    seeds), within 6 %; the first bounce's hard-shadow term has nothing (the camera does not see the floor)."""
    scene = _ortho_bounce()
    t = np.zeros((4, 4))
    t[0, 3] = 1.0
    delta, soft = _later_shadow_terms(scene, t)
    fd = _central_sum(_ortho_bounce, "occluder.to_world", t, 0.05, 8192, (1, 2), max_depth=3)
    assert delta + soft == pytest.approx(fd, rel=0.06), (delta, soft, fd)
    assert abs(soft - fd) > 0.5 * abs(fd)
    assert not shadows.shadow_boundary_forward(scene, "occluder.to_world", t, samples=1024, seed=0, max_depth=3).any()


def test_bands_keep_a_kernel_queued_while_the_host_works():
    """shadows._bands runs the bands' stages in the pipelined order (a band's shading points two bands ahead, its
    sides one band ahead of the host's work on the last band's), so that the device has a kernel queued whenever
    the host works; the bands come back in order, one that ends early (no samples) among them."""
    log = []

    def band(p0, p1):
        log.append(("points", p0))
        yield
        log.append(("sides", p0))
        if p0 == 2:
            return "early"
        yield
        log.append(("samples", p0))
        return p0

    out = list(shadows._bands(5, shadows.SOFT_CHUNK, band))  # bands of one pixel
    assert out == [0, 1, "early", 3, 4]
    assert log == [("points", 0), ("points", 1), ("sides", 0), ("points", 2), ("sides", 1), ("points", 3),
                   ("samples", 0), ("sides", 2), ("points", 4), ("samples", 1), ("sides", 3), ("sides", 4),
                   ("samples", 3), ("samples", 4)]


def _one_band_at_a_time(pixels, spp, band):
    step = max(1, shadows.SOFT_CHUNK // spp)
    for p0 in range(0, pixels, step):
        run = band(p0, min(p0 + step, pixels))
        try:
            while True:
                next(run)
        except StopIteration as stop:
            yield stop.value


def test_pipelined_bands_give_the_samples_of_one_band_at_a_time(each_device, monkeypatch):
    """With 16 bands in flight two and three at a time (their kernels share one set of buffers on the queue, their
    copies are not waited for until read), the soft and later hard-shadow terms' samples are those of one band at
    a time, bit for bit, on each device."""
    monkeypatch.setattr(shadows, "SOFT_CHUNK", 1024)
    box = pyclpt.load("cornell-box")
    kw = dict(spp=4, seed=7, max_depth=5, device=each_device)

    def samples():
        soft = shadows.sample_soft_edges(box, [6], 64, 64, receivers=[1], **kw)  # the small box over the floor
        delta = list(shadows.delta_sample_chunks(_bounce_scene(size=64), 64, 64, **kw))
        return [soft] + delta

    pipelined = samples()
    monkeypatch.setattr(shadows, "_bands", _one_band_at_a_time)
    alone = samples()
    assert len(pipelined) == len(alone) == 17
    assert sum(len(s.jump) for s in pipelined[1:]) > 100 and len(pipelined[0].jump) > 1000
    for a, b in zip(pipelined, alone):
        for f in dataclasses.fields(a):
            np.testing.assert_array_equal(getattr(a, f.name), getattr(b, f.name), err_msg=f.name)


def test_boundary_kernels_take_no_items():
    """The boundary terms' kernels called with no items give empty results (nothing enqueued, nothing to wait for)."""
    from pyclpt.gradients.session import replay_for

    replay = replay_for(_soft_scene(), width=24, height=24, max_depth=2)
    prims, vertex, depths, first_prims, first_hits = replay.path_vertices(np.zeros((0, 2)), 3)
    assert prims.shape == (0,) and vertex.shape == (0, 8) and first_hits.shape == (0, 3)
    assert replay.edge_radiance(np.zeros((0, 4)), 3, shadows.SOFT_SIDE_EPS).shape == (0, 2, 3)


def test_the_boundary_terms_say_how_many_samples_they_dropped(caplog):
    """A light of radiance 3e38 seen in a sharp rough conductor overflows float32 at the occluder's outline: the
    boundary kernels' NaN or inf samples count as 0 (the gradient stays finite) and render_backward and
    render_forward say how many (before, each call's count was overwritten by the next and lost). (The forward
    image's largest derivatives themselves pass float32's range here, whatever is dropped.)"""
    scene = pyclpt.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 40, "fov_axis": "x",
                   "to_world": tf.look_at([0, -2, 1], [0, 0, 0], [0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": 24, "height": 24, "rfilter": {"type": "box"}}},
        "light": {"type": "rectangle", "to_world": tf.look_at([0, 2.5, 1.25], [0, 0, 0], [0, 0, 1]),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [3e38] * 3}}},
        "floor": {"type": "rectangle", "to_world": tf.scale(6.0), "bsdf": {"type": "roughconductor", "alpha": 0.05}},
        "occluder": {"type": "rectangle", "to_world": tf.look_at([0.3, 1.2, 0.6], [0, 0, 0], [0, 0, 1]) @ tf.scale(0.3),
                     "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5] * 3}}},
    })
    kw = dict(spp=4, max_depth=3, seed=1)
    with caplog.at_level("WARNING", logger="pyclpt"):
        g = pyclpt.render_backward(scene, np.full((24, 24, 3), 1e-3, np.float32), params=["occluder.to_world"],
                                   **kw)
        pyclpt.render_forward(scene, "occluder.to_world", np.eye(4)[[0]].T @ np.eye(4)[[3]], **kw)
    assert np.all(np.isfinite(g["occluder.to_world"]))
    said = [r.getMessage() for r in caplog.records if "boundary terms dropped" in r.getMessage()]
    assert len(said) == 2, [r.getMessage() for r in caplog.records]
    assert all(int(m.split("dropped ")[1].split()[0]) > 0 for m in said)
