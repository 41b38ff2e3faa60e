"""The crop window: the part of an image a film holds (Mitsuba's film ``crop_offset_x/y``,
``crop_width/height``).

A film cropped to (x, y, width, height) holds the pixels [x, x + width) x [y, y + height) of its
image. Its pixels are exactly the image's: each is keyed and placed by its index in the whole image
(``film_pixel`` in ``cl/integrators/path.h``, compiled with ``-DFILM_CROP``), so the tiles of an
image rendered one by one, on one machine or many (:mod:`pyclpt.distributed`), put together give
the image rendered whole, bit for bit.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

from pyclpt.common.checks import check_int, is_int


class Crop(NamedTuple):
    """Pixels [x, x + width) x [y, y + height) of an image; x right, y down from the top-left corner."""

    x: int
    y: int
    width: int
    height: int

    @staticmethod
    def of(value: object, image_width: int, image_height: int, name: str = "crop") -> Crop:
        """``value`` (a Crop or four integers x, y, width, height) checked to lie inside an image of
        image_width x image_height; the message names ``name`` and the value."""
        if not (isinstance(value, Sequence) and not isinstance(value, str) and len(value) == 4
                and all(is_int(v) for v in value)):
            raise TypeError(f"{name} must be four integers (x, y, width, height), got "
                            f"{type(value).__name__} {value!r:.60}")
        x, y, w, h = (int(v) for v in value)
        check_int(x, f"{name} x", lo=0, hi=image_width - 1)
        check_int(y, f"{name} y", lo=0, hi=image_height - 1)
        check_int(w, f"{name} width", lo=1)
        check_int(h, f"{name} height", lo=1)
        if x + w > image_width or y + h > image_height:
            raise ValueError(f"{name} {(x, y, w, h)} reaches past the {image_width}x{image_height} image "
                             f"(pixels x {x}..{x + w - 1}, y {y}..{y + h - 1})")
        return Crop(x, y, w, h)

    def covers(self, image_width: int, image_height: int) -> bool:
        """Whether the window is the whole image."""
        return self == (0, 0, image_width, image_height)

    def slices(self) -> tuple[slice, slice]:
        """The window's rows and columns of an (H, W, ...) image array."""
        return slice(self.y, self.y + self.height), slice(self.x, self.x + self.width)


def tiles(image_width: int, image_height: int, tile_width: int, tile_height: int) -> list[Crop]:
    """The image in tiles of tile_width x tile_height (the last column and row narrower), row by row."""
    tile_width = check_int(tile_width, "tile width", lo=1)
    tile_height = check_int(tile_height, "tile height", lo=1)
    return [Crop(x, y, min(tile_width, image_width - x), min(tile_height, image_height - y))
            for y in range(0, image_height, tile_height) for x in range(0, image_width, tile_width)]
