"""Layer 0, used by every other layer: environment settings, the on-disk cache, argument checks,
atomic file writes and image files (OpenImageIO).

Imports nothing else from pyclpt."""
