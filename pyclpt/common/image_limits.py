"""Constants of :mod:`pyclpt.common.image_io` that the command line needs before it loads anything heavy
(its ``--help`` and argument checks): kept here so that they cost no numpy or OpenImageIO import."""
from __future__ import annotations

#: Output formats that keep linear float radiance (no sRGB curve, no exposure).
LINEAR_EXTENSIONS = {".exr", ".hdr", ".pfm"}
#: Exposure in stops: beyond this the scale 2**exposure under- or overflows float32.
MAX_EXPOSURE = 64.0
