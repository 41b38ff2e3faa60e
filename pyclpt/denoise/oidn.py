"""Intel Open Image Denoise (OIDN) through ``pyoidn``: the offline anchor of the denoising
evaluation (mode ``oidn``), run on the host on numpy images.

    from pyclpt.denoise.oidn import Oidn
    oidn = Oidn(1280, 720)                         # hdr=True, quality="high"
    out = oidn.run_numpy(color, albedo, normal)    # (H, W, 3) float32 each; albedo/normal may be None

``pyoidn`` is an optional dependency (``pip install 'pyclpt[oidn]'``); importing this module never
needs it, making an :class:`Oidn` does, and raises ImportError with that command when it is missing
(:func:`available` tells without raising).

Inputs, as OIDN's "RT" filter wants them: ``color`` linear radiance (HDR, >= 0), ``albedo`` in
[0, 1], ``normal`` in [-1, 1] as they are (world space; unit length is not required, so averaged
normals are fine). The auxiliary images are treated as noisy (OIDN's ``cleanAux`` off): the
evaluation feeds it AOVs averaged over the same few 1-spp frames as the colour, which carry noise
from depth of field, antialiasing and glossy chains. A normal image needs an albedo image (OIDN's
rule). Non-finite values are replaced by 0 before the filter (counted in :attr:`Oidn.nonfinite`,
per image, over all calls, and :attr:`Oidn.last_nonfinite` for the last call); negative colours
are clamped to 0 and albedo / normal clipped to their ranges (counted in :attr:`Oidn.clamped`).
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from pyclpt.common.checks import check_bool, check_choice, check_int, check_optional_int

QUALITIES = ("high", "balanced", "fast", "default")
INSTALL_HINT = "pip install 'pyclpt[oidn]' (or pip install pyoidn)"
IMAGES = ("color", "albedo", "normal")


def _import_pyoidn() -> Any:
    try:
        import pyoidn
    except ImportError as exc:  # the module is missing, or its native library failed to load
        raise ImportError(f"Intel Open Image Denoise (the denoiser mode 'oidn') needs the optional package "
                          f"pyoidn, which could not be imported ({exc}): {INSTALL_HINT}") from exc
    return pyoidn


def available() -> bool:
    """Whether pyoidn imports and OIDN's CPU device is supported here."""
    try:
        pyoidn = _import_pyoidn()
        return bool(pyoidn.Device.is_cpu_available())
    except Exception:  # noqa: BLE001 - any failure means "not available"
        return False


def _check_image(image: object, name: str, shape: tuple[int, int]) -> np.ndarray:
    h, w = shape
    if not isinstance(image, np.ndarray):
        raise TypeError(f"{name} must be a numpy array of shape ({h}, {w}, 3), got {type(image).__name__}")
    if image.shape != (h, w, 3):
        raise ValueError(f"{name} must have shape (height, width, 3) = ({h}, {w}, 3) for this "
                         f"{w}x{h} Oidn, got {image.shape}")
    if image.dtype.kind != "f":
        raise TypeError(f"{name} must be a float array (float32 preferred), got dtype {image.dtype}")
    return image


class Oidn:
    """One OIDN CPU device and "RT" filter for images of one size; reused across calls."""

    def __init__(self, width: int, height: int, *, hdr: bool = True, quality: str = "high",
                 threads: int | None = None) -> None:
        self.width = check_int(width, "width", lo=1)
        self.height = check_int(height, "height", lo=1)
        self.hdr = check_bool(hdr, "hdr")
        self.quality = check_choice(quality, "quality", QUALITIES)
        self.threads = check_optional_int(threads, "threads", lo=1, note=" (None: all cores)")
        self._pyoidn = pyoidn = _import_pyoidn()
        if not pyoidn.Device.is_cpu_available():
            raise RuntimeError("OIDN's CPU device is not supported on this machine (it needs SSE4.1 or NEON)")
        self._device = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU)
        if self.threads:
            self._device.set_int("numThreads", int(self.threads))
        self._device.commit()
        self._raise_on_error("device creation")
        self._filter = pyoidn.Filter(self._device, pyoidn.OIDN_FILTER_TYPE_RT)
        self._raise_on_error("filter creation")
        shape = (self.height, self.width, 3)
        # host buffers shared with OIDN (bound once; every call copies its inputs into them)
        self._buffers = {name: np.zeros(shape, np.float32) for name in (*IMAGES, "output")}
        self._bound: tuple[str, ...] | None = None  # the input images bound at the last commit
        self.nonfinite = {name: 0 for name in IMAGES}  # non-finite values replaced by 0, all calls
        self.last_nonfinite = {name: 0 for name in IMAGES}
        self.clamped = {name: 0 for name in IMAGES}  # values clamped into the image's range, all calls
        self.calls = 0
        self.seconds = 0.0  # filter time (execute, and commit when the inputs changed), all calls
        self.last_seconds = 0.0
        self._closed = False

    # -- lifetime ----------------------------------------------------------------------------------
    def close(self) -> None:
        """Release the filter and the device (the object cannot run after this)."""
        if getattr(self, "_closed", True):
            return
        self._closed = True
        self._filter.release()
        self._device.release()

    def __enter__(self) -> Oidn:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass

    def __repr__(self) -> str:
        return f"Oidn({self.width}x{self.height}, hdr={self.hdr}, quality={self.quality!r})"

    # -- running -----------------------------------------------------------------------------------
    def _raise_on_error(self, what: str) -> None:
        message = self._device.get_error()
        if message is not None:
            raise RuntimeError(f"OIDN {what} failed: {message}")

    def _load(self, name: str, image: np.ndarray, lo: float, hi: float) -> None:
        buf = self._buffers[name]
        np.copyto(buf, image, casting="same_kind")
        bad = ~np.isfinite(buf)
        n_bad = int(np.count_nonzero(bad))
        if n_bad:
            buf[bad] = 0.0
        self.last_nonfinite[name] = n_bad
        self.nonfinite[name] += n_bad
        out = (buf < lo) | (buf > hi)
        n_out = int(np.count_nonzero(out))
        if n_out:
            np.clip(buf, lo, hi, out=buf)
            self.clamped[name] += n_out

    def run_numpy(self, color: np.ndarray, albedo: np.ndarray | None = None,
                  normal: np.ndarray | None = None) -> np.ndarray:
        """The denoised ``color``, a new (H, W, 3) float32 array. ``albedo`` and ``normal`` (same
        shape, or None) guide the filter; a normal image needs an albedo image."""
        if self._closed:
            raise RuntimeError("this Oidn was closed")
        shape = (self.height, self.width)
        _check_image(color, "color", shape)
        if albedo is not None:
            _check_image(albedo, "albedo", shape)
        if normal is not None:
            _check_image(normal, "normal", shape)
            if albedo is None:
                raise ValueError("OIDN takes a normal image only together with an albedo image: pass albedo too "
                                 "(or neither)")
        t = time.perf_counter()
        inputs = ("color",) + (("albedo",) if albedo is not None else ()) + (("normal",) if normal is not None else ())
        self._load("color", color, 0.0, np.inf if self.hdr else 1.0)
        if albedo is not None:
            self._load("albedo", albedo, 0.0, 1.0)
        if normal is not None:
            self._load("normal", normal, -1.0, 1.0)
        for name in IMAGES:
            if name not in inputs:
                self.last_nonfinite[name] = 0
        if inputs != self._bound:
            self._commit(inputs)
        self._filter.execute()
        self._raise_on_error("filter execution")
        self.last_seconds = time.perf_counter() - t
        self.seconds += self.last_seconds
        self.calls += 1
        return self._buffers["output"].copy()

    def _commit(self, inputs: tuple[str, ...]) -> None:
        p = self._pyoidn
        flt = self._filter
        for name in IMAGES:
            if name in inputs:
                flt.set_image(name, self._buffers[name], p.OIDN_FORMAT_FLOAT3)
            elif self._bound and name in self._bound:
                flt.unset_image(name)
        flt.set_image("output", self._buffers["output"], p.OIDN_FORMAT_FLOAT3)
        flt.set_bool("hdr", self.hdr)
        flt.set_bool("cleanAux", False)
        flt.set_int("quality", {"high": p.OIDN_QUALITY_HIGH, "balanced": p.OIDN_QUALITY_BALANCED,
                                "fast": p.OIDN_QUALITY_FAST, "default": p.OIDN_QUALITY_DEFAULT}[self.quality])
        flt.commit()
        self._raise_on_error("filter commit")
        self._bound = inputs

    def stats(self) -> dict:
        """Calls, seconds, and the non-finite / clamped counts."""
        return {"calls": self.calls, "seconds": self.seconds, "last_seconds": self.last_seconds,
                "nonfinite": dict(self.nonfinite), "clamped": dict(self.clamped),
                "width": self.width, "height": self.height, "hdr": self.hdr, "quality": self.quality}
