"""Renders against closed forms, with no reference data: direct lighting from a polygonal area light
(the point-to-polygon form factor), one-sided emission, and the eta^2 radiance of a camera inside glass.

The direct-lighting scenes are built so that the two estimators MIS combines both matter: a large,
close, off-centre quad light over a diffuse floor, at max depth 2 (emission seen through a BSDF sample
and next-event estimation at the floor, nothing else). Their expectation is exact:

    L(x) = albedo / pi * integral over the light of Le cos(x) cos(y) / r^2 dA = albedo * Le * F(x)

with F(x) the form factor from the differential area at x to the polygon (Lambert's contour formula,
checked here against a brute-force quadrature). A bias in either estimator or in their weights (the
power heuristic's arguments swapped, a light pdf off by a factor, triangle sampling not uniform)
moves the image mean; a balance heuristic in place of the power heuristic is unbiased and is seen by
tests/test_sampling.py::test_power_heuristic instead.
"""
from __future__ import annotations

import numpy as np
import pytest
from closed_forms import camera_rays, form_factor

import pyclpt

INTEGRATORS = ["megakernel", "wavefront"]
ALBEDO, LE = 0.8, 2.0
SIZE = 32
# the light: x in [-0.3, 1.7], y in [-0.6, 1.0] at height 1 (the camera looks down from 0.9, below it)
LIGHT = (-0.3, 1.7, -0.6, 1.0, 1.0)
UP = np.array([0.0, 0.0, 1.0])


def quad_matrix(x0: float, x1: float, y0: float, y1: float, z: float, facing_down: bool) -> list[float]:
    """to_world of Mitsuba's rectangle ([-1, 1]^2, facing +z) onto [x0, x1] x [y0, y1] at height z,
    facing -z (facing_down) or +z; a rotation times a scale either way."""
    s = -1.0 if facing_down else 1.0
    m = [[(x1 - x0) / 2, 0, 0, (x0 + x1) / 2], [0, s * (y1 - y0) / 2, 0, (y0 + y1) / 2], [0, 0, s, z], [0, 0, 0, 1]]
    return [float(v) for row in m for v in row]


def floor_scene(*, facing_down: bool = True, camera_height: float = 0.9, sky: float | None = None,
                size: int = SIZE, fov: float = 60.0, floor: float = 10.0) -> pyclpt.Scene:
    """A diffuse floor (z = 0, albedo 0.8, 2 floor x 2 floor) under the LIGHT quad, seen from straight
    above."""
    x0, x1, y0, y1, z = LIGHT
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": fov,
                    "film": {"width": size, "height": size, "rfilter": {"type": "box"}},  # per-pixel footprints
                    "to_world": [{"look_at": {"origin": [0, 0, camera_height], "target": [0, 0, 0],
                                              "up": [0, 1, 0]}}]},
         "floor": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": ALBEDO},
                   "to_world": [{"scale": floor}]},
         "light": {"type": "rectangle", "emitter": {"type": "area", "radiance": LE},
                   "to_world": [{"matrix": quad_matrix(x0, x1, y0, y1, z, facing_down)}]}}
    if sky is not None:
        d["sky"] = {"type": "constant", "radiance": sky}
    return pyclpt.load_dict(d, name="analytic-floor")


def light_polygon(scene: pyclpt.Scene) -> np.ndarray:
    """The emitting quad's corners in order around it, from the loaded mesh."""
    (mesh,) = [m for m in scene.meshes if m.emission is not None]
    p = mesh.positions.astype(np.float64)
    centre = p.mean(0)
    order = np.argsort(np.arctan2(p[:, 1] - centre[1], p[:, 0] - centre[0]))
    return p[order]


def pixel_floor_points(scene: pyclpt.Scene, size: int, sub: int = 8, corners: bool = False) -> np.ndarray:
    """(size, size, sub^2, 3): where rays through a sub x sub grid of each pixel (cell midpoints, or
    the grid's corners 0 .. 1 with ``corners``) meet the floor z = 0."""
    offsets = np.linspace(0.0, 1.0, sub) if corners else (np.arange(sub) + 0.5) / sub
    origin, d = camera_rays(scene, size, size, offsets)
    t = -origin[2] / d[..., 2]
    return origin + t[..., None] * d


def expected_floor(scene: pyclpt.Scene, size: int, sky: float = 0.0) -> np.ndarray:
    """Per-pixel expectation at max depth 2: albedo (Le F + sky (1 - F)), F averaged over the pixel."""
    pts = pixel_floor_points(scene, size)
    f = form_factor(pts.reshape(-1, 3), UP, light_polygon(scene)).reshape(pts.shape[:3]).mean(-1)
    return ALBEDO * (LE * f + sky * (1.0 - f))


def blocks(x: np.ndarray) -> np.ndarray:
    n = x.shape[0] // 4
    return x.reshape(4, n, 4, n).mean((1, 3))


def render(scene, integrator, **kw) -> np.ndarray:
    return pyclpt.render(scene, integrator=integrator, progress=False, **kw)


def test_form_factor_matches_quadrature():
    """The closed form against a midpoint rule of cos cos / (pi r^2) over the quad (2000^2 cells)."""
    x0, x1, y0, y1, z = LIGHT
    poly = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]])
    points = np.array([[0.0, 0.0, 0.0], [0.4, -0.3, 0.0], [-0.5, 0.5, 0.0], [3.0, 2.0, 0.0]])
    m = 2000
    u = (np.arange(m) + 0.5) / m
    gx, gy = np.meshgrid(x0 + (x1 - x0) * u, y0 + (y1 - y0) * u)
    d_area = (x1 - x0) * (y1 - y0) / m**2
    for p, f in zip(points, form_factor(points, UP, poly)):
        r2 = (gx - p[0]) ** 2 + (gy - p[1]) ** 2 + (z - p[2]) ** 2
        quadrature = ((z - p[2]) ** 2 / r2**2).sum() * d_area / np.pi
        assert f == pytest.approx(quadrature, rel=1e-5)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_direct_light_from_a_quad_matches_the_form_factor(integrator, each_device):
    """Next-event estimation + BSDF sampling + the power heuristic, max depth 2: albedo Le F(x) per
    pixel. Image mean within 1 % (~12 standard errors), 4x4 blocks within 3 % (~6). On every device."""
    scene = floor_scene()
    expected = expected_floor(scene, SIZE)
    assert 0.25 < expected.min() and expected.max() > 2.5 * expected.min()  # strongly varying: off-centre
    img = render(scene, integrator, spp=512, max_depth=2, seed=1, device=each_device)
    assert np.isfinite(img).all()
    np.testing.assert_array_equal(img[..., 0], img[..., 2])  # grey in, grey out
    lum = img[..., 0].astype(np.float64)
    assert lum.mean() == pytest.approx(expected.mean(), rel=0.01)
    np.testing.assert_allclose(blocks(lum), blocks(expected), rtol=0.03)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_quad_light_and_sky_share_the_floor(integrator):
    """Two emitters of two kinds chosen by power (the light-selection pmf enters both MIS weights):
    the floor sees the quad over F and the constant sky over the rest, albedo (Le F + Lsky (1 - F)).
    A small floor keeps the scene's bounding sphere, which sets the sky's share, small: the quad is
    chosen about a quarter of the time."""
    sky = 0.5
    scene = floor_scene(sky=sky, size=16, floor=1.5)
    expected = expected_floor(scene, 16, sky=sky)
    img = render(scene, integrator, spp=1024, max_depth=2, seed=2)[..., 0].astype(np.float64)
    assert img.mean() == pytest.approx(expected.mean(), rel=0.01)
    np.testing.assert_allclose(blocks(img), blocks(expected), rtol=0.03)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_area_lights_emit_from_their_front_only(integrator):
    """The quad turned to face up, away from the floor: nothing reaches the floor, neither by light
    sampling nor through a BSDF sample that hits the quad's back, so the image is exactly black."""
    scene = floor_scene(facing_down=False)
    for depth in (2, 3):
        img = render(scene, integrator, spp=16, max_depth=depth, seed=3)
        assert img.max() == 0.0, depth
    # the control: facing down, the same floor is lit everywhere
    assert render(floor_scene(), integrator, spp=4, max_depth=2, seed=3).mean() > 0.3


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_camera_behind_an_area_light_sees_its_back_black(integrator):
    """From above the (downward-facing) quad, the camera sees its back: exactly black at every depth
    (no emission from the back; its own light is coplanar), while the floor around it is lit."""
    scene = floor_scene(camera_height=3.0, fov=90.0)
    pts = pixel_floor_points(scene, SIZE, sub=2, corners=True)  # the pixel corners' floor points
    x0, x1, y0, y1, z = LIGHT
    # ray from (0, 0, 3) to a floor point p crosses z = 1 at p * (3 - 1) / 3
    at_light = pts[..., :2] * (3.0 - z) / 3.0
    inside = (at_light[..., 0] > x0 + 1e-3) & (at_light[..., 0] < x1 - 1e-3) & \
        (at_light[..., 1] > y0 + 1e-3) & (at_light[..., 1] < y1 - 1e-3)
    back = inside.all(-1)  # pixels whose whole footprint sees the quad's back
    far = ~inside.any(-1)
    assert back.sum() > 50 and far.sum() > 200
    for depth in (1, 2, 3):
        img = render(scene, integrator, spp=4, max_depth=depth, seed=4)
        assert img[back].max() == 0.0, depth
        if depth > 1:
            # the floor outside the quad's shadow is lit: 0.0515 at 1024 spp, 0.0499-0.0525 at 4 spp (seeds 0-5)
            assert img[far].mean() > 0.025, depth


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_camera_inside_glass_sphere_sees_eta_squared(integrator):
    """A camera at the centre of a glass sphere (ior 1.5) under a constant sky Le: every path leaves
    the glass through a refraction with weight eta^2 (reflections have weight 1 and only delay it), so
    every pixel is eta^2 Le = 2.25 Le (radiance / n^2 is invariant along a ray). Sees the eta^2 scaling
    and the orientation of eta in the Fresnel term, which a glass object seen from outside cannot."""
    scene = pyclpt.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 70.0, "film": {"width": 16, "height": 16},
                   "to_world": [{"look_at": {"origin": [0, 0, 0], "target": [0.3, 0.2, -1], "up": [0, 1, 0]}}]},
        "sky": {"type": "constant", "radiance": 0.8},
        "glass": {"type": "sphere", "radius": 2.0, "bsdf": {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0}},
    }, name="inside-glass")
    img = render(scene, integrator, spp=32, max_depth=-1, seed=5)
    assert np.isfinite(img).all()
    assert img.mean() == pytest.approx(2.25 * 0.8, rel=0.005)
    np.testing.assert_allclose(img, 2.25 * 0.8, rtol=0.05)
