"""Images as a person sees them: the tonemap of :func:`~pyclpt.common.image_io.write_image` (exposure in
stops, then the sRGB curve, 8 bits), the G-buffer's AOVs mapped to colours, PNG bytes in memory, and
:class:`ImageView`, an image that shows itself in a Jupyter notebook (``_repr_png_``, ``_repr_html_``).

    import pyclpt
    pyclpt.show(pyclpt.render("cornell-box", spp=16, width=128, height=128))   # the last line of a cell

The PNG encoder is zlib's (the standard library): no imaging library is needed.
"""
from __future__ import annotations

import base64
import struct
import zlib

import numpy as np

from pyclpt.common.image_io import check_exposure, linear_to_srgb

# What an image can be shown as: the radiance (plain average or denoised), the G-buffer's AOVs, and the
# samples per pixel of the plain average (samples_to_display).
VIEWS = ("color", "denoised", "albedo", "normal", "depth", "motion", "samples")
# zlib's level for the frames: 1 encodes a 320x180 frame in about a millisecond, 6 saves a few per cent more.
PNG_LEVEL = 1


def _as_rgb(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 2:
        img = img[:, :, None]
    if img.ndim != 3 or img.shape[2] not in (1, 3, 4):
        raise ValueError(f"expected an (H, W, 3) image (or (H, W) / (H, W, 1)), got shape {np.shape(image)}")
    if img.shape[2] == 1:
        img = np.repeat(img, 3, axis=2)
    return img[:, :, :3]


def tonemap(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """(H, W, 3) uint8: ``image`` (linear radiance) scaled by 2**exposure, through the sRGB curve, as
    :func:`~pyclpt.common.image_io.write_image` writes a PNG; NaN shows black."""
    img = _as_rgb(image)
    exposure = check_exposure(exposure)
    with np.errstate(over="ignore", invalid="ignore"):
        scaled = np.nan_to_num(img * np.float32(2.0 ** exposure), nan=0.0)
    return (linear_to_srgb(scaled) * 255.0 + 0.5).astype(np.uint8)


# The live pictures' tonemap: a table of the sRGB curve over this many linear values in [0, 1].
LUT_SIZE = 65536
_lut: np.ndarray | None = None


def tonemap_fast(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """:func:`tonemap` by a table of 65536 linear values, seven times faster (0.3 ms at 320x180 on two
    cores): a pixel differs from it by at most one 8-bit step (under 0.1 % of them do). NaN shows black."""
    global _lut
    if _lut is None:
        _lut = (linear_to_srgb(np.arange(LUT_SIZE, dtype=np.float64) / (LUT_SIZE - 1)) * 255.0 + 0.5).astype(np.uint8)
    exposure = check_exposure(exposure)
    with np.errstate(over="ignore", invalid="ignore"):
        x = _as_rgb(image) * np.float32((LUT_SIZE - 1) * 2.0 ** exposure)
    np.fmax(x, 0.0, out=x)  # NaN -> 0
    np.fmin(x, LUT_SIZE - 1, out=x)
    x += 0.5
    return _lut[x.astype(np.int32)]


def aov_to_display(name: str, values: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """(H, W, 3) uint8 of an AOV: ``albedo`` through the sRGB curve (exposure ignored: a reflectance),
    ``normal`` as 0.5 + 0.5 n, ``depth`` as grey, the nearest hit white, the farthest dark, misses black,
    ``motion`` (pixels to the previous frame) as 0.5 + 0.5 m / the largest |m| in red (x) and green (y),
    grey where nothing moved, black where the previous camera had the point behind it."""
    if name == "motion":
        m = np.nan_to_num(np.asarray(values, np.float32)[:, :, :2])
        valid = np.all(np.abs(m) < 1e5, axis=2)  # 10^6: the previous camera had the point behind it
        scale = float(np.abs(m[valid]).max()) if valid.any() else 0.0
        rgb = np.full((*m.shape[:2], 3), 0.5, np.float32)
        rgb[:, :, :2] += 0.5 * m / max(scale, 1e-6)
        rgb[~valid] = 0.0
        return (np.clip(rgb, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    v = _as_rgb(values)
    if name == "albedo":
        return tonemap(v)
    if name == "normal":
        return (np.clip(0.5 + 0.5 * np.nan_to_num(v), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    if name == "depth":
        d = np.nan_to_num(v[:, :, 0])
        hit = d > 0
        grey = np.zeros_like(d)
        if hit.any():
            lo, hi = float(d[hit].min()), float(d[hit].max())
            grey[hit] = 1.0 - 0.8 * (d[hit] - lo) / max(hi - lo, 1e-12)
        return np.repeat((grey * 255.0 + 0.5).astype(np.uint8)[:, :, None], 3, axis=2)
    raise ValueError(f"no display for AOV {name!r} (albedo, normal, depth, motion)")


# The samples view's scale: no sample black, then log2(n) from 1 sample (dark blue) to SAMPLES_WHITE (white).
SAMPLES_WHITE = 4096
# Its colours along that scale, evenly spaced: black, dark blue, purple, red, orange, yellow, white.
SAMPLES_RAMP = np.array([[0, 0, 0], [20, 20, 110], [120, 30, 140], [210, 50, 60], [245, 140, 20],
                         [250, 225, 60], [255, 255, 255]], np.float32)


def samples_to_display(counts: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 of a per-pixel sample count (H, W): a colour ramp on a log scale, black for no
    sample, dark blue for 1, then purple, red, orange and yellow up to white at :data:`SAMPLES_WHITE` samples
    and more. The scale is absolute, so that the colour says how far a render has come."""
    n = np.nan_to_num(np.asarray(counts, np.float64), nan=0.0)
    if n.ndim == 3 and n.shape[2] == 1:
        n = n[:, :, 0]
    if n.ndim != 2:
        raise ValueError(f"expected an (H, W) array of sample counts, got shape {np.shape(counts)}")
    steps = len(SAMPLES_RAMP) - 1
    t = np.where(n > 0, 1.0 + (steps - 1) * np.log2(np.maximum(n, 1.0)) / np.log2(SAMPLES_WHITE), 0.0)
    t = np.clip(t, 0.0, steps)
    lo = np.minimum(t.astype(np.int32), steps - 1)
    frac = (t - lo)[:, :, None].astype(np.float32)
    rgb = SAMPLES_RAMP[lo] * (1.0 - frac) + SAMPLES_RAMP[lo + 1] * frac
    return (rgb + 0.5).astype(np.uint8)


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def encode_png(pixels: np.ndarray, level: int = PNG_LEVEL) -> bytes:
    """PNG bytes of an (H, W, 3) uint8 image: 8-bit RGB, every row with the Up filter, zlib ``level``."""
    px = np.ascontiguousarray(pixels)
    if px.dtype != np.uint8 or px.ndim != 3 or px.shape[2] != 3:
        raise ValueError(f"expected (H, W, 3) uint8 pixels, got {px.dtype} {px.shape}")
    h, w, _ = px.shape
    rows = px.reshape(h, w * 3)
    up = np.empty_like(rows)
    up[0] = rows[0]
    np.subtract(rows[1:], rows[:-1], out=up[1:])  # uint8 wraps modulo 256, as the Up filter is defined
    raw = np.empty((h, w * 3 + 1), np.uint8)
    raw[:, 0] = 2  # filter type Up (the first row's "previous row" is zeros: its values stay)
    raw[:, 1:] = up
    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header) + _chunk(b"IDAT", zlib.compress(raw.tobytes(), level))
            + _chunk(b"IEND", b""))


class ImageView:
    """A linear (H, W, 3) image that a notebook shows tonemapped (``_repr_png_``, ``_repr_html_``), as
    :func:`~pyclpt.common.image_io.write_image` would write it as PNG with ``exposure`` stops.
    ``numpy.asarray(view)`` is the image itself."""

    def __init__(self, image: np.ndarray, exposure: float = 0.0) -> None:
        self.image = _as_rgb(image)
        self.exposure = check_exposure(exposure)

    @property
    def shape(self) -> tuple[int, ...]:
        return self.image.shape

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        return self.image if dtype is None else self.image.astype(dtype)

    def pixels(self) -> np.ndarray:
        """The tonemapped (H, W, 3) uint8 pixels."""
        return tonemap(self.image, self.exposure)

    def _repr_png_(self) -> bytes:
        return encode_png(self.pixels(), level=6)

    def _repr_html_(self) -> str:
        data = base64.b64encode(self._repr_png_()).decode("ascii")
        h, w = self.image.shape[:2]
        return f'<img src="data:image/png;base64,{data}" width="{w}" height="{h}" style="image-rendering:pixelated">'

    def __repr__(self) -> str:
        h, w = self.image.shape[:2]
        return f"ImageView({w}x{h}, exposure={self.exposure:g})"


def show(image: np.ndarray, exposure: float = 0.0) -> ImageView | None:
    """Show ``image`` (linear, (H, W, 3)) tonemapped as write_image's PNG (``exposure`` in stops): in IPython
    or Jupyter it is displayed at once (and None returned, so that a cell does not show it twice);
    elsewhere the :class:`ImageView` is returned."""
    view = ImageView(image, exposure)
    try:
        from IPython import get_ipython
        from IPython.display import display
    except ImportError:
        return view
    if get_ipython() is not None:
        display(view)
        return None
    return view
