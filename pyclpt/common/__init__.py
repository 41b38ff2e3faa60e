"""Layer 0, used by every other layer: environment settings, the on-disk cache, argument checks,
atomic file writes, image files (OpenImageIO) and the ``pyclpt`` logger's warnings.

Imports nothing else from pyclpt."""
