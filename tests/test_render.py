"""Correctness of the renders: analytic scenes, Mitsuba's reference, depth semantics,
NaN/inf handling. Run on the megakernel and the wavefront (both layouts)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from closed_forms import camera_rays, emitter_pixels

import pyclpt
from scenes import interior_furnace, object_under_sky, sensor

INTEGRATORS = [("megakernel", "soa"), ("wavefront", "soa"), ("wavefront", "aos")]
DATA = Path(__file__).parent / "data"


def render(scene, integrator="megakernel", layout="soa", **kw):
    return pyclpt.render(scene, integrator=integrator, layout=layout, progress=False, **kw)


def interior_cube_furnace(albedo: float, radiance: float = 1.0) -> pyclpt.Scene:
    """A camera inside a closed emissive diffuse cube (side 6, normals inward), off its centre:
    radiance is Le * sum_{k<d} albedo^k, as in the sphere; but here, unlike inside a sphere, the
    light-sampling pdf differs from the BSDF's, so MIS weights that do not sum to 1 show."""
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": sensor([{"look_at": {"origin": [1.0, 0.5, 0.5], "target": [-2.0, -1.5, -3.0], "up": [0, 1, 0]}}]),
        "shell": {"type": "cube", "flip_normals": True, "to_world": [{"scale": 3.0}],
                  "bsdf": {"type": "diffuse", "reflectance": albedo},
                  "emitter": {"type": "area", "radiance": radiance}},
    }, name="interior-cube-furnace")


FURNACES = {"sphere": interior_furnace, "cube": interior_cube_furnace}


@pytest.mark.parametrize("integrator,layout", INTEGRATORS)
@pytest.mark.parametrize("shape,depth,albedo", [
    ("sphere", 1, 0.5), ("sphere", 2, 0.5), ("sphere", 3, 0.5), ("sphere", -1, 0.5), ("sphere", -1, 0.8),
    ("cube", 2, 0.5), ("cube", 3, 0.8), ("cube", -1, 0.8)])
def test_interior_furnace(integrator, layout, shape, depth, albedo):
    """Le * sum_{k<depth} albedo^k: exercises emission, NEE, depth and roulette; MIS in the cube only
    (inside a sphere the light pdf equals the BSDF pdf, so any symmetric weighting passes there)."""
    scene = FURNACES[shape](albedo)
    img = render(scene, integrator, layout, spp=64, max_depth=depth, seed=1)
    n = 50 if depth == -1 else depth
    expected = sum(albedo**k for k in range(n))
    assert np.isfinite(img).all()
    assert img.mean() == pytest.approx(expected, rel=0.01 if depth != -1 else 0.02)


@pytest.mark.parametrize("integrator,layout", INTEGRATORS[:2])
def test_diffuse_cube_under_constant_sky(integrator, layout):
    """A convex diffuse object under a uniform sky reflects exactly albedo * Le."""
    scene = object_under_sky({"type": "diffuse", "reflectance": 0.7}, radiance=1.5)
    img = render(scene, integrator, layout, spp=128, max_depth=-1, seed=2)
    # background pixels see the sky directly: exactly Le
    assert np.allclose(img[0, 0], 1.5) and np.allclose(img[-1, -1], 1.5)
    centre = img[9:15, 9:15]
    assert centre.mean() == pytest.approx(0.7 * 1.5, rel=0.02)


@pytest.mark.parametrize("integrator,layout", INTEGRATORS[:2])
def test_glass_sphere_under_constant_sky_is_invisible(integrator, layout):
    """A lossless dielectric under a uniform sky: every path escapes with weight 1, so the pixels that
    see the sphere show the sky's radiance. (Entering and leaving scale radiance by 1/eta^2 and eta^2,
    which cancel: a dropped eta^2 or an inverted Fresnel eta passes here; see
    tests/test_analytic.py::test_camera_inside_glass_sphere_sees_eta_squared.)"""
    scene = object_under_sky({"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0}, radiance=1.0,
                             shape="sphere")
    img = render(scene, integrator, layout, spp=128, max_depth=-1, seed=3)
    origin, dirs = camera_rays(scene, 24, 24, np.linspace(0.0, 1.0, 3))
    miss_distance = np.linalg.norm(np.cross(dirs, -origin), axis=-1)  # from the sphere's centre to each ray
    sphere = (miss_distance < 0.95).all(-1)  # the pixel sees the (faceted, unit) sphere everywhere
    background = (miss_distance > 1.0).all(-1)
    assert sphere.sum() > 150 and background.sum() > 150
    assert np.all(img[background] == 1.0)
    assert img[sphere].mean() == pytest.approx(1.0, rel=0.005)
    np.testing.assert_allclose(img[sphere], 1.0, rtol=0.05)


def test_cornell_box_matches_mitsuba(cornell_box):
    """Mitsuba 3's own render of cornell_box() (tests/data/make_mitsuba_reference.py)."""
    ref = np.load(DATA / "cornell-box-mitsuba-64.npy")
    img = render(cornell_box, spp=256, max_depth=8, width=64, height=64, seed=11)
    assert img.shape == ref.shape == (64, 64, 3)
    np.testing.assert_allclose(img.mean((0, 1)), ref.mean((0, 1)), rtol=0.01)

    def blocks(x):
        return x.reshape(4, 16, 4, 16, 3).mean((1, 3))

    rel_mse = np.mean((blocks(img) - blocks(ref)) ** 2) / np.mean(blocks(ref) ** 2)
    assert rel_mse < 1e-4, rel_mse
    assert np.abs(blocks(img) - blocks(ref)).max() / blocks(ref).max() < 0.03


def test_depth_one_shows_only_emitters(cornell_box):
    """max_depth 1: each sample is the radiance of the emitter its camera ray sees first, else 0.
    Where the whole pixel sees the same thing (ray casting in numpy at the pixel's corners, edges and
    centre) the pixel is exactly that; at the light's edges it is one of the two. The light is in the
    top rows; max_depth 0 is black."""
    w = h = 128  # the light is seen nearly edge-on: ~4 rows
    expected, certain = emitter_pixels(cornell_box, w, h)
    le = np.asarray(next(m.emission for m in cornell_box.meshes if m.emission is not None), np.float32)
    lit_for_sure = certain & (expected.max(-1) > 0)
    assert lit_for_sure.sum() >= 20 and (~certain).sum() < 80
    rows = np.flatnonzero((expected.max(-1) > 0).any(1))
    assert rows.max() < h // 4  # the ceiling light is in the top rows
    for seed in (1, 2):
        img = render(cornell_box, spp=1, max_depth=1, width=w, height=h, seed=seed)
        np.testing.assert_array_equal(img[certain], expected[certain].astype(np.float32))
        edge = img[~certain]
        assert np.all((edge == 0).all(-1) | (edge == le).all(-1))
    assert render(cornell_box, spp=1, max_depth=0, width=8, height=8).max() == 0.0


def test_deeper_paths_add_light():
    """Each extra bounce adds exactly the light of paths of that length: in the closed emissive cube,
    Le albedo^(d-1) for max depth d (a closed form, not just an increase). With the same seed the
    renders share their first bounces, so the differences are far less noisy than the images."""
    albedo = 0.6
    scene = interior_cube_furnace(albedo, radiance=2.0)
    means = [render(scene, spp=128, max_depth=d, width=16, height=16, seed=4).mean() for d in (1, 2, 3, 4)]
    assert means[0] == pytest.approx(2.0, rel=1e-6)  # depth 1: the emission itself, exactly
    for d in (2, 3, 4):
        assert means[d - 1] - means[d - 2] == pytest.approx(2.0 * albedo ** (d - 1), rel=0.03), d


def test_inf_samples_are_dropped_and_counted():
    """An emitter and a sky so bright that emission plus a light sample overflows to inf:
    those samples are dropped and counted, and the image stays finite."""
    scene = object_under_sky({"type": "diffuse", "reflectance": 0.9}, radiance=3.0e38)
    scene.meshes[0].emission = (3.0e38, 3.0e38, 3.0e38)
    for integrator in ("megakernel", "wavefront"):
        r = pyclpt.Renderer(scene, integrator=integrator, max_depth=2)
        img = r.render(1, seed=5, progress=False)
        assert np.isfinite(img).all()
        assert r.stats.dropped_samples > 20
        assert img[0, 0, 0] == pytest.approx(3.0e38, rel=1e-6)  # the sky itself is fine
        assert img[12, 12, 0] == 0.0  # the overflowing object pixels were dropped


def test_same_seed_same_image_different_seed_different_image(cornell_box):
    a = render(cornell_box, spp=2, width=16, height=16, seed=7)
    b = render(cornell_box, spp=2, width=16, height=16, seed=7)
    c = render(cornell_box, spp=2, width=16, height=16, seed=8)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_resolution_override_and_bad_arguments(cornell_box):
    img = render(cornell_box, spp=1, width=12, height=7)
    assert img.shape == (7, 12, 3) and img.dtype == np.float32
    with pytest.raises(ValueError, match="spp"):
        render(cornell_box, spp=0, width=4, height=4)
    with pytest.raises(ValueError, match="integrator"):
        render(cornell_box, spp=1, integrator="bogus")
    with pytest.raises(ValueError, match="max_depth"):
        render(cornell_box, spp=1, max_depth=-3)
    with pytest.raises(ValueError, match="seed"):
        render(cornell_box, spp=1, seed=-1)
