"""Image textures: reading bitmaps through OpenImageIO into :class:`~pyclpt.scene.model.Bitmap`.

LDR files (8- or 16-bit integer pixels) hold sRGB-encoded values unless the
scene says ``raw``; they stay encoded in the model and are decoded to linear on
the device before filtering (``cl/scene/texture.h``), as Mitsuba does. Float files
(EXR, HDR, PFM) are linear.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from pyclpt.scene.model import RGB, Bitmap


def read_texture_image(path: str | os.PathLike) -> tuple[np.ndarray, bool]:
    """(pixels (H, W, C) float32, is_ldr) of an image file; OSError naming the file if unreadable."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OSError(f"{path}: cannot read image: {oiio.geterror()}")
    try:
        spec = inp.spec()
        basetype = spec.format.basetype
        ldr = basetype in (oiio.UINT8, oiio.UINT16, oiio.INT8, oiio.INT16)
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
        if pixels is None:
            raise OSError(f"{path}: cannot read image: {inp.geterror()}")
    finally:
        inp.close()
    px = np.asarray(pixels, np.float32)
    if px.ndim == 2:
        px = px[:, :, None]
    if px.shape[2] > 4:
        px = px[:, :, :4]
    # NaN or infinite texels are kept: Bitmap and Envmap refuse them, naming the file and the texel
    return px, ldr


def load_bitmap(path: str | os.PathLike, *, raw: bool = False, filter: str = "bilinear",
                wrap_mode: str = "repeat", uv_scale=(1.0, 1.0), uv_offset=(0.0, 0.0),
                scale: RGB = (1.0, 1.0, 1.0), uv_skew=(0.0, 0.0)) -> Bitmap:
    """A bitmap texture from an image file (sRGB-encoded when it is LDR and not ``raw``)."""
    pixels, ldr = read_texture_image(path)
    return Bitmap(pixels, name=Path(path).name, srgb=ldr and not raw, filter=filter, wrap_mode=wrap_mode,
                  uv_scale=uv_scale, uv_offset=uv_offset, scale=scale, uv_skew=uv_skew)
