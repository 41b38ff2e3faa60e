"""The ``pyclpt`` command line, run in-process (plus one subprocess run of the console script)."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import pyclpt
from pyclpt.cli import main

REPO = Path(__file__).resolve().parent.parent


def _json_after_summary(out: str) -> dict:
    return json.loads(out[out.index("\n{") + 1:])


def test_render_exr(tmp_path, capsys, device):
    out = tmp_path / "x.exr"
    rc = main(["render", "cornell-box", "--spp", "2", "--width", "24", "--height", "16", "-o", str(out),
               "--quiet"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    image = pyclpt.read_image(out)
    assert image.shape == (16, 24, 3)
    assert np.all(np.isfinite(image))
    assert 0.05 < image.mean() < 5.0  # a lit Cornell box, not black
    lines = captured.out.strip().splitlines()
    assert len(lines) == 1
    assert re.match(rf"{re.escape(str(out))}: 24x16, 2 spp, max depth 8, megakernel on .+: "
                    r"render [\d.]+ s, compile [\d.]+ s, setup [\d.]+ s, total [\d.]+ s$", lines[0]), lines[0]
    assert device.name in lines[0]


def test_render_stats_prints_kernels(tmp_path, capsys):
    rc = main(["render", "cornell-box", "--spp", "1", "--width", "16", "--height", "16", "--max-depth", "3",
               "-o", str(tmp_path / "s.exr"), "--stats", "--quiet"])
    out = capsys.readouterr().out
    assert rc == 0
    assert "max depth 3" in out.splitlines()[0]
    stats = _json_after_summary(out)
    assert set(stats) >= {"kernels", "bounces", "dropped_samples"}
    assert stats["kernels"], stats
    assert all("kernel" in k for k in stats["kernels"])
    assert stats["dropped_samples"] == 0


def test_render_wavefront_aos(tmp_path, capsys):
    out = tmp_path / "w.png"
    rc = main(["render", "cornell-box", "--spp", "2", "--width", "16", "--height", "16",
               "--integrator", "wavefront", "--layout", "aos", "-o", str(out), "--stats", "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0
    assert "wavefront/aos" in text.splitlines()[0]
    stats = _json_after_summary(text)
    names = {k["kernel"] for k in stats["kernels"]}
    assert {"intersect", "process_hit"} <= names
    assert stats["bounces"] and stats["bounces"][0]["rays"] == 16 * 16 * 2
    assert pyclpt.read_image(out).shape == (16, 16, 3)
    assert out.read_bytes()[:4] == b"\x89PNG"


def test_render_default_output_name(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc = main(["render", "cornell-box", "--spp", "1", "--width", "8", "--height", "8", "--quiet"])
    assert rc == 0, capsys.readouterr().err
    assert (tmp_path / "cornell-box.png").is_file()


def test_devices_lists_pocl(capsys):
    assert main(["devices"]) == 0
    out = capsys.readouterr().out
    assert "Portable Computing Language" in out
    assert re.search(r"^0:0 ", out, re.M)


def test_scenes_lists_builtins(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    names = [ln.split()[0] for ln in out.strip().splitlines()]
    assert "cornell-box" in names and "cornell-bunny" in names
    assert "Mitsuba" in out  # descriptions are printed


@pytest.mark.parametrize("args, needle", [
    (["--spp", "0"], "got 0"),
    (["--spp", "x"], "got 'x'"),
    (["--spp", "-3"], "got -3"),
    (["--width", "0"], "got 0"),
    (["--max-depth", "-5"], "got -5"),
    (["--max-depth", "deep"], "got 'deep'"),
    (["--seed", "-1"], "got -1"),
    (["--integrator", "nope"], "'nope'"),
    (["--layout", "zigzag"], "'zigzag'"),
])
def test_bad_arguments_exit_2(tmp_path, capsys, args, needle):
    with pytest.raises(SystemExit) as info:
        main(["render", "cornell-box", "-o", str(tmp_path / "x.exr"), *args])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert needle in err
    assert args[0] in err  # argparse names the option
    assert not (tmp_path / "x.exr").exists()


def test_missing_command_exits_2(capsys):
    with pytest.raises(SystemExit) as info:
        main([])
    assert info.value.code == 2


def test_unknown_scene_returns_1(capsys):
    rc = main(["render", "no-such-scene", "--spp", "1"])
    err = capsys.readouterr().err
    assert rc == 1
    assert err.startswith("pyclpt: error: ")
    assert "no-such-scene" in err and "cornell-box" in err


def test_unwritable_output_fails_before_rendering(tmp_path, capsys, monkeypatch):
    import pyclpt.rendering.renderer

    def no_render(*args, **kwargs):
        raise AssertionError("must not render when the output cannot be written")

    monkeypatch.setattr(pyclpt.rendering.renderer, "Renderer", no_render)
    bad = tmp_path / "missing-dir" / "x.exr"
    rc = main(["render", "cornell-box", "--spp", "1", "-o", str(bad)])
    err = capsys.readouterr().err
    assert rc == 1
    assert str(bad) in err and "does not exist" in err
    rc = main(["render", "cornell-box", "--spp", "1", "-o", str(tmp_path / "noext")])
    assert rc == 1
    assert "no file extension" in capsys.readouterr().err


def test_unknown_image_extension_returns_1(tmp_path, capsys):
    bad = tmp_path / "x.notanimage"
    rc = main(["render", "cornell-box", "--spp", "1", "--width", "8", "--height", "8", "-o", str(bad), "--quiet"])
    assert rc == 1
    assert "x.notanimage" in capsys.readouterr().err


def test_bad_device_returns_1(tmp_path, capsys):
    rc = main(["render", "cornell-box", "--spp", "1", "-o", str(tmp_path / "x.exr"), "--device", "no-such-gpu"])
    err = capsys.readouterr().err
    assert rc == 1
    assert "no-such-gpu" in err and "found:" in err


def test_devices_without_opencl_returns_1(capsys, monkeypatch):
    import pyopencl as cl

    monkeypatch.setattr(cl, "get_platforms", lambda: [])
    assert main(["devices"]) == 1
    err = capsys.readouterr().err
    assert "pocl-binary-distribution" in err


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
    return env


def test_console_script_scenes():
    exe = shutil.which("pyclpt")
    if exe is None:
        pytest.skip("the pyclpt console script is not on PATH (package not installed)")
    proc = subprocess.run([exe, "scenes"], capture_output=True, text=True, timeout=120, env=_env())
    assert proc.returncode == 0, proc.stderr
    assert "cornell-box" in proc.stdout


def test_module_entry_point_scenes_and_bad_args():
    proc = subprocess.run([sys.executable, "-m", "pyclpt.cli", "scenes"], capture_output=True, text=True,
                          timeout=120, env=_env())
    assert proc.returncode == 0, proc.stderr
    assert "cornell-bunny" in proc.stdout
    proc = subprocess.run([sys.executable, "-m", "pyclpt.cli", "render", "cornell-box", "--spp", "0"],
                          capture_output=True, text=True, timeout=120, env=_env())
    assert proc.returncode == 2
    assert "--spp" in proc.stderr


# -- the front door: output checked first, bad values, Ctrl-C, progress bar ---------------------------
def _forbid_loading_and_rendering(monkeypatch):
    import pyclpt.rendering.progressive
    import pyclpt.scene.library

    def forbidden(*args, **kwargs):
        raise AssertionError("must not load or render when the output cannot be written")

    monkeypatch.setattr(pyclpt.scene.library, "load", forbidden)
    monkeypatch.setattr(pyclpt.rendering.progressive, "ProgressiveRenderer", forbidden)


@pytest.mark.parametrize("output, needle", [
    ("x.xyz", "cannot write '.xyz' images"),
    ("/proc/x.png", "cannot write in the output folder /proc"),
    ("missing/x.png", "does not exist"),
    (".", "is a folder"),
])
def test_bad_output_fails_before_loading_the_scene(tmp_path, capsys, monkeypatch, output, needle):
    monkeypatch.chdir(tmp_path)
    _forbid_loading_and_rendering(monkeypatch)
    rc = main(["render", "cornell-box", "--spp", "16", "--quiet", "-o", output])
    err = capsys.readouterr().err
    assert rc == 1
    assert err.startswith(f"pyclpt: error: {output}: ") and err.count("\n") == 1, err
    assert needle in err
    assert list(tmp_path.iterdir()) == []


def test_default_output_is_checked_before_rendering(capsys, monkeypatch):
    import pyclpt.rendering.progressive

    def no_render(*args, **kwargs):
        raise AssertionError("must not render when the output cannot be written")

    monkeypatch.setattr(pyclpt.rendering.progressive, "ProgressiveRenderer", no_render)
    monkeypatch.chdir("/proc")  # the default output, ./cornell-box.png, cannot be created here
    rc = main(["render", "cornell-box", "--spp", "1", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 1
    assert "cornell-box.png" in err and "cannot write" in err


@pytest.mark.parametrize("value", ["1100", "-65", "nan", "inf", "-inf", "abc"])
def test_bad_exposure_exits_2_before_rendering(tmp_path, capsys, monkeypatch, value):
    _forbid_loading_and_rendering(monkeypatch)
    with pytest.raises(SystemExit) as info:
        main(["render", "cornell-box", "--quiet", "-o", str(tmp_path / "x.png"), f"--exposure={value}"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "--exposure" in err and repr(value) in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_exposure_within_range_is_applied(tmp_path, capsys):
    args = ["render", "cornell-box", "--spp", "1", "--width", "8", "--height", "8", "--quiet"]
    assert main([*args, "-o", str(tmp_path / "a.png")]) == 0
    assert main([*args, "-o", str(tmp_path / "b.png"), "--exposure", "-64"]) == 0
    assert pyclpt.read_image(tmp_path / "a.png").max() > 0
    assert pyclpt.read_image(tmp_path / "b.png").max() == 0  # 2**-64: black, but asked for


@pytest.mark.parametrize("text, kind", [("[1, 2]", "an array"), ("null", "null"), ('"scene"', "a string")])
def test_json_scene_that_is_not_an_object_returns_1(tmp_path, capsys, text, kind):
    scene = tmp_path / "list.json"
    scene.write_text(text)
    rc = main(["render", str(scene), "-o", str(tmp_path / "x.png"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 1
    assert err.startswith(f"pyclpt: error: {scene}: ") and f"not {kind}" in err and err.count("\n") == 1
    assert not (tmp_path / "x.png").exists()


def test_version(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out == f"pyclpt {pyclpt.__version__}\n"


def test_interrupted_render_writes_nothing_and_exits_130(tmp_path, capsys, monkeypatch):
    import pyclpt.rendering.progressive

    def interrupted(self, frames, progress=None, on_frame=None):
        raise KeyboardInterrupt

    monkeypatch.setattr(pyclpt.rendering.progressive.ProgressiveRenderer, "run", interrupted)
    out = tmp_path / "x.png"
    rc = main(["render", "cornell-box", "--spp", "4", "--width", "8", "--height", "8", "-o", str(out)])
    captured = capsys.readouterr()
    assert rc == 130
    assert captured.err == "pyclpt: interrupted; nothing written\n"
    assert captured.out == ""
    assert list(tmp_path.iterdir()) == []


def test_interrupted_write_keeps_the_old_image(tmp_path, capsys, monkeypatch):
    from pyclpt.common import image_io

    out = tmp_path / "x.png"
    out.write_bytes(b"an earlier image")

    def interrupted(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(image_io, "_write", interrupted)
    rc = main(["render", "cornell-box", "--spp", "1", "--width", "8", "--height", "8", "--quiet", "-o", str(out)])
    assert rc == 130
    assert capsys.readouterr().err == "pyclpt: interrupted; nothing written\n"
    assert out.read_bytes() == b"an earlier image"
    assert [p.name for p in tmp_path.iterdir()] == ["x.png"]


def test_user_errors_of_any_kind_are_one_line(tmp_path, capsys, monkeypatch):
    import pyclpt.scene.library

    def overflow(*args, **kwargs):
        raise OverflowError("math range error")

    monkeypatch.setattr(pyclpt.scene.library, "load", overflow)
    rc = main(["render", "cornell-box", "-o", str(tmp_path / "x.png")])
    assert rc == 1
    assert capsys.readouterr().err == "pyclpt: error: OverflowError: math range error\n"


def test_progress_bar_unless_quiet(tmp_path, capsys, monkeypatch):
    from pyclpt.rendering import frame_loop

    monkeypatch.setattr(frame_loop, "PROGRESS_DELAY_S", 0.0)  # a long render: the bar shows
    args = ["render", "cornell-box", "--spp", "3", "--width", "8", "--height", "8"]
    assert main([*args, "-o", str(tmp_path / "a.png")]) == 0
    err = capsys.readouterr().err
    assert "frame" in err and "cornell-box megakernel" in err
    assert main([*args, "-o", str(tmp_path / "b.png"), "--quiet"]) == 0
    assert capsys.readouterr().err == ""
