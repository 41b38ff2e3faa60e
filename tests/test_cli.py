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


def _stats_json(path: Path) -> dict:
    return json.loads(path.read_text())


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
                    r"load [\d.]+ s, compile [\d.]+ s, render [\d.]+ s, total [\d.]+ s$", lines[0]), lines[0]
    assert device.name in lines[0]


def test_render_stats_prints_kernels(tmp_path, capsys):
    rc = main(["render", "cornell-box", "--spp", "1", "--width", "16", "--height", "16", "--max-depth", "3",
               "-o", str(tmp_path / "s.exr"), "--stats", "--stats-json", str(tmp_path / "s.json"), "--quiet"])
    out = capsys.readouterr().out
    assert rc == 0
    lines = out.splitlines()
    assert "max depth 3" in lines[0]
    assert "{" not in out  # a table, not JSON
    assert "counted by the wavefront integrator only" in lines[1]  # the megakernel counts no bounces
    head = next(i for i, line in enumerate(lines) if line.startswith("kernel "))
    assert lines[head].split() == ["kernel", "launches", "total", "ms", "mean", "ms", "share"]
    assert lines[head + 1].split()[0] == "megakernel" and lines[head + 2].startswith("all kernels")
    stats = _stats_json(tmp_path / "s.json")
    assert set(stats) >= {"kernels", "bounces", "dropped_samples"}
    assert stats["kernels"], stats
    assert all("kernel" in k for k in stats["kernels"])
    assert stats["dropped_samples"] == 0


def test_render_wavefront_aos(tmp_path, capsys):
    out = tmp_path / "w.png"
    rc = main(["render", "cornell-box", "--spp", "2", "--width", "16", "--height", "16",
               "--integrator", "wavefront", "--layout", "aos", "-o", str(out), "--stats-json", "-", "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0
    assert "wavefront/aos" in text.splitlines()[0]
    stats = json.loads(text[text.index("\n{") + 1:])  # --stats-json -: the JSON on stdout
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
    # the default (PYCLPT_DEVICE=pocl in this session, tests/conftest.py) marked, and why
    marked = [line for line in out.splitlines() if line.endswith("[default]")]
    assert len(marked) == 1 and "Portable Computing Language" in marked[0], out
    assert out.splitlines()[-1].startswith("default: Portable Computing Language") and "PYCLPT_DEVICE" in out


def test_devices_marks_the_fastest_without_pyclpt_device(capsys, monkeypatch):
    from pyclpt.device import context

    monkeypatch.delenv("PYCLPT_DEVICE", raising=False)
    monkeypatch.setattr(context, "fastest", lambda devices: (devices[-1][2], "the test's choice"))
    assert main(["devices"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[-2].endswith("[default]") and sum(line.endswith("[default]") for line in lines) == 1
    assert lines[-1].startswith("default: ") and "the test's choice" in lines[-1]


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


# -- readable output: help, start-up, the summary line, --stats, log lines, the compile message ---------
def test_every_option_has_help():
    import argparse

    from pyclpt.cli import build_parser

    parser = build_parser()
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    missing = [f"{name} {'/'.join(action.option_strings) or action.dest}"
               for name, sub in [("pyclpt", parser), *subparsers.choices.items()]
               for action in sub._actions if not action.help]
    assert missing == [], missing
    device = next(a for a in subparsers.choices["render"]._actions if "--device" in a.option_strings)
    assert all(word in device.help for word in ("pocl", "intel", "gpu", "cpu", "PYCLPT_DEVICE", "fastest"))


HEAVY = ("pyopencl", "dask", "distributed", "OpenImageIO", "scipy", "trimesh", "tqdm")


@pytest.mark.parametrize("command", ["--version", "scenes"])
def test_startup_imports_no_heavy_layer(command):
    """``pyclpt --version`` and ``pyclpt scenes`` load none of the heavy layers (OpenCL, Dask, OpenImageIO):
    ``import pyclpt`` is lazy (a module __getattr__) and the commands import what they use."""
    code = (f"import sys, pyclpt.cli\ntry:\n    pyclpt.cli.main([{command!r}])\nexcept SystemExit:\n    pass\n"
            f"print('loaded:', sorted(m for m in {HEAVY!r} if m in sys.modules))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=_env())
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[-1] == "loaded: []", proc.stdout


def test_lazy_package_keeps_its_names():
    code = ("import sys, pyclpt\nassert 'pyopencl' not in sys.modules\n"
            "from pyclpt import Scene, render, optim, default_device\n"
            "assert all(getattr(pyclpt, n) is not None for n in pyclpt.__all__)\n"
            "assert set(pyclpt.__all__) <= set(dir(pyclpt))\nprint(render.__module__, Scene.__name__)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=_env())
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["pyclpt.rendering.renderer", "Scene"]
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        pyclpt.no_such_name  # noqa: B018


@pytest.mark.parametrize("args, phrase", [
    (["--frames", "6", "--max-frames", "2", "--overflow", "ema"],
     ", 6 frames rendered, the image their exponential moving average over a window of 2 frames (--overflow ema), "),
    (["--frames", "5", "--max-frames", "2", "--overflow", "reset"],
     ", 5 frames rendered, the image averages the last 1 (--overflow reset starts over every 2), "),
    (["--frames", "5", "--max-frames", "2"], ", 2 spp of the 5 asked (--max-frames 2 stopped the accumulation), "),
    (["--frames", "2", "--max-frames", "4", "--overflow", "ema"], ", 2 spp, "),
])
def test_summary_says_what_the_image_holds_once(tmp_path, capsys, args, phrase):
    rc = main(["render", "cornell-box", *args, "--width", "8", "--height", "8", "--max-depth", "2",
               "-o", str(tmp_path / "x.exr"), "--quiet"])
    out = capsys.readouterr().out
    assert rc == 0
    lines = out.splitlines()
    assert len(lines) == 1 and phrase in lines[0], out
    assert "spp" not in phrase or "frames rendered" not in lines[0]


def test_summary_total_is_the_commands_wall_time(tmp_path, capsys, monkeypatch):
    """The total counts from the command's start to the written file, scene loading included."""
    import pyclpt.scene.library

    real_load = pyclpt.scene.library.load

    def slow_load(*args, **kwargs):
        import time

        time.sleep(0.3)
        return real_load(*args, **kwargs)

    monkeypatch.setattr(pyclpt.scene.library, "load", slow_load)
    rc = main(["render", "cornell-box", "--spp", "1", "--width", "8", "--height", "8", "-o", str(tmp_path / "x.png"),
               "--quiet"])
    line = capsys.readouterr().out.splitlines()[0]
    assert rc == 0
    parts = {m[0]: float(m[1]) for m in re.findall(r"(load|compile|render|total) ([\d.]+) s", line)}
    assert parts["load"] >= 0.3 and parts["total"] >= parts["load"] + parts["compile"] + parts["render"] - 0.02


def test_stats_table_counts_the_tails_paths(tmp_path, capsys):
    """--stats on the wavefront: a row per bounce, the paths the tail (finish_paths) runs on included."""
    rc = main(["render", "cornell-box", "--spp", "2", "--width", "16", "--height", "16", "--max-depth", "6",
               "--integrator", "wavefront", "-o", str(tmp_path / "w.png"), "--stats", "--stats-json",
               str(tmp_path / "w.json"), "--quiet"])
    lines = capsys.readouterr().out.splitlines()
    assert rc == 0
    assert lines[1].split()[:3] == ["bounce", "paths", "alive"]
    rows = []
    for line in lines[2:]:
        if not line or not line[0].isdigit():
            break
        rows.append([int(c.replace(",", "")) for c in line.split()])
    stats = _stats_json(tmp_path / "w.json")
    assert rows[0][:2] == [0, 16 * 16 * 2]
    assert stats["bounces"][1]["tail"] > 0  # the tail takes every path at bounce 1 on a small image
    assert len(rows) > len(stats["bounces"]) and len(rows) == max(len(stats["bounces"]), len(stats["tail_alive"]))
    for b, row in enumerate(rows):
        rays = stats["bounces"][b]["rays"] if b < len(stats["bounces"]) else 0
        tail = stats["tail_alive"][b] if b < len(stats["tail_alive"]) else 0
        assert row[:3] == [b, rays + tail, tail]
    alive = [row[1] for row in rows]
    assert alive == sorted(alive, reverse=True) and alive[-1] > 0  # paths alive never grow


def test_importer_warnings_are_short_lines():
    import logging

    from pyclpt.cli import IGNORED_LINES, IGNORED_WIDTH, LogFormatter

    notes = [f"m{i}.bsdf.alpha (scenes/x.xml:{i}): {'a long reason ' * 20}" for i in range(30)]
    record = logging.LogRecord("pyclpt.scene.mitsuba_dict.scene", logging.WARNING, __file__, 1, "%s: one line",
                               ("scenes/x.xml",), None)
    record.ignored, record.origin = notes, "scenes/x.xml"
    lines = LogFormatter().format(record).splitlines()
    assert lines[0] == "pyclpt: scenes/x.xml: 30 settings not used by pyclpt:"
    assert lines[1].startswith("  m0.bsdf.alpha (line 0): a long reason")
    assert len(lines) == 1 + IGNORED_LINES + 1 and "18 more (-v lists them all)" in lines[-1]
    assert all(len(line) <= IGNORED_WIDTH + 2 for line in lines[1:])
    assert len(LogFormatter(verbose=True).format(record).splitlines()) == 31
    plain = logging.LogRecord("pyclpt.rendering.renderer", logging.WARNING, __file__, 1, "dropped %d", (3,), None)
    assert LogFormatter().format(plain) == "pyclpt: dropped 3"


def test_cli_logs_importer_warnings_as_short_lines(tmp_path):
    scene = tmp_path / "s.xml"
    scene.write_text('<scene version="3.0.0"><integrator type="sppm"/><bsdf type="diffuse" id="unused"/>'
                     '<shape type="sphere"><bsdf type="diffuse"/></shape>'
                     '<emitter type="constant"/></scene>')
    proc = subprocess.run([sys.executable, "-m", "pyclpt", "render", str(scene), "--spp", "1", "--width", "4",
                           "--height", "4", "-o", str(tmp_path / "s.png"), "--quiet"], capture_output=True, text=True,
                          timeout=300, env=_env())
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.splitlines()
    assert lines[0] == f"pyclpt: {scene}: 2 settings not used by pyclpt:", proc.stderr
    assert lines[1].startswith("  integrator (line 1): integrator 'sppm'") and lines[2].startswith("  unused (line 1)")
    assert "pyclpt.scene" not in proc.stderr


def test_compile_message_only_for_slow_builds(caplog, device, monkeypatch):
    """A build that is not in the device's cache, in a compile_notice block still open NOTICE_AFTER_S later,
    logs the compile message once (logger pyclpt.notice); a cached build logs nothing."""
    import threading

    from pyclpt.device import program

    source = "__kernel void notice_test(__global int* x) { x[0] = NOTICE_VALUE; }"
    monkeypatch.setattr(program, "NOTICE_AFTER_S", 0.05)
    caplog.set_level("INFO", logger="pyclpt.notice")
    done = threading.Event()
    with program.compile_notice("a-scene"):
        program.build_program(device, source=source, defines={"NOTICE_VALUE": 7}, name="notice_test")
        done.wait(0.3)  # the block stays open past NOTICE_AFTER_S
        program.build_program(device, source=source, defines={"NOTICE_VALUE": 8}, name="notice_test")
        done.wait(0.3)
    said = [r.getMessage() for r in caplog.records if r.name == "pyclpt.notice"]
    assert said == ["compiling kernels for a-scene (first use, cached afterwards)…"]
    caplog.clear()
    with program.compile_notice("a-scene"):  # served from the device's cache: no timer, no message
        program.build_program(device, source=source, defines={"NOTICE_VALUE": 7}, name="notice_test")
        done.wait(0.3)
    assert [r for r in caplog.records if r.name == "pyclpt.notice"] == []


def test_stats_json_folder_is_checked_before_rendering(tmp_path, capsys, monkeypatch):
    _forbid_loading_and_rendering(monkeypatch)
    rc = main(["render", "cornell-box", "--spp", "1", "-o", str(tmp_path / "x.png"), "--stats-json",
               str(tmp_path / "missing" / "s.json")])
    assert rc == 1
    assert "--stats-json" in capsys.readouterr().err and list(tmp_path.iterdir()) == []
