"""Reliability fixes: refused inputs fail up front with a clear message, counts and errors say what happened."""
from __future__ import annotations

import numpy as np
import pytest

import pyclpt
from pyclpt.cli import main


def test_sequence_counts_the_frames_really_written(tmp_path, capsys):
    pattern = str(tmp_path / "out_####.exr")
    rc = main(["render", "cornell-box", "--frames", "5", "--max-frames", "2", "--sequence", "-o", pattern,
               "--width", "8", "--height", "8", "--quiet"])
    out = capsys.readouterr().out
    assert rc == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out_0000.exr", "out_0001.exr"]
    assert "wrote 2 frames of 5" in out and "wrote 5 frames" not in out
    assert "out_0001.exr" in out and "out_0004.exr" not in out


@pytest.mark.parametrize("args, needle", [
    (["--spp", "4294967297"], "--spp must be an integer in 1..4294967296, got 4294967297"),
    (["--frames", "4294967297"], "--frames must be an integer in 1..4294967296, got 4294967297"),
])
def test_spp_over_the_limit_is_refused_up_front(tmp_path, capsys, monkeypatch, args, needle):
    def no_render(*_a, **_k):
        raise AssertionError("rendering started")

    monkeypatch.setattr(pyclpt.ProgressiveRenderer, "run", no_render)
    rc = main(["render", "cornell-box", *args, "-o", str(tmp_path / "x.exr"), "--width", "8", "--height", "8",
               "--quiet"])
    assert rc == 1
    assert needle in capsys.readouterr().err


@pytest.mark.parametrize("element", ['<float name="sample_count" value="1e20"/>',
                                     '<integer name="sample_count" value="100000000000000000000"/>'])
def test_scene_sample_count_over_the_limit_is_refused_up_front(tmp_path, capsys, monkeypatch, element):
    scene = tmp_path / "big.xml"
    scene.write_text(f"""<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="39"/>
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent">{element}</sampler>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
    <shape type="sphere"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
</scene>""")

    def no_render(*_a, **_k):
        raise AssertionError("rendering started")

    monkeypatch.setattr(pyclpt.ProgressiveRenderer, "run", no_render)
    rc = main(["render", str(scene), "-o", str(tmp_path / "x.exr"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 1, err
    assert "must be an integer in 1..4294967296, got 100000000000000000000" in err, err
    assert not (tmp_path / "x.exr").exists()


@pytest.mark.parametrize("value", ["3x", "x3", "3x3x3"])
def test_cli_bad_tile_is_an_error(capsys, value):
    with pytest.raises(SystemExit):
        main(["render", "cornell-box", "--workers", "2", "--tile", value])
    assert f"--tile: expected N or WxH pixels (0: no tiles), got '{value}'" in capsys.readouterr().err


RED = "red.reflectance.value"
LIGHT = "light.emitter.radiance.value"


def test_failed_update_writes_nothing_later():
    """One NaN among good values in one update: nothing is written, then or by the next update."""
    box = pyclpt.load("cornell-box")
    params = pyclpt.traverse(box)
    red, light = params[RED], params[LIGHT]
    with pytest.raises(ValueError, match=f"{LIGHT}: values must be finite"):
        params.update({RED: [0.1, 0.2, 0.3], LIGHT: [1.0, np.nan, 1.0]})
    np.testing.assert_array_equal(params[RED], red)  # not staged either
    params.update({"green.reflectance.value": [0.5, 0.5, 0.5]})  # an unrelated update
    np.testing.assert_array_equal(params[RED], red)
    np.testing.assert_array_equal(params[LIGHT], light)
    np.testing.assert_allclose(params["green.reflectance.value"], 0.5)
    with pytest.raises(KeyError, match="no parameter"):
        params.update({RED: [0.1, 0.2, 0.3], "nothing.value": 1.0})
    assert params.update() == []


def test_render_backward_takes_one_parameter_name():
    box = pyclpt.load("cornell-box")
    grad = np.full((8, 8, 3), 1.0 / 192, np.float32)
    one = pyclpt.render_backward(box, grad, spp=1, seed=4, width=8, height=8, params=RED)
    assert list(one) == [RED] and one[RED].shape == (3,)
    listed = pyclpt.render_backward(box, grad, spp=1, seed=4, width=8, height=8, params=[RED])
    np.testing.assert_array_equal(one[RED], listed[RED])
    with pytest.raises(TypeError, match="params must be a parameter name, a sequence of names"):
        pyclpt.render_backward(box, grad, spp=1, seed=4, width=8, height=8, params=7)
    with pytest.raises(TypeError, match="params must be a parameter name, a sequence of names"):
        pyclpt.render_backward(box, grad, spp=1, seed=4, width=8, height=8, params=[RED, 3])


def test_cluster_render_spp_over_the_limit_is_refused_before_connecting(tmp_path, capsys):
    pytest.importorskip("distributed")
    rc = main(["render", "cornell-box", "--spp", "4294967297", "--scheduler", "tcp://127.0.0.1:1",
               "-o", str(tmp_path / "x.exr"), "--quiet"])  # no scheduler there: refused before connecting
    assert rc == 1
    assert "--spp must be an integer in 1..4294967296, got 4294967297" in capsys.readouterr().err


def _fresh_backward(scene, grad, **kw):
    """The gradient from a device copy built now (what an edited scene must give)."""
    from pyclpt.gradients import clear_cache

    clear_cache()
    return pyclpt.render_backward(scene, grad, **kw)


def test_render_backward_sees_vertices_moved_in_place():
    box = pyclpt.load("cornell-box")
    grad = np.full((8, 8, 3), 1.0 / 192, np.float32)
    kw = dict(spp=4, seed=4, width=8, height=8, params=RED)
    before = pyclpt.render_backward(box, grad, **kw)[RED]
    small = next(m for m in box.meshes if m.name == "small-box")
    small.positions[:, 1] += 0.25  # in place: no field assigned, no update()
    after = pyclpt.render_backward(box, grad, **kw)[RED]
    assert not np.allclose(after, before)
    np.testing.assert_allclose(after, _fresh_backward(box, grad, **kw)[RED], rtol=1e-4, atol=1e-7)


def test_render_backward_sees_texels_edited_in_place():
    from gradient_scenes import textured_quad

    scene = textured_quad(np.full((4, 4, 3), 0.5, np.float32), size=8)
    grad = np.full((8, 8, 3), 1.0 / 192, np.float32)
    name = next(n for n in pyclpt.traverse(scene) if n.startswith("sky"))
    kw = dict(spp=2, seed=3, params=name)
    before = pyclpt.render_backward(scene, grad, **kw)[name]
    tex = scene.materials[0].reflectance
    tex.pixels[...] = 0.125  # in place
    after = pyclpt.render_backward(scene, grad, **kw)[name]
    assert not np.allclose(after, before)
    np.testing.assert_allclose(after, _fresh_backward(scene, grad, **kw)[name], rtol=1e-4, atol=1e-7)
    tex.pixels[1, 2, 0] = np.nan  # a NaN texel: the usual validation error, not a silent gradient
    with pytest.raises(ValueError, match="NaN") as caught:
        pyclpt.render_backward(scene, grad, **kw)
    with pytest.raises(ValueError) as fresh:
        scene.validate()
    assert str(caught.value) == str(fresh.value)
    with pytest.raises(ValueError, match="NaN"):  # still refused on the next call
        pyclpt.render_backward(scene, grad, **kw)
    tex.pixels[1, 2, 0] = 0.125
    np.testing.assert_allclose(pyclpt.render_backward(scene, grad, **kw)[name], after, rtol=1e-4, atol=1e-7)


def test_scene_files_lists_every_file_the_loaders_read(tmp_path):
    """Scene.files: the scene file, its includes, meshes and textures (what the distributed workers'
    renderer cache is keyed on, by modification time and size)."""
    import shutil
    from pathlib import Path

    shutil.copy(Path(__file__).parent / "data" / "glyph.png", tmp_path / "glyph.png")
    (tmp_path / "quad.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n")
    (tmp_path / "part.xml").write_text(
        '<scene version="3.0.0"><shape type="obj"><string name="filename" value="quad.obj"/>'
        '<bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        '<string name="filename" value="glyph.png"/></texture></bsdf></shape></scene>')
    (tmp_path / "main.xml").write_text(
        '<scene version="3.0.0"><include filename="part.xml"/>'
        '<emitter type="constant"><rgb name="radiance" value="1"/></emitter></scene>')
    files = pyclpt.load(str(tmp_path / "main.xml")).files
    assert files[0] == tmp_path / "main.xml"
    assert {p.name for p in files} == {"main.xml", "part.xml", "quad.obj", "glyph.png"}
    assert all(p.is_absolute() for p in files) and len(set(files)) == len(files)
    assert pyclpt.load("cornell-box").files[0].name == "cornell-box.json"


def test_exposure_is_ignored_with_a_warning_for_linear_output(tmp_path, caplog):
    """--exposure is for PNG/JPEG: an EXR keeps the radiance as rendered, with or without --aov."""
    base = ["render", "cornell-box", "--width", "8", "--height", "8", "--spp", "2", "--quiet"]
    assert main([*base, "-o", str(tmp_path / "plain.exr")]) == 0
    caplog.clear()
    with caplog.at_level("WARNING", logger="pyclpt"):
        assert main([*base, "--exposure", "2", "-o", str(tmp_path / "bright.exr")]) == 0
    assert any(r.name.startswith("pyclpt") and "--exposure 2" in r.getMessage() and "bright.exr" in r.getMessage()
               for r in caplog.records), caplog.text
    np.testing.assert_array_equal(pyclpt.read_image(tmp_path / "bright.exr"), pyclpt.read_image(tmp_path / "plain.exr"))
    caplog.clear()
    with caplog.at_level("WARNING", logger="pyclpt"):
        assert main([*base, "--exposure", "2", "--aov", "albedo", "-o", str(tmp_path / "aov.exr")]) == 0
    assert any("--exposure 2" in r.getMessage() and "--aov" in r.getMessage() for r in caplog.records), caplog.text
    # In Python too; an 8-bit file still gets the exposure.
    image = np.full((2, 2, 3), 0.1, np.float32)
    caplog.clear()
    with caplog.at_level("WARNING", logger="pyclpt"):
        pyclpt.write_image(tmp_path / "py.exr", image, exposure=3)
    assert "exposure 3" in caplog.text and "py.exr" in caplog.text
    np.testing.assert_array_equal(pyclpt.read_image(tmp_path / "py.exr"), image)
    pyclpt.write_image(tmp_path / "dark.png", image, exposure=0)
    pyclpt.write_image(tmp_path / "light.png", image, exposure=2)
    assert pyclpt.read_image(tmp_path / "light.png").mean() > pyclpt.read_image(tmp_path / "dark.png").mean()


def test_camera_path_between_mirrored_and_unmirrored_keyframes_is_refused():
    from pyclpt.scene.model import Camera

    plain = Camera(np.eye(4), 40.0)
    mirrored = Camera(np.diag([-1.0, 1.0, 1.0, 1.0]), 40.0)
    with pytest.raises(ValueError, match=r"keyframes at frames 0 and 10 differ in handedness.*degenerate camera"):
        pyclpt.CameraPath([pyclpt.Keyframe(0, plain), pyclpt.Keyframe(10, mirrored)])
    with pytest.raises(ValueError, match=r"frames 10 and 20"):
        pyclpt.CameraPath([pyclpt.Keyframe(0, mirrored), pyclpt.Keyframe(10, mirrored), pyclpt.Keyframe(20, plain)])
    path = pyclpt.CameraPath([pyclpt.Keyframe(0, mirrored), pyclpt.Keyframe(10, mirrored)])
    assert np.linalg.det(np.asarray(path.camera(5).to_world)[:3, :3]) == pytest.approx(-1.0)


@pytest.mark.parametrize("make, needle", [
    (lambda: pyclpt.Diffuse(reflectance=(0.5, 1e39, 0.5)), "diffuse reflectance"),
    (lambda: pyclpt.PointLight(position=(0, 0, 0), intensity=1e39), "point light intensity"),
    (lambda: pyclpt.Mesh("lamp", np.zeros((3, 3)), np.array([[0, 1, 2]]), 0, emission=1e39), "lamp"),
])
def test_values_infinite_in_float32_are_refused(make, needle):
    with pytest.raises(ValueError, match="not finite in float32") as caught:
        make()
    assert needle in str(caught.value)


def test_float32_overflow_found_by_scene_validate():
    scene = pyclpt.load("cornell-box")
    scene.materials[0].__dict__["reflectance"] = (1e39, 0.5, 0.5)  # past the assignment check
    with pytest.raises(ValueError, match="not finite in float32"):
        scene.validate()


def test_adam_refuses_zero_epsilon_and_non_finite_steps():
    with pytest.raises(ValueError, match="epsilon must be a finite number > 0, got 0"):
        pyclpt.optim.Adam(epsilon=0)
    opt = pyclpt.optim.Adam(lr=1e300, params={"x": np.zeros(3, np.float32)})
    with pytest.raises(ValueError, match=r"step 1 of x .*not finite in float32.*lr=1e\+300"):
        opt.step({"x": np.ones(3)})
    np.testing.assert_array_equal(opt["x"], np.zeros(3))  # unchanged
    opt = pyclpt.optim.Adam(params={"x": np.zeros(3, np.float32)})
    opt.step({"x": np.zeros(3)})
    assert np.all(np.isfinite(opt["x"]))


def _corrupt(path, **changes):
    with np.load(path) as z:
        arrays = {k: z[k].copy() for k in z.files}
    for k, f in changes.items():
        arrays[k] = f(arrays[k])
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


@pytest.mark.parametrize("change, needle", [
    ({"tri_order": lambda a: a + 1000}, "tri_order"),
    ({"nodes": lambda a: np.full_like(a, np.nan)}, "NaN"),
    ({"nodes": lambda a: a[:0]}, "nodes"),
    ({"tris": lambda a: a * 2}, "tris"),
])
def test_wrong_bvh_cache_entry_is_rebuilt_with_a_warning(tmp_path, monkeypatch, caplog, change, needle):
    from pyclpt.accel import bvh as bvh_mod

    monkeypatch.setenv("PYCLPT_CACHE_DIR", str(tmp_path))
    rng = np.random.default_rng(3)
    pos = rng.random((60, 3)).astype(np.float32)
    idx = rng.integers(0, 60, (40, 3))
    fresh = bvh_mod.build_bvh(pos, idx)
    cached = bvh_mod.build_bvh(pos, idx)
    assert cached.build_seconds == 0.0  # a good entry is used
    (entry,) = (tmp_path / "bvh").glob("*.npz")
    _corrupt(entry, **change)
    with caplog.at_level("WARNING", logger="pyclpt"):
        rebuilt = bvh_mod.build_bvh(pos, idx)
    assert rebuilt.build_seconds > 0.0
    np.testing.assert_array_equal(rebuilt.nodes, fresh.nodes)
    np.testing.assert_array_equal(rebuilt.tri_order, fresh.tri_order)
    assert str(entry) in caplog.text and needle in caplog.text, caplog.text
    assert bvh_mod.build_bvh(pos, idx).build_seconds == 0.0  # rewritten


def test_emission_aov_of_a_huge_emitter_stays_finite(tmp_path):
    """The G-buffer sums are scaled so that values up to FLT_MAX over many frames do not overflow."""
    scene = pyclpt.load("cornell-box")
    light = next(m for m in scene.meshes if m.emission is not None)
    light.emission = (3e38, 3e38, 3e38)
    image, aov = pyclpt.render(scene, spp=4, width=16, height=16, aovs=["emission"], max_depth=1)
    emission = aov["emission"]
    assert np.all(np.isfinite(emission)) and emission.max() > 1e38
    np.testing.assert_array_equal(emission, image)  # max_depth 1: the image is what the first vertex emits


def test_render_backward_of_a_huge_finite_image_gradient_stays_finite():
    """The gradient is linear in image_grad: a finite 3e38 one (float32's range ends at 3.4e38) gives the
    gradient of a 1 scaled by 3e38 where that is representable, never inf; beyond float32's range an
    OverflowError names the element and its value."""
    box = pyclpt.load("cornell-box")
    kw = dict(spp=1, seed=4, width=8, height=8, params=[RED, LIGHT])
    unit = np.full((8, 8, 3), 1.0, np.float32)
    small = np.full((8, 8, 3), 1.0 / 192, np.float32)
    ref = pyclpt.render_backward(box, unit, **kw)
    scale = 1e38 / max(float(np.max(np.abs(g))) for g in ref.values())  # the largest gradient becomes 1e38
    huge = pyclpt.render_backward(box, unit * np.float32(scale), **kw)
    for name in ref:
        assert np.all(np.isfinite(huge[name])), (name, huge[name])
        np.testing.assert_allclose(huge[name], ref[name].astype(np.float64) * np.float32(scale), rtol=1e-5)
    assert max(float(np.abs(g).max()) for g in huge.values()) > 9.9e37
    # the same gradient for an image_grad 192 times smaller, up to that factor (linear, no scaling below 1)
    np.testing.assert_allclose(pyclpt.render_backward(box, small, **kw)[RED] * 192, ref[RED], rtol=1e-5)
    with pytest.raises(OverflowError, match=r"the gradient of .*\[\d\] is -?[\d.]+e\+\d+, beyond float32's range"):
        pyclpt.render_backward(box, np.full((8, 8, 3), 3e38, np.float32), **kw)
