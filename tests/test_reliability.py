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
