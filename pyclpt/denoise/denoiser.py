"""The denoiser a renderer or a user drives: one object per image size and mode.

- ``"svgf"`` (default): spatiotemporal variance-guided filtering on the device (:mod:`pyclpt.denoise.svgf`),
  which needs the G-buffer (albedo, normal, depth, motion, material id);
- ``"blend"``: the seed's fixed 0.7/0.3 blend of frames (:mod:`pyclpt.denoise.blend`);
- ``"oidn"``: Intel Open Image Denoise on the host (``pyclpt/denoise/oidn.py``, imported only for this
  mode), frame by frame, with albedo and normal.

:meth:`Denoiser.denoise_buffers` takes device buffers (what a renderer passes every frame: the
film's frame, interleaved RGB float32, and the per-pixel planar AOVs of ``cl/film/aovs.h``);
:meth:`Denoiser.denoise` takes numpy arrays and builds the G-buffer from them.
"""
from __future__ import annotations

import logging
from typing import Any

import numpy as np
import pyopencl as cl

from pyclpt.common.checks import check_choice, check_int
from pyclpt.denoise.blend import Blend
from pyclpt.denoise.gbuffer import AOV_COUNT, build_aovs, image_shape, split_aovs
from pyclpt.denoise.settings import DenoiserSettings
from pyclpt.denoise.svgf import Svgf, check_buffer
from pyclpt.device.context import Device, alloc, check_alloc, get_device
from pyclpt.device.profile import KernelProfile

log = logging.getLogger("pyclpt.denoise")

MODES = ("svgf", "blend", "oidn")


def _load_oidn() -> type:
    try:
        from pyclpt.denoise.oidn import Oidn
    except ModuleNotFoundError as exc:
        if exc.name == "pyclpt.denoise.oidn":
            raise ImportError("denoiser mode 'oidn' needs pyclpt/denoise/oidn.py (class Oidn), which is not "
                              "installed; use mode 'svgf' or 'blend'") from None
        raise ImportError(f"denoiser mode 'oidn' could not load its dependency {exc.name!r} ({exc})") from exc
    return Oidn


class Denoiser:
    """Denoises frames of ``width`` x ``height`` in ``mode`` (one of :data:`MODES`) on ``device``
    (a Device, a selector string, or None: the default device). ``settings``: the SVGF parameters
    (:class:`DenoiserSettings`; the other modes have none)."""

    def __init__(self, device: Device | str | None = None, width: int | None = None, height: int | None = None,
                 mode: str = "svgf", settings: DenoiserSettings | None = None) -> None:
        if width is None or height is None:
            raise TypeError("Denoiser needs the image size: Denoiser(device, width, height, mode=...)")
        self.width = check_int(width, "denoiser width", lo=1, hi=65536)
        self.height = check_int(height, "denoiser height", lo=1, hi=65536)
        self.mode = check_choice(mode, "denoiser mode", MODES)
        if settings is not None and not isinstance(settings, DenoiserSettings):
            raise TypeError(f"settings must be a DenoiserSettings or None, got {type(settings).__name__}")
        self.pixels = self.width * self.height
        self._oidn: Any = None
        self._impl: Svgf | Blend | None = None
        self._last: np.ndarray | None = None  # the oidn mode's last output
        self._oidn_dropped = 0
        self._oidn_frames = 0
        self._staging: dict[str, cl.Buffer] = {}
        self._host_profile = KernelProfile(enabled=False)  # oidn runs on the host: no kernels to time
        if self.mode == "oidn":
            self._oidn = _load_oidn()(self.width, self.height)
            self.device = get_device(device) if device is not None else None
        else:
            self.device = get_device(device)
            if self.mode == "svgf":
                self._impl = Svgf(self.device, self.width, self.height, settings)
            else:
                self._impl = Blend(self.device, self.width, self.height)
        self._has_output = False
        log.debug("denoiser %s %dx%d", self.mode, self.width, self.height)

    # -- configuration ---------------------------------------------------------------------------
    @property
    def settings(self) -> DenoiserSettings | None:
        """The SVGF settings (None in the other modes); assign new ones to change them."""
        return self._impl.settings if isinstance(self._impl, Svgf) else None

    @settings.setter
    def settings(self, settings: DenoiserSettings) -> None:
        if not isinstance(self._impl, Svgf):
            raise ValueError(f"settings apply to denoiser mode 'svgf', not {self.mode!r}")
        self._impl.settings = settings

    @property
    def profile(self) -> KernelProfile:
        """Per-kernel times of the device modes (an empty profile for oidn)."""
        return self._host_profile if self._impl is None else self._impl.profile

    @property
    def dropped(self) -> int:
        """Non-finite inputs replaced by 0 so far (svgf: one per pixel with a NaN/inf colour, one per
        pixel with a NaN/inf albedo, one each per pixel with a NaN/-inf depth, a NaN/inf normal or a
        NaN/inf motion; blend and oidn: pixels with a NaN/inf colour)."""
        return self._oidn_dropped if self._impl is None else self._impl.dropped

    def reset(self) -> None:
        """Forget the history (a camera cut, a scene change): the next frame starts over."""
        if self._impl is not None:
            self._impl.reset()
        self._oidn_frames = 0

    def history_length(self) -> np.ndarray:
        """Frames in each pixel's history, (H, W) int32: SVGF's N; blend: frames since the reset; oidn: 1
        after a frame (it has no history)."""
        if self._impl is None:
            return np.full((self.height, self.width), min(self._oidn_frames, 1), np.int32)
        return self._impl.history_length()

    # -- frames ----------------------------------------------------------------------------------
    def denoise_buffers(self, color: cl.Buffer, aovs: cl.Buffer | None = None) -> cl.Buffer:
        """Denoise one frame given as device buffers: ``color`` interleaved RGB float32 (3 per pixel),
        ``aovs`` the per-pixel planar G-buffer (cl/film/aovs.h; svgf and oidn need it, blend does not).
        Returns the output buffer (interleaved RGB float32), valid until the next frame."""
        if self.mode == "svgf" and aovs is None:
            raise ValueError("denoiser mode 'svgf' needs the AOV buffer (the G-buffer) with the colour")
        if self._impl is not None:
            out = self._impl.run(color, aovs)
            self._has_output = True
            return out
        return self._oidn_buffers(color, aovs)

    def denoise(self, color: object, albedo: object | None = None, normal: object | None = None,
                depth: object | None = None, motion: object | None = None,
                material_id: object | None = None) -> np.ndarray:
        """Denoise one frame given as numpy arrays: ``color`` (H, W, 3); the G-buffer as for
        :func:`~pyclpt.denoise.gbuffer.build_aovs`, each optional: albedo (default 1: no demodulation),
        normal (default 0: unknown, no normal tests), depth (default 1: one plane), motion (default 0),
        material_id (default 0 on surfaces). Returns the output, (H, W, 3) float32."""
        h, w = image_shape(color)
        if (h, w) != (self.height, self.width):
            raise ValueError(f"color is {w}x{h} but the denoiser was made for {self.width}x{self.height}")
        rgb = np.ascontiguousarray(color, dtype=np.float32)
        if self.mode == "oidn":
            self._last = self._oidn_numpy(rgb, albedo, normal)
            return self._last.copy()
        color_buf = self._upload("color", rgb)
        aov_buf = None
        if self.mode == "svgf":
            aovs = build_aovs(np.ones((h, w, 3), np.float32) if albedo is None else albedo,
                              np.zeros((h, w, 3), np.float32) if normal is None else normal,
                              np.ones((h, w), np.float32) if depth is None else depth,
                              motion=motion, material_id=material_id)
            aov_buf = self._upload("aovs", aovs)
        self.denoise_buffers(color_buf, aov_buf)
        return self.image()

    def denoise_gbuffer(self, color: np.ndarray, gbuffer: np.ndarray | None = None) -> np.ndarray:
        """Denoise one frame given as a renderer records it, on the host: ``color`` (H, W, 3) float32 (its
        frame buffer) and ``gbuffer`` the per-pixel planar G-buffer, (AOV_COUNT, H, W) float32
        (``AovFilm.read()``; svgf and oidn need it, blend does not): the frames of another machine
        (:mod:`pyclpt.distributed`) denoised exactly as :meth:`denoise_buffers` denoises them on the
        device that rendered them. Returns the output, (H, W, 3) float32."""
        if self.device is None:
            raise ValueError("denoise_gbuffer in mode 'oidn' needs a device to stage the frame on: "
                             "Denoiser(device, width, height, mode='oidn')")
        shape = (self.height, self.width)
        if np.shape(color) != (*shape, 3):
            raise ValueError(f"color must be ({self.height}, {self.width}, 3) for this denoiser, got {np.shape(color)}")
        if gbuffer is not None and np.shape(gbuffer) != (AOV_COUNT, *shape):
            raise ValueError(f"gbuffer must be ({AOV_COUNT}, {self.height}, {self.width}) (AovFilm.read()), "
                             f"got {np.shape(gbuffer)}")
        color_buf = self._upload("color", np.asarray(color, np.float32))
        aov_buf = None if gbuffer is None else self._upload("aovs", np.asarray(gbuffer, np.float32))
        self.denoise_buffers(color_buf, aov_buf)
        return self.image()

    def image(self) -> np.ndarray:
        """The last output, (H, W, 3) float32."""
        if self._impl is None:
            if self._last is None:
                raise RuntimeError("the denoiser has not denoised a frame yet")
            return self._last.copy()
        if not self._has_output:
            raise RuntimeError("the denoiser has not denoised a frame yet")
        return self._impl.image()

    # -- helpers ---------------------------------------------------------------------------------
    def _upload(self, name: str, arr: np.ndarray) -> cl.Buffer:
        assert self.device is not None
        buf = self._staging.get(name)
        if buf is None or buf.size < arr.nbytes:
            check_alloc(self.device, arr.nbytes, f"denoiser {name} upload buffer")
            buf = cl.Buffer(self.device.context, cl.mem_flags.READ_ONLY, size=max(arr.nbytes, 4))
            self._staging[name] = buf
        cl.enqueue_copy(self.device.queue, buf, np.ascontiguousarray(arr))
        return buf

    def _oidn_numpy(self, rgb: np.ndarray, albedo: object | None, normal: object | None) -> np.ndarray:
        bad = ~np.isfinite(rgb).all(axis=2)
        if bad.any():
            rgb = np.where(bad[..., None], np.float32(0), rgb)
            self._oidn_dropped += int(bad.sum())
        alb = None if albedo is None else np.nan_to_num(np.asarray(albedo, np.float32), nan=0, posinf=0, neginf=0)
        nrm = None if normal is None else np.nan_to_num(np.asarray(normal, np.float32), nan=0, posinf=0, neginf=0)
        out = np.asarray(self._oidn.run_numpy(rgb, alb, nrm), dtype=np.float32).reshape(self.height, self.width, 3)
        self._oidn_frames += 1
        return np.where(np.isfinite(out), out, np.float32(0))

    def _oidn_buffers(self, color: cl.Buffer, aovs: cl.Buffer | None) -> cl.Buffer:
        if self.device is None:
            raise ValueError("denoise_buffers in mode 'oidn' needs the device the buffers live on: "
                             "Denoiser(device, width, height, mode='oidn')")
        q = self.device.queue
        check_buffer(color, 12 * self.pixels, f"the colour buffer of a {self.width}x{self.height} frame", self.device)
        rgb = np.empty((self.height, self.width, 3), np.float32)
        cl.enqueue_copy(q, rgb, color)
        albedo = normal = None
        if aovs is not None:
            check_buffer(aovs, 4 * AOV_COUNT * self.pixels, f"the AOV buffer of a {self.width}x{self.height} frame",
                         self.device)
            flat = np.empty(AOV_COUNT * self.pixels, np.float32)
            cl.enqueue_copy(q, flat, aovs)
            parts = split_aovs(flat, self.width, self.height)
            albedo, normal = parts["albedo"], parts["normal"]
        self._last = self._oidn_numpy(rgb, albedo, normal)
        if "output" not in self._staging:
            self._staging["output"] = alloc(self.device, 12 * self.pixels, "denoised image (oidn)")
        out = self._staging["output"]
        cl.enqueue_copy(q, out, self._last)
        return out
