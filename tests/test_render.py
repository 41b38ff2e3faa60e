"""Correctness of the renders: analytic scenes, Mitsuba's reference, depth semantics,
NaN/inf handling. Run on the megakernel and the wavefront (both layouts)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import pyclpt
from scenes import interior_furnace, object_under_sky

INTEGRATORS = [("megakernel", "soa"), ("wavefront", "soa"), ("wavefront", "aos")]
DATA = Path(__file__).parent / "data"


def render(scene, integrator="megakernel", layout="soa", **kw):
    return pyclpt.render(scene, integrator=integrator, layout=layout, progress=False, **kw)


@pytest.mark.parametrize("integrator,layout", INTEGRATORS)
@pytest.mark.parametrize("depth,albedo", [(1, 0.5), (2, 0.5), (3, 0.5), (-1, 0.5), (-1, 0.8)])
def test_interior_furnace(integrator, layout, depth, albedo):
    """Le * sum_{k<depth} albedo^k: exercises emission, NEE, MIS, depth and roulette."""
    scene = interior_furnace(albedo)
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
    """A lossless dielectric under a uniform sky: every path escapes with weight 1."""
    scene = object_under_sky({"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0}, radiance=1.0,
                             shape="sphere")
    img = render(scene, integrator, layout, spp=128, max_depth=-1, seed=3)
    assert img.mean() == pytest.approx(1.0, rel=0.01)


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
    img = render(cornell_box, spp=1, max_depth=1, width=32, height=32)
    lit = img.max(axis=2) > 0
    assert 0 < lit.sum() < 16  # the small ceiling light only
    assert lit[:8].all(axis=1).sum() == 0 or lit[:8].any()  # the light is in the top rows
    assert not lit[16:].any()
    assert render(cornell_box, spp=1, max_depth=0, width=8, height=8).max() == 0.0


def test_deeper_paths_add_light(cornell_box):
    means = [render(cornell_box, spp=8, max_depth=d, width=16, height=16, seed=4).mean() for d in (1, 2, 3)]
    assert means[0] < means[1] < means[2]


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
