"""Writing and reading images through OpenImageIO.

EXR/HDR/PFM keep linear float radiance; PNG, JPEG, TIFF and the like get the
sRGB transfer curve after ``exposure`` (stops) and are quantised to 8 bits.

Writing never loses an image: the output is checked first (:func:`check_output_path`: a format
OpenImageIO can write, an existing writable folder), the pixels are checked (NaN is always an
error, infinity for formats that cannot hold it), and the file is written to a temporary file in
the same folder, then renamed over the target, so a failed or interrupted write leaves neither a
half-written file nor a damaged earlier image.
"""
from __future__ import annotations

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

LINEAR_EXTENSIONS = {".exr", ".hdr", ".pfm"}
# Formats whose float pixels can hold +-infinity (RGBE .hdr cannot, 8-bit formats cannot).
INFINITY_EXTENSIONS = {".exr", ".pfm"}
# Exposure in stops: beyond this the scale 2**exposure under- or overflows float32.
MAX_EXPOSURE = 64.0
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
    new files (tried with a nameless temporary file). Returns ``path`` as a Path; raises ValueError
    (format) or OSError (folder), each naming the path."""
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


def _write(out: oiio.ImageOutput, path: Path, target: Path, spec: oiio.ImageSpec, pixels: np.ndarray) -> None:
    """Write ``pixels`` to ``path`` (errors name ``target``, the file the user asked for)."""
    if not out.open(str(path), spec):
        raise OSError(f"{target}: cannot open for writing: {out.geterror()}")
    try:
        ok = out.write_image(pixels)
        error = "" if ok else out.geterror()
    finally:
        closed = out.close()
    if not ok:
        raise OSError(f"{target}: write failed: {error}")
    if not closed:
        raise OSError(f"{target}: write failed on close: {out.geterror()}")


def write_image(path: str | os.PathLike, image: np.ndarray, exposure: float = 0.0) -> Path:
    """Write an (H, W, 3) linear image; the format follows the extension; ``exposure`` in stops
    (finite, within +-64). Atomic: written to a temporary file beside ``path``, then renamed over it.
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
    tmp = _temporary_path(path)
    try:
        _write(out, tmp, path, spec, pixels)
        if path.is_file():  # keep the permissions of the image it replaces
            os.chmod(tmp, stat.S_IMODE(path.stat().st_mode))
        os.replace(tmp, path)
    except BaseException:  # failed or interrupted (KeyboardInterrupt): leave no half file behind
        tmp.unlink(missing_ok=True)
        raise
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
    tmp = _temporary_path(path)
    try:
        _write(out, tmp, path, spec, pixels)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
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
