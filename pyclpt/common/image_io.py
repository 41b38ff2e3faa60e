"""Writing and reading images through OpenImageIO.

EXR/HDR/PFM keep linear float radiance; PNG, JPEG, TIFF and the like get the
sRGB transfer curve after ``exposure`` (stops) and are quantised to 8 bits.

Writing never loses an image: the output is checked first (:func:`check_output_path`: a format
OpenImageIO can write, an existing writable folder, no read-only file), the pixels are checked (NaN is always an
error, infinity for formats that cannot hold it), and the file is written to a temporary file in
the same folder, then renamed over the target, so a failed or interrupted write leaves neither a
half-written file nor a damaged earlier image.

OpenImageIO encodes into memory (an anonymous in-memory file), where the encoders cannot meet a
full disk: some report no failed write (PNG) and libjpeg ends the whole process on one (JPEG). The
encoded bytes are read back and checked, then written with Python's own file I/O, which raises
OSError (ENOSPC, EIO ...) for every failed write, flush or close; the temporary file's size is
checked after fsync before the rename. A read-only output file is refused, as a read-only folder
is; an output that is a symbolic link is written through: its target is replaced, atomically.
"""
from __future__ import annotations

import errno
import logging
import math
import os
import secrets
import stat
import tempfile
from collections.abc import Sequence
from numbers import Real
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from pyclpt.common.image_limits import LINEAR_EXTENSIONS, MAX_EXPOSURE  # noqa: F401 (part of this module's API)

log = logging.getLogger("pyclpt.common.image_io")

# Formats whose float pixels can hold +-infinity (RGBE .hdr cannot, 8-bit formats cannot).
INFINITY_EXTENSIONS = {".exr", ".pfm"}
# Formats that store the pixels exactly: the encoded image is read back and compared before writing.
LOSSLESS_EXTENSIONS = {".exr", ".pfm", ".png", ".tif", ".tiff"}
FORMATS_HINT = ".exr (linear float), .png or .jpg (sRGB, 8 bits)"


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_to_linear(x):
    """The sRGB transfer curve undone (encoded values in [0, 1] -> linear); float32 arrays stay
    float32, anything else (a Python float, float64) is computed in float64."""
    a = np.asarray(x)
    a = a if a.dtype == np.float32 else a.astype(np.float64)
    out = np.where(a <= 0.04045, a / 12.92, np.power((np.clip(a, 0.0, None) + 0.055) / 1.055, 2.4)).astype(a.dtype)
    return float(out) if out.ndim == 0 else out


def check_exposure(exposure: object) -> float:
    """``exposure`` as a float: a finite number of stops in [-MAX_EXPOSURE, MAX_EXPOSURE]."""
    if isinstance(exposure, bool) or not isinstance(exposure, Real):
        raise TypeError(f"exposure must be a number of stops, got {exposure!r}")
    value = float(exposure)
    if not math.isfinite(value) or abs(value) > MAX_EXPOSURE:
        raise ValueError(f"exposure must be a finite number of stops in [-{MAX_EXPOSURE:g}, {MAX_EXPOSURE:g}], "
                         f"got {exposure!r}")
    return value


def check_output_path(path: str | os.PathLike) -> Path:
    """Check that an image can be written to ``path`` before anything expensive happens: it has an
    extension OpenImageIO has a writer for, it is not a folder, and its folder exists and accepts
    new files (tried with a nameless temporary file), and an existing file there is not read-only
    (no write permission bits, or not writable by this user: refused, as for a read-only folder).
    A symbolic link is followed: its target is checked (and written). Returns ``path`` as a Path;
    raises ValueError (format) or OSError (folder, read-only file), each naming the path."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{path}: is a folder; give an image file name, e.g. {path / 'image.exr'}")
    ext = path.suffix.lower()
    if not ext:
        raise ValueError(f"{path}: no file extension to choose the image format from; use {FORMATS_HINT}")
    if oiio.ImageOutput.create(str(path)) is None:
        oiio.geterror()  # clear OpenImageIO's pending error message
        raise ValueError(f"{path}: OpenImageIO cannot write {ext!r} images; use {FORMATS_HINT}")
    folder = path.resolve().parent
    if not folder.exists():
        raise FileNotFoundError(f"{path}: the output folder {folder} does not exist")
    if not folder.is_dir():
        raise NotADirectoryError(f"{path}: {folder} is not a folder")
    try:
        with tempfile.TemporaryFile(dir=folder, prefix=".pyclpt-probe-"):
            pass
    except OSError as exc:
        raise PermissionError(f"{path}: cannot write in the output folder {folder}: "
                              f"{exc.strerror or exc}") from None
    if path.is_file():
        mode = path.stat().st_mode
        if not mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH) or not os.access(path, os.W_OK):
            raise PermissionError(f"{path}: the file is read-only; not overwritten (make it writable, "
                                  f"e.g. chmod u+w, or remove it, or write another file)")
    return path


def _check_pixels(path: Path, img: np.ndarray) -> None:
    nan = int(np.count_nonzero(np.isnan(img).any(axis=-1)))
    if nan:
        raise ValueError(f"{path}: the image has {nan} NaN pixel(s) of {img.shape[0] * img.shape[1]}; "
                         "nothing written (replace them first, e.g. numpy.nan_to_num)")
    if path.suffix.lower() not in INFINITY_EXTENSIONS:
        inf = int(np.count_nonzero(np.isinf(img).any(axis=-1)))
        if inf:
            raise ValueError(f"{path}: the image has {inf} infinite pixel(s), which {path.suffix} cannot hold; "
                             "nothing written (write .exr, or clip them first)")


def _temporary_path(path: Path) -> Path:
    """A file name in ``path``'s folder, hidden, with the same extension (OpenImageIO picks the
    format by it)."""
    return path.with_name(f".{path.stem}.tmp-{secrets.token_hex(4)}{path.suffix}")


def _memory_file() -> tuple[int, str] | None:
    """An anonymous in-memory file (Linux memfd) and a name OpenImageIO can open it by, or None."""
    if not hasattr(os, "memfd_create"):
        return None
    try:
        fd = os.memfd_create("pyclpt-image", getattr(os, "MFD_CLOEXEC", 0))
    except OSError:
        return None
    name = f"/proc/self/fd/{fd}"
    if not os.path.exists(name):  # no /proc: the memory file cannot be named
        os.close(fd)
        return None
    return fd, name


def _encode(out: oiio.ImageOutput, target: Path, spec: oiio.ImageSpec, pixels: np.ndarray) -> bytes:
    """The file ``out`` encodes from ``pixels``, as bytes: written into memory (where no encoder meets a
    full disk), or, without in-memory files (not Linux), into the system temporary folder (there a
    full disk is still the encoder's to report); then read back with OpenImageIO and checked (size,
    and the pixels of lossless formats)."""
    memory = _memory_file()
    if memory is not None:
        fd, name = memory
    else:
        fd, name = tempfile.mkstemp(prefix="pyclpt-image-", suffix=target.suffix)
    try:
        if not out.open(name, spec):
            raise OSError(f"{target}: cannot encode the image: {out.geterror()}")
        try:
            ok = out.write_image(pixels)
            error = "" if ok else out.geterror()
        finally:
            closed = out.close()
        if not ok:
            raise OSError(f"{target}: write failed: {error}")
        if not closed:
            raise OSError(f"{target}: write failed on close: {out.geterror()}")
        _verify(name, target, spec, pixels)
        os.lseek(fd, 0, os.SEEK_SET)
        with open(fd, "rb", closefd=False) as f:
            data = f.read()
    finally:
        os.close(fd)
        if memory is None:
            os.unlink(name)
    if not data:
        raise OSError(f"{target}: write failed: the encoder produced no bytes")
    return data


def _verify(name: str, target: Path, spec: oiio.ImageSpec, pixels: np.ndarray) -> None:
    """The encoded file ``name`` is a readable image of ``spec``'s size, and, in lossless formats, holds
    ``pixels`` exactly (8-bit RGBA is not compared: the alpha (un)association rounds the colours)."""
    inp = oiio.ImageInput.open(name)
    if inp is None:
        raise OSError(f"{target}: write failed: the encoded image cannot be read back: {oiio.geterror()}")
    try:
        got = inp.spec()
        if (got.width, got.height) != (spec.width, spec.height):  # (JPEG drops an alpha channel)
            raise OSError(f"{target}: write failed: the encoded image is {got.width}x{got.height}, "
                          f"not {spec.width}x{spec.height}")
        back = inp.read_image(pixels.dtype.name if pixels.dtype == np.uint8 else "float")
        if back is None:
            raise OSError(f"{target}: write failed: the encoded image cannot be read back: {inp.geterror()}")
        names = list(got.channelnames)
    finally:
        inp.close()
    if (target.suffix.lower() not in LOSSLESS_EXTENSIONS or got.nchannels != spec.nchannels
            or (pixels.dtype == np.uint8 and spec.nchannels == 4)):
        return
    back = np.asarray(back).reshape(pixels.shape[:2] + (-1,))
    if sorted(names) == sorted(spec.channelnames):  # OpenEXR stores the channels sorted by name
        back = back[..., [names.index(n) for n in spec.channelnames]]
    if not np.array_equal(back.reshape(pixels.shape), pixels):
        raise OSError(f"{target}: write failed: the encoded image does not hold the pixels written")


def _write_all(fd: int, data: bytes) -> None:
    """os.write until every byte is written (a short write is not an error; a failed one raises)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _write(out: oiio.ImageOutput, path: Path, target: Path, spec: oiio.ImageSpec, pixels: np.ndarray) -> None:
    """Write ``pixels`` to the new file ``path`` (errors name ``target``, the file the user asked for):
    encoded in memory by ``out``, then written with Python's file I/O, flushed to the disk (fsync)
    and its size checked, so a full disk or an I/O error raises OSError (errno kept) here."""
    data = _encode(out, target, spec, pixels)
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
        try:
            _write_all(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)
        size = os.stat(path).st_size
        if size != len(data):
            raise OSError(errno.EIO, f"{size} of {len(data)} bytes on the disk")
    except OSError as exc:
        error = OSError(f"{target}: write failed: {exc.strerror or exc}; nothing replaced")
        error.errno = exc.errno  # (a filename too would change the message)
        raise error from exc


def _replace(out: oiio.ImageOutput, path: Path, spec: oiio.ImageSpec, pixels: np.ndarray) -> None:
    """Write ``pixels`` (:func:`_write`) to a temporary file beside ``path``'s real file and rename it over
    that: a symbolic link is written through (its target replaced), the permissions of the image it
    replaces are kept, and a failed or interrupted (KeyboardInterrupt) write leaves no half file."""
    real = Path(os.path.realpath(path))
    tmp = _temporary_path(real)
    try:
        _write(out, tmp, path, spec, pixels)
        if real.is_file():
            os.chmod(tmp, stat.S_IMODE(real.stat().st_mode))
        os.replace(tmp, real)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_image(path: str | os.PathLike, image: np.ndarray, exposure: float = 0.0) -> Path:
    """Write an (H, W, 3) linear image; the format follows the extension; ``exposure`` in stops
    (finite, within +-64) scales 8-bit output only: a linear file (.exr, .hdr, .pfm) keeps the
    radiance as rendered, and a non-zero exposure there is ignored with a warning. Atomic: written
    to a temporary file beside ``path``, then renamed over it.
    Raises ValueError for a bad image (NaN pixels; infinite ones in a format that cannot hold
    them), extension or exposure, OSError when the file cannot be written; nothing is written then."""
    path = Path(path)
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 3 or img.shape[2] not in (1, 3, 4):
        raise ValueError(f"expected an (H, W, 3) image, got shape {img.shape}")
    exposure = check_exposure(exposure)
    check_output_path(path)
    _check_pixels(path, img)
    ext = path.suffix.lower()
    if ext in LINEAR_EXTENSIONS and exposure != 0.0:  # a linear file keeps the radiance as rendered
        log.warning("%s: exposure %g applies to 8-bit output (PNG, JPEG, ...) only; ignored for a linear %s file",
                    path, exposure, ext)
        exposure = 0.0
    with np.errstate(over="ignore"):  # a huge finite value times 2**exposure: inf, clipped to 1 in 8 bits
        scaled = img * np.float32(2.0 ** exposure)
    if ext in LINEAR_EXTENSIONS:
        pixels, fmt = scaled, "float"
    else:
        pixels = (linear_to_srgb(scaled) * 255.0 + 0.5).astype(np.uint8)
        fmt = "uint8"
    out = oiio.ImageOutput.create(str(path))
    if out is None:
        raise OSError(f"{path}: no image writer for {ext!r}: {oiio.geterror()}")
    spec = oiio.ImageSpec(img.shape[1], img.shape[0], img.shape[2], fmt)
    if ext not in LINEAR_EXTENSIONS:
        spec.attribute("oiio:ColorSpace", "sRGB")
    _replace(out, path, spec, pixels)
    return path


def write_layers(path: str | os.PathLike, image: np.ndarray,
                 layers: dict[str, tuple[np.ndarray, Sequence[str]]]) -> Path:
    """Write an (H, W, 3) linear image and named layers into one multi-layer OpenEXR file: channels
    ``R, G, B`` and, per layer ``name -> (array, channel names)``, ``name.X``, ``name.Y`` ... (an (H, W)
    array is one channel; integer arrays are stored as float, exact below 2^24). Atomic, as
    :func:`write_image`; ValueError for a path that is not .exr, mismatched shapes or NaN values."""
    path = Path(path)
    if path.suffix.lower() != ".exr":
        raise ValueError(f"{path}: AOV layers need an OpenEXR file (.exr), not {path.suffix or 'no extension'!r}")
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) image, got shape {img.shape}")
    check_output_path(path)
    _check_pixels(path, img)
    planes, names = [img], ["R", "G", "B"]
    for layer, (array, channels) in layers.items():
        a = np.asarray(array)
        a = a[..., None] if a.ndim == 2 else a
        if a.shape[:2] != img.shape[:2] or a.shape[2] != len(channels):
            raise ValueError(f"{path}: layer {layer!r} has shape {a.shape}, expected {img.shape[:2]} and "
                             f"{len(channels)} channel(s) {', '.join(channels)}")
        a = a.astype(np.float32)
        if np.isnan(a).any():
            raise ValueError(f"{path}: layer {layer!r} holds NaN values; nothing written")
        planes.append(a)
        names += [f"{layer}.{c}" for c in channels]
    pixels = np.ascontiguousarray(np.concatenate(planes, axis=2))
    out = oiio.ImageOutput.create(str(path))
    if out is None:
        raise OSError(f"{path}: no image writer for .exr: {oiio.geterror()}")
    spec = oiio.ImageSpec(img.shape[1], img.shape[0], len(names), "float")
    spec.channelnames = tuple(names)
    _replace(out, path, spec, pixels)
    return path


def read_layers(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Every channel of an image by its name (``R``, ``albedo.R`` ...), each (H, W) float32."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OSError(f"{path}: cannot read image: {oiio.geterror()}")
    try:
        names = list(inp.spec().channelnames)
        pixels = inp.read_image("float")
        if pixels is None:
            raise OSError(f"{path}: cannot read image: {inp.geterror()}")
    finally:
        inp.close()
    pixels = np.asarray(pixels, np.float32)
    return {name: pixels[..., i] for i, name in enumerate(names)}


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an image as float32 (H, W, C) (values as stored: linear for EXR, encoded for PNG)."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OSError(f"{path}: cannot read image: {oiio.geterror()}")
    try:
        pixels = inp.read_image("float")
        if pixels is None:
            raise OSError(f"{path}: cannot read image: {inp.geterror()}")
        return np.asarray(pixels, np.float32)
    finally:
        inp.close()
