"""Writing and reading images through OpenImageIO.

EXR/HDR/PFM keep linear float radiance; PNG, JPEG, TIFF and the like get the
sRGB transfer curve after ``exposure`` (stops) and are quantised to 8 bits.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

LINEAR_EXTENSIONS = {".exr", ".hdr", ".pfm"}


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


def write_image(path: str | os.PathLike, image: np.ndarray, exposure: float = 0.0) -> Path:
    """Write an (H, W, 3) linear image; the format follows the extension. Raises OSError on failure."""
    path = Path(path)
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 3 or img.shape[2] not in (1, 3, 4):
        raise ValueError(f"expected an (H, W, 3) image, got shape {img.shape}")
    ext = path.suffix.lower()
    if not ext:
        raise ValueError(f"{path}: no file extension to choose the image format from (.exr, .png, .jpg)")
    scaled = img * np.float32(2.0 ** exposure)
    if ext in LINEAR_EXTENSIONS:
        pixels, fmt = scaled, "float"
    else:
        pixels = (linear_to_srgb(np.nan_to_num(scaled, nan=0.0, posinf=1.0)) * 255.0 + 0.5).astype(np.uint8)
        fmt = "uint8"
    out = oiio.ImageOutput.create(str(path))
    if out is None:
        raise OSError(f"{path}: no image writer for {ext!r}: {oiio.geterror()}")
    spec = oiio.ImageSpec(img.shape[1], img.shape[0], img.shape[2], fmt)
    if ext not in LINEAR_EXTENSIONS:
        spec.attribute("oiio:ColorSpace", "sRGB")
    try:
        if not out.open(str(path), spec):
            raise OSError(f"{path}: cannot open for writing: {out.geterror()}")
        if not out.write_image(pixels):
            raise OSError(f"{path}: write failed: {out.geterror()}")
    finally:
        out.close()
    return path


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
