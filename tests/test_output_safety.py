"""Writing outputs safely: a full disk, a read-only file, a symbolic link, SIGTERM mid-write.

A full disk is real (a tiny tmpfs, where ``mount`` works: root) or simulated (the lowest-level write
of pyclpt's image writer, ``image_io._write_all``, raising ENOSPC after writing part of the file).
"""
from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from pyclpt.common import image_io
from pyclpt.common.image_io import check_output_path, read_image, read_layers, write_image, write_layers

REPO = Path(__file__).resolve().parent.parent


def _noise(h, w, seed=0):
    return np.random.default_rng(seed).random((h, w, 3), dtype=np.float32)


def _temporary_files(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if ".tmp-" in p.name or p.name.startswith((".pyclpt", "pyclpt-"))]


def _run_python(code: str, timeout: float = 60, **kwargs) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=timeout, env=env, **kwargs)


# -- a real full disk: a 64 KiB tmpfs ------------------------------------------------------------
@pytest.fixture
def full_disk(tmp_path):
    """A 64 KiB tmpfs folder (skipped where it cannot be mounted: not root, no mount, a container)."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if os.name != "posix" or not shutil.which("mount"):
        pytest.skip("no mount command")
    try:
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(disk)],
                           capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.SubprocessError) as exc:
        pytest.skip(f"cannot mount a tmpfs: {exc}")
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs: {r.stderr.strip()}")
    try:
        yield disk
    finally:
        if subprocess.run(["umount", str(disk)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(disk)], capture_output=True)


@pytest.mark.parametrize("name, size", [("keep.png", 200), ("keep.jpg", 400)])
def test_full_disk_raises_naming_the_file_and_keeps_the_old_image(full_disk, name, size):
    target = full_disk / name
    write_image(target, _noise(32, 32))  # a small good image: fits
    before = target.read_bytes()
    # In a child process: libjpeg used to end the whole process (exit 1) on a full disk.
    r = _run_python(f"""
        import json, numpy as np
        from pyclpt.common.image_io import write_image
        try:
            write_image({str(target)!r}, np.random.default_rng(1).random(({size}, {size}, 3), dtype=np.float32))
            print(json.dumps({{"error": None}}))
        except OSError as exc:
            print(json.dumps({{"error": str(exc), "errno": exc.errno}}))
    """)
    assert r.returncode == 0, f"the process died: rc {r.returncode}, {r.stdout} {r.stderr}"
    result = json.loads(r.stdout.strip().splitlines()[-1])
    assert result["error"] is not None, "a write on a full disk reported success"
    assert str(target) in result["error"]
    assert result["errno"] == errno.ENOSPC
    assert target.read_bytes() == before  # unchanged, byte for byte
    np.testing.assert_array_equal(read_image(target).shape, (32, 32, 3))
    assert sorted(p.name for p in full_disk.iterdir()) == [name]  # no temporary file left


def test_full_disk_new_file_leaves_nothing(full_disk):
    with pytest.raises(OSError, match="new.png") as info:
        write_image(full_disk / "new.png", _noise(200, 200))
    assert info.value.errno == errno.ENOSPC
    assert list(full_disk.iterdir()) == []


def test_full_disk_stops_a_png_sequence_at_the_frame_that_failed(full_disk, capsys):
    from pyclpt.cli import main

    rc = main(["render", "cornell-box", "--spp", "6", "--width", "96", "--height", "96", "--sequence",
               "-o", str(full_disk / "f#.png"), "--quiet"])
    captured = capsys.readouterr()
    assert rc == 1, captured
    frames = sorted(p.name for p in full_disk.iterdir())
    assert 0 < len(frames) < 6 and frames == [f"f{k}.png" for k in range(len(frames))]  # no temporary file
    for name in frames:  # every frame on the disk is a whole image
        assert read_image(full_disk / name).shape == (96, 96, 3)
    failed = full_disk / f"f{len(frames)}.png"
    assert captured.err == f"pyclpt: error: {failed}: write failed: No space left on device; nothing replaced\n"
    assert "wrote" not in captured.out


# -- a simulated full disk: the writer's lowest-level write fails --------------------------------
@pytest.mark.parametrize("name", ["keep.png", "keep.jpg", "keep.exr"])
def test_enospc_from_the_write_raises_and_keeps_the_old_image(tmp_path, monkeypatch, name):
    target = tmp_path / name
    write_image(target, _noise(8, 8))
    before = target.read_bytes()
    real = image_io._write_all
    calls = []

    def disk_full(fd, data):
        calls.append(len(data))
        real(fd, data[: len(data) // 2])  # part of the file reaches the disk, then it is full
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(image_io, "_write_all", disk_full)
    with pytest.raises(OSError, match=f"{target}.*No space left on device") as info:
        write_image(target, _noise(8, 8, seed=2))
    assert calls
    assert info.value.errno == errno.ENOSPC
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


def test_failed_fsync_raises_and_keeps_the_old_image(tmp_path, monkeypatch):
    target = tmp_path / "keep.png"
    write_image(target, _noise(8, 8))
    before = target.read_bytes()

    def failing_fsync(fd):
        raise OSError(errno.EIO, os.strerror(errno.EIO))

    monkeypatch.setattr(image_io.os, "fsync", failing_fsync)
    with pytest.raises(OSError, match="keep.png.*Input/output error") as info:
        write_image(target, _noise(8, 8, seed=3))
    monkeypatch.undo()
    assert info.value.errno == errno.EIO
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.png"]


def test_short_file_on_the_disk_is_an_error(tmp_path, monkeypatch):
    """Writes that report success but leave fewer bytes (the PNG writer's silent failure) are caught."""
    target = tmp_path / "keep.png"
    write_image(target, _noise(8, 8))
    before = target.read_bytes()
    real = image_io._write_all
    monkeypatch.setattr(image_io, "_write_all", lambda fd, data: real(fd, data[:10]))
    with pytest.raises(OSError, match="keep.png"):
        write_image(target, _noise(8, 8, seed=4))
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.png"]


def test_encoded_image_is_checked_before_writing(tmp_path, monkeypatch):
    """An encoder that silently writes a damaged file is caught before anything reaches the disk."""
    target = tmp_path / "keep.png"
    write_image(target, _noise(8, 8))
    before = target.read_bytes()
    real_open = image_io.oiio.ImageInput.open

    class Broken:
        @staticmethod
        def open(name, *args):
            os.truncate(name, 40)  # what a full disk leaves of a PNG
            return real_open(name, *args)

    monkeypatch.setattr(image_io.oiio, "ImageInput", Broken)
    with pytest.raises(OSError, match="keep.png: write failed"):
        write_image(target, _noise(8, 8, seed=5))
    monkeypatch.undo()
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.png"]


def test_without_in_memory_files_the_image_is_encoded_in_the_temporary_folder(tmp_path, monkeypatch):
    """Where there is no memfd (not Linux), OpenImageIO encodes into the system temporary folder."""
    encoder_dir = tmp_path / "encoder"
    encoder_dir.mkdir()
    monkeypatch.setattr(image_io, "_memory_file", lambda: None)
    monkeypatch.setattr(image_io.tempfile, "tempdir", str(encoder_dir))
    img = _noise(5, 7) * 4
    np.testing.assert_array_equal(read_image(write_image(tmp_path / "a.exr", img)), img)
    assert read_image(write_image(tmp_path / "a.jpg", img)).shape == (5, 7, 3)
    assert list(encoder_dir.iterdir()) == []  # the encoder's file is removed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr", "a.jpg", "encoder"]


# -- read-only outputs and symbolic links --------------------------------------------------------
@pytest.mark.parametrize("name", ["ro.png", "ro.exr"])
def test_read_only_file_is_refused(tmp_path, name):
    target = tmp_path / name
    write_image(target, _noise(4, 4))
    target.chmod(0o444)
    before = target.read_bytes()
    try:
        with pytest.raises(PermissionError, match=f"{target}: the file is read-only"):
            check_output_path(target)
        with pytest.raises(PermissionError, match=f"{target}: the file is read-only"):
            write_image(target, _noise(4, 4, seed=1))
        if name.endswith(".exr"):
            with pytest.raises(PermissionError, match="read-only"):
                write_layers(target, _noise(4, 4), {})
        assert target.read_bytes() == before
        assert stat.S_IMODE(target.stat().st_mode) == 0o444
        assert sorted(p.name for p in tmp_path.iterdir()) == [name]
    finally:
        target.chmod(0o644)


def test_read_only_file_is_refused_by_the_cli_before_rendering(tmp_path, capsys, monkeypatch):
    import pyclpt.rendering.progressive
    import pyclpt.scene.library
    from pyclpt.cli import main

    def forbidden(*args, **kwargs):
        raise AssertionError("loaded or rendered before the output was checked")

    monkeypatch.setattr(pyclpt.scene.library, "load", forbidden)
    monkeypatch.setattr(pyclpt.rendering.progressive, "ProgressiveRenderer", forbidden)
    target = tmp_path / "ro.png"
    write_image(target, _noise(4, 4))
    target.chmod(0o444)
    try:
        assert main(["render", "cornell-box", "-o", str(target)]) == 1
        assert capsys.readouterr().err == (f"pyclpt: error: {target}: the file is read-only; not overwritten "
                                           "(make it writable, e.g. chmod u+w, or remove it, or write another file)\n")
    finally:
        target.chmod(0o644)


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="no symbolic links")
@pytest.mark.parametrize("ext", [".png", ".exr"])
def test_symlink_output_writes_through_to_its_target(tmp_path, ext):
    real_dir = tmp_path / "real"
    real_dir.mkdir()
    real = real_dir / f"image{ext}"
    write_image(real, np.zeros((4, 4, 3), np.float32))
    real.chmod(0o640)
    link = tmp_path / f"link{ext}"
    link.symlink_to(real)
    write_image(link, np.ones((4, 4, 3), np.float32))
    assert link.is_symlink() and os.readlink(link) == str(real)  # still the link
    np.testing.assert_array_equal(read_image(real), np.ones((4, 4, 3), np.float32))  # the target got the image
    assert stat.S_IMODE(real.stat().st_mode) == 0o640
    if ext == ".exr":  # AOV layers too (OpenEXR stores channels sorted by name; they are checked as written)
        img = _noise(4, 4) * 10
        write_layers(link, img, {"albedo": (img * 0.5, ("R", "G", "B")), "depth": (img[..., 0], ("Z",))})
        assert link.is_symlink()
        layers = read_layers(real)
        np.testing.assert_array_equal(layers["albedo.G"], img[..., 1] * 0.5)
        np.testing.assert_array_equal(layers["depth.Z"], img[..., 0])
    assert sorted(p.name for p in real_dir.iterdir()) == [real.name]  # no temporary file left
    assert sorted(p.name for p in tmp_path.iterdir()) == [link.name, "real"]


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="no symbolic links")
def test_dangling_symlink_output_creates_its_target(tmp_path):
    (tmp_path / "real").mkdir()
    link = tmp_path / "link.png"
    link.symlink_to(tmp_path / "real" / "new.png")
    write_image(link, np.ones((4, 4, 3), np.float32))
    assert link.is_symlink()
    assert (tmp_path / "real" / "new.png").is_file()
    assert read_image(link).shape == (4, 4, 3)


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="no symbolic links")
def test_symlink_to_a_read_only_file_is_refused(tmp_path):
    real = tmp_path / "ro.png"
    write_image(real, _noise(4, 4))
    real.chmod(0o444)
    link = tmp_path / "link.png"
    link.symlink_to(real)
    try:
        with pytest.raises(PermissionError, match="link.png: the file is read-only"):
            write_image(link, _noise(4, 4, seed=1))
        assert link.is_symlink()
    finally:
        real.chmod(0o644)


# -- SIGTERM (and Ctrl-C) in the middle of a write -----------------------------------------------
_SLOW_WRITE = """
    import sys, time
    import numpy as np
    from pyclpt import cli
    from pyclpt.common import image_io

    real = image_io._write

    def slow(*args):  # a write that takes a while: the signal arrives in the middle of it
        real(*args)  # the temporary file beside the target is written, not yet renamed
        print("writing", flush=True)
        time.sleep(60)

    image_io._write = slow

    def render(a):  # no rendering: write an image as a render does
        image_io.write_image(a.output, np.ones((16, 16, 3), np.float32))
        return 0

    cli._cmd_render = render
    sys.exit(cli.main(["render", "cornell-box", "-o", sys.argv[1]]))
"""


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
@pytest.mark.parametrize("sig, rc, word", [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")])
def test_signal_during_a_write_removes_the_temporary_file(tmp_path, sig, rc, word):
    target = tmp_path / "out.exr"
    write_image(target, np.zeros((2, 2, 3), np.float32))
    before = target.read_bytes()
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    child = subprocess.Popen([sys.executable, "-c", textwrap.dedent(_SLOW_WRITE), str(target)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        assert child.stdout.readline().strip() == "writing", child.stderr.read()
        assert len(_temporary_files(tmp_path)) == 1  # the write is in progress: its temporary file exists
        child.send_signal(sig)
        out, err = child.communicate(timeout=30)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    assert child.returncode == rc, err
    assert err == f"pyclpt: {word}; nothing written\n"
    assert _temporary_files(tmp_path) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.exr"]
    assert target.read_bytes() == before


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
def test_cli_catches_sigterm_while_it_runs_and_restores_the_handler(monkeypatch):
    from pyclpt import cli

    before = signal.getsignal(signal.SIGTERM)
    during = []
    monkeypatch.setattr(cli, "_cmd_scenes", lambda: during.append(signal.getsignal(signal.SIGTERM)) or 0)
    assert cli.main(["scenes"]) == 0
    assert during and during[0] is not before and during[0] not in (signal.SIG_DFL, signal.SIG_IGN)
    assert signal.getsignal(signal.SIGTERM) is before


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
def test_sigterm_handler_raises_terminated():
    from pyclpt import cli

    previous = cli._catch_sigterm()
    try:
        with pytest.raises(KeyboardInterrupt) as info:
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(100):  # the handler runs at the next bytecode
                pass
        assert isinstance(info.value, cli.Terminated)
    finally:
        signal.signal(signal.SIGTERM, previous)
