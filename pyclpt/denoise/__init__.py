"""Denoising the frames of a render: SVGF (spatiotemporal variance-guided filtering, with NRD RELAX's
history clipping) on the device, the seed's fixed blend, and Intel Open Image Denoise on the host.

:class:`Denoiser` is the entry point (``denoise`` for numpy frames, ``denoise_buffers`` for the
renderer's device buffers); :class:`DenoiserSettings` holds the SVGF parameters; the passes are
in :mod:`pyclpt.denoise.svgf` and ``cl/denoise/``, the G-buffer helpers in :mod:`pyclpt.denoise.gbuffer`.

May import: :mod:`pyclpt.device`, :mod:`pyclpt.film`, :mod:`pyclpt.common` (and the buffers and
integrators layers below it); never :mod:`pyclpt.rendering` or :mod:`pyclpt.cli`.
"""
from pyclpt.denoise.denoiser import MODES, Denoiser
from pyclpt.denoise.settings import DenoiserSettings

__all__ = ["Denoiser", "DenoiserSettings", "MODES"]
