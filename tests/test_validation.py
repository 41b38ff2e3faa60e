"""Checks of what users hand to pyclpt: API arguments (pyclpt.common.checks) and scene values,
on load and when changed afterwards (pyclpt.scene.model, Scene.validate before every upload)."""
from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

import pyclpt
from pyclpt.buffers.scene import pack_scene
from pyclpt.common.checks import check_bool, check_choice, check_float, check_int, check_optional_bool
from pyclpt.device.context import get_device
from pyclpt.film.accumulator import Accumulator, AccumulatorError
from pyclpt.scene.model import Bitmap, BumpMap, Checkerboard, Diffuse, Envmap, Film, Mask
from pyclpt.scene.textures import load_bitmap

SMALL = dict(width=8, height=6)


@pytest.fixture
def scene() -> pyclpt.Scene:
    """A private cornell box: these tests change it."""
    return pyclpt.load("cornell-box")


@pytest.fixture(scope="module")
def renderer(device, cornell_box) -> pyclpt.Renderer:
    return pyclpt.Renderer(cornell_box, device=device, max_depth=2, **SMALL)


# -- the checks themselves --------------------------------------------------------------------------

def test_check_int_wording_and_kinds():
    assert check_int(np.int64(5), "n", lo=1) == 5 and type(check_int(np.uint32(5), "n")) is int
    for bad in (True, np.bool_(True), 1.5, 2.0, "7", None, [1]):
        with pytest.raises(TypeError, match=r"^n must be an integer in 1..9, got \w+ "):
            check_int(bad, "n", lo=1, hi=9)
    with pytest.raises(ValueError, match=r"^n must be an integer in 1..9, got 0$"):
        check_int(0, "n", lo=1, hi=9)
    with pytest.raises(AccumulatorError, match=r"n must be an integer >= 2 \(note\), got 1"):
        check_int(1, "n", lo=2, error=AccumulatorError, note=" (note)")
    assert check_float(np.float32(0.5), "x", lo=0, hi=1) == 0.5 and check_float(2, "x") == 2.0
    for bad in (True, "0.5", None):
        with pytest.raises(TypeError, match="x must be a number"):
            check_float(bad, "x")
    for bad in (float("nan"), float("inf"), -0.1):
        with pytest.raises(ValueError, match="x must be a finite number"):
            check_float(bad, "x", lo=0)
    assert check_bool(np.bool_(True), "b") is True
    for bad in (1, 0, "yes", None):
        with pytest.raises(TypeError, match="b must be True or False"):
            check_bool(bad, "b")
    assert check_optional_bool(None, "p") is None
    with pytest.raises(TypeError, match="p must be True, False or None, got int 1"):
        check_optional_bool(1, "p")
    assert check_choice("b", "mode", ("a", "b")) == "b"
    with pytest.raises(ValueError, match=r"unknown mode 'c' \(choose from a, b\)"):
        check_choice("c", "mode", ("a", "b"))
    with pytest.raises(TypeError, match="mode must be one of a, b, got int 1"):
        check_choice(1, "mode", ("a", "b"))


# -- API arguments ---------------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, error, needle", [
    (dict(seed=1.5), TypeError, "seed must be an integer .*got float 1.5"),
    (dict(seed="7"), TypeError, "seed must be an integer .*got str '7'"),
    (dict(seed=-1), ValueError, "seed must be an integer in 0..4294967295, got -1"),
    (dict(max_depth=1.7), TypeError, "max_depth must be an integer .*got float 1.7"),
    (dict(spp=True), TypeError, "spp must be an integer .*got bool True"),
    (dict(spp="4"), TypeError, "spp must be an integer .*got str '4'"),
    (dict(spp=0), ValueError, "spp must be an integer in 1"),
    (dict(width=0), ValueError, "width must be an integer in 1..65536 .*got 0"),
    (dict(height=0), ValueError, "height must be an integer in 1..65536 .*got 0"),
    (dict(width=8.0), TypeError, "width must be an integer"),
    (dict(device=123), TypeError, r"device must be a pyclpt.Device, a selector string .* got int 123"),
    (dict(progress=1), TypeError, "progress must be True, False or None"),
    (dict(integrator=1), TypeError, "integrator must be one of megakernel, wavefront"),
    (dict(layout="aosoa"), ValueError, "unknown layout 'aosoa'"),
    (dict(wave_size=0), ValueError, "wave_size must be an integer >= 1, got 0"),
    (dict(precision="quad"), AccumulatorError, "'quad'"),
])
def test_render_refuses_bad_arguments(cornell_box, kwargs, error, needle):
    with pytest.raises(error, match=needle):
        pyclpt.render(cornell_box, **{"spp": 1, **SMALL, **kwargs})


def test_render_refuses_what_is_not_a_scene():
    with pytest.raises(TypeError, match="scene must be a pyclpt.Scene .*got int 123"):
        pyclpt.render(123, spp=1)


def test_numpy_integers_are_integers(cornell_box):
    plain = pyclpt.render(cornell_box, spp=1, seed=3, max_depth=2, **SMALL)
    numpy = pyclpt.render(cornell_box, spp=np.int64(1), seed=np.uint32(3), max_depth=np.int8(2),
                          width=np.int32(8), height=np.int16(6))
    assert numpy.shape == (6, 8, 3) and np.array_equal(plain, numpy)


def test_renderer_refuses_bad_arguments(renderer):
    for kwargs, error, needle in [
        (dict(spp=True), TypeError, "spp must be an integer"),
        (dict(spp=1, seed=1.5), TypeError, "seed must be an integer"),
        (dict(spp=1, seed=2**32), ValueError, "seed must be an integer in 0..4294967295"),
        (dict(spp=1, first_sample=-1), ValueError, "first_sample must be an integer"),
        (dict(spp=4, first_sample=2**32 - 2), ValueError, "first_sample .* 32-bit"),
        (dict(spp=1, progress="yes"), TypeError, "progress must be True, False or None"),
    ]:
        with pytest.raises(error, match=needle):
            renderer.render(**kwargs)
    assert renderer.render(np.int64(1), seed=np.int32(1), progress=False).shape == (6, 8, 3)


def test_renderer_width_zero_is_an_error_and_none_the_scenes(cornell_box, device):
    with pytest.raises(ValueError, match="width must be an integer in 1..65536"):
        pyclpt.Renderer(cornell_box, device=device, width=0, height=6)
    with pytest.raises(TypeError, match="local_size must be an integer"):
        pyclpt.Renderer(cornell_box, device=device, local_size=64.0, **SMALL)
    with pytest.raises(TypeError, match="scene must be a pyclpt.Scene"):
        pyclpt.Renderer("cornell-box", device=device)


def test_progressive_renderer_refuses_bad_arguments(cornell_box, device):
    base = dict(device=device, max_depth=2, **SMALL)
    for kwargs, error, needle in [
        (dict(seed=1.5), TypeError, "seed must be an integer"),
        (dict(width=0, height=6), ValueError, "width must be an integer in 1..65536"),
        (dict(width=8.0, height=6), TypeError, "width must be an integer"),
        (dict(auto_reset="yes"), TypeError, "auto_reset must be True or False"),
        (dict(max_frame_count=1.5), TypeError, "max_frame_count must be an integer"),
        (dict(max_depth="2"), TypeError, "max_depth must be an integer"),
    ]:
        with pytest.raises(error, match=needle):
            pyclpt.ProgressiveRenderer(cornell_box, **{**base, **kwargs})
    pr = pyclpt.ProgressiveRenderer(cornell_box, **base)
    for call, error, needle in [
        (lambda: pr.step(1.5), TypeError, "frames must be an integer >= 0, got float 1.5"),
        (lambda: pr.step(-1), ValueError, "frames must be an integer >= 0, got -1"),
        (lambda: pr.run(True), TypeError, "frames must be an integer >= 1, got bool True"),
        (lambda: pr.run(1, progress=2), TypeError, "progress must be True, False or None"),
        (lambda: pr.set_resolution(8.0, 6), TypeError, "width must be an integer"),
        (lambda: pr.set_resolution(8, 0), ValueError, "height must be an integer in 1..65536, got 0"),
        (lambda: pr.set_emission(1.0, 2.0), TypeError, "mesh must be a mesh index or name, got float 1.0"),
    ]:
        with pytest.raises(error, match=needle):
            call()
    assert pr.step(np.int64(1)) == 1 and pr.sample_index == 1


def test_accumulator_refuses_bad_arguments(device):
    for kwargs, error, needle in [
        (dict(width=4.0), TypeError, "accumulator width must be an integer"),
        (dict(height=0), AccumulatorError, "accumulator height must be an integer in 1..65536, got 0"),
        (dict(channels=True), TypeError, "channels must be an integer in 1..4, got bool True"),
        (dict(enabled=1), TypeError, "enabled must be True or False"),
        (dict(local_size=8), TypeError, "local_size must be a pair of integers"),
        (dict(local_size=(8.0, 1)), TypeError, "local_size must be an integer"),
        (dict(force_emulated_double="no"), TypeError, "force_emulated_double must be True or False"),
    ]:
        with pytest.raises(error, match=needle):
            Accumulator(device, **{"width": 4, "height": 3, **kwargs})


def test_get_device_refuses_other_types():
    for bad in (123, 1.5, ["pocl"]):
        with pytest.raises(TypeError, match="device must be a pyclpt.Device, a selector string"):
            get_device(bad)


# -- scene values, on load and when changed --------------------------------------------------------

@pytest.mark.parametrize("value", [(-3, 0, 0), (float("nan"), 0.5, 0.5), float("inf"), "red"])
def test_material_values_are_checked_when_assigned(scene, value):
    mat = scene.materials[0]
    before = mat.reflectance
    with pytest.raises(ValueError, match="diffuse reflectance: expected a number or 3 finite numbers >= 0"):
        mat.reflectance = value
    assert mat.reflectance == before  # a refused value leaves the old one
    with pytest.raises(ValueError, match="diffuse reflectance"):
        Diffuse(reflectance=value)


def test_every_material_kind_refuses_negative_colours():
    with pytest.raises(ValueError, match="plastic diffuse_reflectance"):
        pyclpt.Plastic(diffuse_reflectance=-0.1)
    with pytest.raises(ValueError, match="conductor k"):
        pyclpt.Conductor(k=(1, -1, 1))
    with pytest.raises(ValueError, match="dielectric specular_transmittance"):
        pyclpt.Dielectric(specular_transmittance=(0, float("nan"), 0))
    with pytest.raises(ValueError, match="mask opacity"):
        Mask(-0.5, Diffuse())
    with pytest.raises(TypeError, match="mask material: expected a pyclpt material"):
        Mask(0.5, "diffuse")
    with pytest.raises(TypeError, match="diffuse twosided must be True or False"):
        Diffuse(twosided="yes")
    with pytest.raises(ValueError, match="roughness alpha"):
        pyclpt.Conductor(alpha=float("nan"))


def test_colour_textures_must_be_non_negative_and_bump_heights_may_be():
    negative = Bitmap(np.full((2, 3, 3), -0.25, np.float32), name="dent.exr", srgb=False)
    with pytest.raises(ValueError, match=r"diffuse reflectance: texture 'dent.exr': texel \(row 0, column 0, "
                                         r"channel 0\) is -0.25 \(18 bad values\); a colour must be >= 0"):
        Diffuse(reflectance=negative)
    with pytest.raises(ValueError, match="texture 'checkerboard' color1"):
        Diffuse(reflectance=Checkerboard(color1=(0.2, -0.2, 0.2)))
    BumpMap(negative, Diffuse())  # heights may be negative


def test_mesh_emission_is_checked_when_assigned(scene):
    light = next(m for m in scene.meshes if m.emission is not None)
    before = light.emission
    for bad in ((-1.0, 0.0, 0.0), (float("nan"),) * 3):
        with pytest.raises(ValueError, match=f"mesh {light.name!r}"):
            light.emission = bad
    assert light.emission == before
    with pytest.raises(TypeError, match=f"mesh {light.name!r} material must be an integer"):
        light.material = 0.5
    with pytest.raises(ValueError, match="environment radiance: expected a number or 3 finite numbers >= 0"):
        scene.environment = (-1, 0, 0)
    with pytest.raises(TypeError, match="spp must be an integer >= 1, got float 1.5"):
        scene.spp = 1.5
    with pytest.raises(TypeError, match="film width must be an integer"):
        Film(width=True)


def test_changes_no_assignment_sees_are_caught_before_upload(scene, device):
    """Arrays changed in place and list items replaced: Scene.validate, run before every upload,
    names the element."""
    scene.meshes[2].positions[1, 0] = np.nan
    with pytest.raises(ValueError, match=f"mesh {scene.meshes[2].name!r}: vertex 1 has a NaN"):
        pack_scene(scene)
    scene = pyclpt.load("cornell-box")
    scene.meshes[0].normals = np.ones_like(scene.meshes[0].positions)
    scene.meshes[0].normals[3] = np.inf
    with pytest.raises(ValueError, match="vertex 3 has NaN or infinite normals"):
        pyclpt.Renderer(scene, device=device, **SMALL)
    scene = pyclpt.load("cornell-box")
    scene.materials[1] = "green"
    with pytest.raises(TypeError, match=r"scene 'cornell-box' materials\[1\]: expected Diffuse"):
        pyclpt.render(scene, spp=1, device=device, **SMALL)
    scene = pyclpt.load("cornell-box")
    tex = Bitmap(np.full((2, 2, 3), 0.5, np.float32), name="wood.png")
    scene.materials[2].reflectance = tex
    tex.pixels[1, 0, 2] = -3.0
    users = ", ".join(repr(m.name) for m in scene.meshes if m.material == 2)
    with pytest.raises(ValueError, match=rf"material 2 \(Diffuse, used by {users}\): diffuse reflectance: "
                                         rf"texture 'wood.png': texel \(row 1, column 0, channel 2\) is -3.0"):
        pyclpt.render(scene, spp=1, device=device, **SMALL)
    tex.pixels[1, 0, 2] = np.nan
    with pytest.raises(ValueError, match=r"texture 'wood.png': texel \(row 1, column 0, channel 2\) is nan"):
        pack_scene(scene)


def test_progressive_renderer_refuses_bad_changes(device):
    scene = pyclpt.load("cornell-box")
    pr = pyclpt.ProgressiveRenderer(scene, device=device, max_depth=2, **SMALL)
    pr.step(2)
    with pytest.raises(TypeError, match="material 0: expected a pyclpt material"):
        pr.set_material(0, "red")
    opacity = Bitmap(np.full((1, 1, 1), 0.5), name="cut-out")
    mask = Mask(opacity, Diffuse())
    opacity.pixels[0, 0, 0] = -1.0  # in place, after the mask checked it
    with pytest.raises(ValueError, match=r"material 1: mask opacity: texture 'cut-out': texel \(row 0, column 0, "
                                         r"channel 0\) is -1.0; a colour must be >= 0"):
        pr.set_material(-2, mask)
    assert isinstance(scene.materials[0], Diffuse) and isinstance(scene.materials[1], Diffuse)
    x = scene.camera.to_world[0, 3]
    scene.camera.to_world[0, 3] = np.nan  # in place: only the next frame's sync can see it
    with pytest.raises(ValueError, match="camera to_world holds NaN"):
        pr.step(1)
    scene.camera.to_world[0, 3] = x
    scene.meshes[1].positions[0, 1] = np.inf
    with pytest.raises(ValueError, match=f"mesh {scene.meshes[1].name!r}: vertex 0"):
        pr.step(1)
    assert pr.sample_index == 2  # nothing was rendered with the bad values


def test_envmap_texels_must_be_finite_and_non_negative(device):
    pixels = np.full((4, 8, 3), 0.5, np.float32)
    pixels[2, 5, 1] = np.inf
    with pytest.raises(ValueError, match=r"environment map 'sky.exr': texel \(row 2, column 5, channel 1\) is inf; "
                                         r"values must be finite and >= 0"):
        Envmap(pixels, name="sky.exr")
    env = Envmap(np.full((4, 8, 3), 0.5, np.float32), name="sky.exr")
    with pytest.raises(ValueError, match="'sky.exr': scale must be >= 0"):
        env.scale = -1.0
    scene = pyclpt.load("cornell-box")
    scene.environment = env
    env.pixels[0, 0, 0] = -2.0
    with pytest.raises(ValueError, match=r"environment map 'sky.exr': texel \(row 0, column 0, channel 0\) is -2.0"):
        pyclpt.render(scene, spp=1, device=device, **SMALL)


def _write_exr(path, pixels: np.ndarray) -> None:
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], "float"))
    assert out.write_image(pixels.astype(np.float32))
    out.close()


def test_texture_and_envmap_files_with_nan_texels_are_refused(tmp_path):
    """They used to be read with the NaN and inf texels silently set to zero."""
    pixels = np.full((4, 8, 3), 0.25, np.float32)
    pixels[3, 1, 0] = np.nan
    _write_exr(tmp_path / "broken.exr", pixels)
    with pytest.raises(ValueError, match=r"texture 'broken.exr': texel \(row 3, column 1, channel 0\) is nan"):
        load_bitmap(tmp_path / "broken.exr")
    scene = {"type": "scene", "shape": {"type": "rectangle", "bsdf": {"type": "diffuse"}},
             "sky": {"type": "envmap", "filename": str(tmp_path / "broken.exr")}}
    with pytest.raises(pyclpt.SceneDictError, match=r"'broken.exr': texel \(row 3, column 1, channel 0\) is nan"):
        pyclpt.load_dict(scene)
