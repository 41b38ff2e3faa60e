"""The crop window (pyclpt.film.crop): a cropped film's pixels are the whole image's, bit for bit, on
both integrators and on each device, with the G-buffer; tiles put together give the image; bad
windows are refused by name."""
from __future__ import annotations

import numpy as np
import pytest

import pyclpt
from pyclpt.film.crop import Crop, tiles
from pyclpt.rendering.renderer import Renderer

W, H = 36, 27
CROPS = [(0, 0, W, H), (5, 7, 13, 9), (W - 1, H - 1, 1, 1), (0, 10, W, 5), (20, 0, 16, 27)]


@pytest.fixture(scope="module")
def gaussian_box():
    """The Cornell box through Mitsuba's default gaussian filter, on a thin lens: every random number the
    camera ray draws depends on the pixel's place."""
    return pyclpt.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 5},
        "sensor": {"type": "thinlens", "fov": 40, "aperture_radius": 0.05, "focus_distance": 3.5,
                   "to_world": {"look_at": {"origin": [0, 1, 3.8], "target": [0, 1, 0], "up": [0, 1, 0]}},
                   "film": {"type": "hdrfilm", "width": W, "height": H}},
        "floor": {"type": "rectangle", "to_world": [{"rotate": {"axis": [1, 0, 0], "angle": -90}}, {"scale": 2}],
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "checkerboard"}}},
        "ball": {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5,
                 "bsdf": {"type": "roughconductor", "alpha": 0.2}},
        "light": {"type": "rectangle",
                  "to_world": [{"translate": [0, 2.5, 0]}, {"rotate": {"axis": [1, 0, 0], "angle": 90}}],
                  "emitter": {"type": "area", "radiance": 8}},
    }, name="crop-scene")


@pytest.mark.parametrize("integrator", ["megakernel", "wavefront"])
def test_crop_is_the_image_window(device, cornell_box, gaussian_box, integrator):
    for scene in (cornell_box, gaussian_box):
        r = Renderer(scene, integrator=integrator, width=W, height=H, max_depth=5, device=device)
        full = r.render(6, seed=3, first_sample=2)
        for crop in CROPS:
            c = r.cropped(crop)
            assert c.scene_buffers is r.scene_buffers
            image = c.render(6, seed=3, first_sample=2)
            rows, cols = Crop(*crop).slices()
            assert image.shape == (crop[3], crop[2], 3)
            np.testing.assert_array_equal(image, full[rows, cols], err_msg=f"{scene.name} {crop}")


def test_crop_on_each_device(each_device, cornell_box):
    r = Renderer(cornell_box, width=W, height=H, max_depth=4, device=each_device)
    full = r.render_sum(3, seed=1)
    part = Renderer(cornell_box, width=W, height=H, max_depth=4, device=each_device, crop=(5, 7, 13, 9))
    np.testing.assert_array_equal(part.render_sum(3, seed=1), full[7:16, 5:18])


def test_crop_gbuffer(device, cornell_box):
    r = Renderer(cornell_box, integrator="wavefront", width=W, height=H, max_depth=4, device=device, aovs=True)
    r.render(3, seed=5)
    full = r.aovs()
    c = r.cropped((5, 7, 13, 9))
    c.render(3, seed=5)
    for name, value in c.aovs().items():
        np.testing.assert_array_equal(value, full[name][7:16, 5:18], err_msg=name)


def test_tiles_make_the_image(device, cornell_box):
    r = Renderer(cornell_box, width=W, height=H, max_depth=4, device=device)
    full = r.render(4, seed=9)
    out = np.full_like(full, np.nan)
    parts = tiles(W, H, 16, 10)
    assert len(parts) == 3 * 3 and sum(t.width * t.height for t in parts) == W * H
    for t in parts:
        out[t.slices()] = r.cropped(t).render(4, seed=9)
    np.testing.assert_array_equal(out, full)


@pytest.mark.parametrize("crop,message", [
    ((0, 0, W + 1, H), "reaches past the 36x27 image"),
    ((-1, 0, 4, 4), "crop x must be an integer in 0..35"),
    ((0, 27, 4, 4), "crop y must be an integer in 0..26"),
    ((0, 0, 0, 4), "crop width must be an integer >= 1"),
    ((30, 20, 10, 10), r"pixels x 30\.\.39"),
])
def test_bad_crop_named(device, cornell_box, crop, message):
    with pytest.raises(ValueError, match=message):
        Renderer(cornell_box, width=W, height=H, device=device, crop=crop)


@pytest.mark.parametrize("crop", [(0, 0, 4), "0,0,4,4", (0, 0, 4.0, 4)])
def test_crop_kind_named(device, cornell_box, crop):
    with pytest.raises(TypeError, match="crop must be four integers"):
        Renderer(cornell_box, width=W, height=H, device=device, crop=crop)


def test_scene_buffers_of_another_scene_refused(device, cornell_box, gaussian_box):
    r = Renderer(cornell_box, width=8, height=8, device=device)
    with pytest.raises(ValueError, match="scene_buffers must hold this scene"):
        Renderer(gaussian_box, width=8, height=8, device=device, scene_buffers=r.scene_buffers)
