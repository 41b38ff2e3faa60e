"""Image writing and reading: linear EXR, sRGB-encoded PNG/JPEG, errors."""
from __future__ import annotations

import os
import re
import stat

import numpy as np
import pytest

from pyclpt.common import image_io
from pyclpt.common.image_io import check_output_path, linear_to_srgb, read_image, write_image

MAGIC = {".exr": b"\x76\x2f\x31\x01", ".png": b"\x89PNG", ".jpg": b"\xff\xd8\xff", ".jpeg": b"\xff\xd8\xff"}


def _hdr_image(h=5, w=7, seed=1):
    rng = np.random.default_rng(seed)
    img = rng.random((h, w, 3), dtype=np.float32) * 20.0
    img[0, 0] = (0.0, 1e-8, 123456.0)
    img[1, 1] = (0.1, 0.5, 1.0 / 3.0)
    return img


def test_exr_roundtrip_is_exact(tmp_path):
    img = _hdr_image()
    path = write_image(tmp_path / "a.exr", img)
    assert path == tmp_path / "a.exr"
    back = read_image(path)
    assert back.shape == img.shape and back.dtype == np.float32
    np.testing.assert_array_equal(back, img)  # linear floats, no encoding, no clamping


def test_exr_keeps_non_square_orientation(tmp_path):
    img = np.zeros((3, 8, 3), np.float32)
    img[0, 7] = (1.0, 2.0, 3.0)  # top-right
    back = read_image(write_image(tmp_path / "o.exr", img))
    assert back.shape == (3, 8, 3)
    np.testing.assert_array_equal(back[0, 7], (1.0, 2.0, 3.0))
    assert back.sum() == 6.0


def test_png_is_srgb_encoded(tmp_path):
    img = np.full((4, 6, 3), 0.5, np.float32)
    img[0, 0] = (0.0, 1.0, 2.0)  # clamped at 1
    img[0, 1] = (0.002, 0.0031308, 0.2)  # linear segment / curve
    img[0, 2] = (-1.0, 0.0, 1e30)
    back = read_image(write_image(tmp_path / "a.png", img)) * 255.0
    assert back.shape == (4, 6, 3)
    assert abs(back[2, 3, 0] - 188) <= 1  # 0.5 linear is 188 in 8-bit sRGB, not 128
    assert abs(back[2, 3, 0] - 128) > 50
    np.testing.assert_allclose(back[0, 0], (0, 255, 255), atol=0.5)
    np.testing.assert_allclose(back[0, 1, :2], np.round(12.92 * np.array([0.002, 0.0031308]) * 255), atol=1)
    np.testing.assert_allclose(back[0, 2], (0, 0, 255), atol=0.5)  # negative -> 0, huge -> 1


def test_png_exposure_doubles_per_stop(tmp_path):
    img = np.full((2, 2, 3), 0.25, np.float32)
    plain = read_image(write_image(tmp_path / "plain.png", img))
    up = read_image(write_image(tmp_path / "up.png", img, exposure=1.0))
    down = read_image(write_image(tmp_path / "down.png", img * 4, exposure=-2.0))
    half = read_image(write_image(tmp_path / "half.png", np.full((2, 2, 3), 0.5, np.float32)))
    np.testing.assert_array_equal(up, half)  # 0.25 * 2^1 == 0.5
    np.testing.assert_array_equal(down, plain)  # 1.0 * 2^-2 == 0.25
    assert abs(up[0, 0, 0] * 255 - 188) <= 1
    assert up[0, 0, 0] > plain[0, 0, 0]


def test_linear_to_srgb_reference_values():
    x = np.array([0.0, 0.0031308, 0.5, 1.0, 2.0, -1.0])
    y = linear_to_srgb(x)
    np.testing.assert_allclose(y, [0.0, 0.04045, 0.735357, 1.0, 1.0, 0.0], atol=1e-5)


def test_jpeg_writes(tmp_path):
    img = np.zeros((16, 16, 3), np.float32)
    img[:, :8] = (0.5, 0.5, 0.5)
    for ext in (".jpg", ".jpeg"):
        path = write_image(tmp_path / f"a{ext}", img)
        assert path.read_bytes()[:3] == MAGIC[ext]
        back = read_image(path) * 255.0
        assert back.shape[:2] == (16, 16)
        assert abs(back[8, 2, 0] - 188) <= 4  # lossy, but sRGB-encoded
        assert back[8, 13, 0] <= 4


@pytest.mark.parametrize("ext", [".exr", ".png", ".jpg", ".EXR", ".Png"])
def test_extension_picks_format(tmp_path, ext):
    path = write_image(tmp_path / f"img{ext}", np.full((2, 3, 3), 0.5, np.float32))
    assert path.read_bytes()[:len(MAGIC[ext.lower()])] == MAGIC[ext.lower()]


def test_single_channel_and_rgba(tmp_path):
    gray = np.full((2, 2, 1), 0.5, np.float32)
    assert read_image(write_image(tmp_path / "g.exr", gray)).shape == (2, 2, 1)
    rgba = np.full((2, 2, 4), 0.5, np.float32)
    assert read_image(write_image(tmp_path / "c.exr", rgba)).shape == (2, 2, 4)


def test_missing_directory_names_path(tmp_path):
    bad = tmp_path / "no" / "such" / "dir" / "x.exr"
    with pytest.raises(OSError, match=re.escape(str(bad))):
        write_image(bad, np.zeros((2, 2, 3), np.float32))
    assert not bad.parent.exists()


def test_unknown_extension_names_path(tmp_path):
    bad = tmp_path / "x.notanimage"
    with pytest.raises((OSError, ValueError), match="x.notanimage"):
        write_image(bad, np.zeros((2, 2, 3), np.float32))


def test_no_extension_is_rejected(tmp_path):
    with pytest.raises(ValueError, match="no file extension"):
        write_image(tmp_path / "noext", np.zeros((2, 2, 3), np.float32))


@pytest.mark.parametrize("shape", [(4, 4), (4, 4, 2), (4, 4, 5), (2, 4, 4, 3), (12,)])
def test_bad_shape_is_rejected(tmp_path, shape):
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        write_image(tmp_path / "x.exr", np.zeros(shape, np.float32))
    assert not (tmp_path / "x.exr").exists()


def test_read_missing_file_raises(tmp_path):
    with pytest.raises(OSError, match="missing.exr"):
        read_image(tmp_path / "missing.exr")


# -- the output is checked before anything is written ---------------------------------------------
def _no_temporary_files(folder):
    return [p.name for p in folder.iterdir() if ".tmp-" in p.name or p.name.startswith(".pyclpt-probe")]


@pytest.mark.parametrize("name", ["x.xyz", "x.psd", "x.cin"])  # unknown to OpenImageIO, or read-only formats
def test_format_without_writer_is_rejected(tmp_path, name):
    with pytest.raises(ValueError, match=re.escape(str(tmp_path / name)) + r".*cannot write"):
        check_output_path(tmp_path / name)
    with pytest.raises(ValueError, match="cannot write"):
        write_image(tmp_path / name, np.zeros((2, 2, 3), np.float32))
    assert list(tmp_path.iterdir()) == []


def test_folder_that_takes_no_files_is_rejected():
    with pytest.raises(OSError, match=re.escape("/proc/x.png") + ".*cannot write in the output folder /proc"):
        check_output_path("/proc/x.png")


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="needs POSIX permissions (root writes anyway)")
def test_read_only_folder_is_rejected(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        with pytest.raises(PermissionError, match=re.escape(str(folder / "x.exr"))):
            check_output_path(folder / "x.exr")
    finally:
        folder.chmod(0o755)


def test_output_checks_name_the_path(tmp_path):
    with pytest.raises(IsADirectoryError, match="is a folder"):
        check_output_path(tmp_path)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        check_output_path(tmp_path / "missing" / "x.png")
    (tmp_path / "file").write_text("")
    with pytest.raises(NotADirectoryError, match="is not a folder"):
        check_output_path(tmp_path / "file" / "x.png")
    assert check_output_path(tmp_path / "ok.EXR") == tmp_path / "ok.EXR"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]  # the probe left nothing behind


# -- atomic writes -------------------------------------------------------------------------------
@pytest.mark.parametrize("error", [OSError("disk full"), KeyboardInterrupt()])
def test_failed_write_keeps_the_old_image_and_leaves_no_temporary_file(tmp_path, monkeypatch, error):
    target = tmp_path / "keep.png"
    write_image(target, np.full((4, 4, 3), 0.5, np.float32))
    before = target.read_bytes()
    real_write = image_io._write
    seen = []

    def half_write(out, path, *args):
        real_write(out, path, *args)  # the temporary file exists, complete, beside the target
        seen.append(path)
        assert path.parent == tmp_path and path.is_file() and path != target
        raise error

    monkeypatch.setattr(image_io, "_write", half_write)
    with pytest.raises(type(error)):
        write_image(target, np.zeros((4, 4, 3), np.float32))
    assert seen
    assert target.read_bytes() == before
    assert _no_temporary_files(tmp_path) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.png"]


def test_overwrite_replaces_the_image_and_keeps_its_permissions(tmp_path):
    target = tmp_path / "a.exr"
    write_image(target, np.zeros((2, 2, 3), np.float32))
    target.chmod(0o640)
    write_image(target, np.ones((2, 2, 3), np.float32))
    np.testing.assert_array_equal(read_image(target), np.ones((2, 2, 3), np.float32))
    assert stat.S_IMODE(target.stat().st_mode) == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr"]


# -- pixels and exposure -------------------------------------------------------------------------
@pytest.mark.parametrize("ext", [".exr", ".png", ".jpg", ".hdr"])
def test_nan_pixels_are_refused_with_their_count(tmp_path, ext):
    img = np.ones((4, 5, 3), np.float32)
    img[0, 0, 1] = np.nan
    img[2, 3] = np.nan
    with pytest.raises(ValueError, match=r"2 NaN pixel\(s\) of 20"):
        write_image(tmp_path / f"n{ext}", img)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("ext", [".png", ".jpg", ".hdr"])
def test_infinite_pixels_are_refused_where_the_format_cannot_hold_them(tmp_path, ext):
    img = np.ones((3, 3, 3), np.float32)
    img[1, 1, 0] = np.inf
    with pytest.raises(ValueError, match=r"1 infinite pixel"):
        write_image(tmp_path / f"i{ext}", img)
    assert list(tmp_path.iterdir()) == []


def test_exr_keeps_infinity(tmp_path):
    img = np.ones((2, 2, 3), np.float32)
    img[0, 1] = (np.inf, -np.inf, 1.0)
    np.testing.assert_array_equal(read_image(write_image(tmp_path / "i.exr", img)), img)


@pytest.mark.parametrize("exposure", [float("nan"), float("inf"), -float("inf"), 1100, -64.5, 65])
def test_bad_exposure_is_refused(tmp_path, exposure):
    with pytest.raises(ValueError, match=r"exposure must be a finite number of stops in \[-64, 64\]"):
        write_image(tmp_path / "e.png", np.ones((2, 2, 3), np.float32), exposure=exposure)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("exposure", ["1", True, None])
def test_exposure_must_be_a_number(tmp_path, exposure):
    with pytest.raises(TypeError, match="exposure must be a number"):
        write_image(tmp_path / "e.png", np.ones((2, 2, 3), np.float32), exposure=exposure)


def test_exposure_at_the_limits(tmp_path):
    img = np.full((2, 2, 3), 0.5, np.float32)
    assert read_image(write_image(tmp_path / "hi.png", img, exposure=64)).min() == 1.0
    assert read_image(write_image(tmp_path / "lo.png", img, exposure=-64.0)).max() == 0.0
