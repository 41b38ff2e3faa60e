"""Image metrics of the denoising evaluation (bench/evaluations/denoise_eval.py, docs/denoising-eval.md).

Every function takes linear radiance images, (H, W, 3) float arrays (a test image ``x`` and its
converged reference ``ref``), and returns a Python float (or a per-pixel map where it says so).

- :func:`relmse`: relative mean squared error, mean over pixels and channels of
  ``(x - ref)^2 / (ref^2 + eps)`` with ``eps = 1e-2``, on the linear images (the denoising
  literature's error: dark and bright regions count alike);
- :func:`ssim`: structural similarity (scikit-image) of the tonemapped images, 1 for identical;
- :func:`flip`: NVIDIA's FLIP (PyPI ``flip-evaluator``), 0 for identical. By default LDR-FLIP on the
  same tonemapped sRGB images as SSIM (what a viewer of the clipped sRGB display sees; one exposure,
  fast); ``mode="hdr"`` runs HDR-FLIP on the linear images (FLIP picks its exposure range from the
  reference);
- :func:`tonemap`: the display transform of SSIM and LDR-FLIP: scale by ``2**exposure``, clip to
  [0, 1], sRGB transfer curve;
- :func:`temporal_instability`: mean |D_t - D_{t-1}| of consecutive outputs (tonemapped), per step,
  with a static camera: flicker;
- :func:`lag_frames`: frames after a change until an error series falls under a threshold (ghosting);
- :func:`change_mask` and :func:`disocclusion_mask`: the region a lag is measured in.

scikit-image and flip-evaluator are optional (``pip install 'pyclpt[bench]'``): importing this module
needs neither; :func:`ssim` and :func:`flip` raise ImportError naming the package when it is missing.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pyclpt.common.image_io import linear_to_srgb

RELMSE_EPS = 1e-2
FLIP_MODES = ("ldr", "hdr")
FLIP_PPD = 67.0  # FLIP's default: a 0.7 m viewing distance from a 24" 3840-pixel-wide monitor
BENCH_HINT = "pip install 'pyclpt[bench]'"


def _optional(module: str, package: str):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ImportError(f"this metric needs the optional package {package} ({exc}): {BENCH_HINT} "
                          f"(or pip install {package})") from exc


def _pair(x: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x)
    ref = np.asarray(ref)
    if x.shape != ref.shape:
        raise ValueError(f"image and reference shapes differ: {x.shape} vs {ref.shape}")
    if x.ndim != 3 or x.shape[2] != 3 or min(x.shape[:2]) < 1:
        raise ValueError(f"images must be (height, width, 3), got {x.shape}")
    return x, ref


def _mask(mask: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray | None:
    if mask is None:
        return None
    m = np.asarray(mask, bool)
    if m.shape != shape[:2]:
        raise ValueError(f"mask must be (height, width) = {shape[:2]}, got {m.shape}")
    return m


def _masked_mean(values: np.ndarray, mask: np.ndarray | None) -> float:
    """Mean of a (H, W) or (H, W, C) array over the pixels of ``mask`` (all pixels when None);
    NaN for an empty mask."""
    if mask is not None:
        values = values[mask]
        if values.size == 0:
            return float("nan")
    return float(np.mean(values, dtype=np.float64))


def tonemap(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Display values in [0, 1]: ``image * 2**exposure`` clipped to [0, 1], sRGB-encoded (float32).
    Non-finite values become 0."""
    a = np.nan_to_num(np.asarray(image, np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    return linear_to_srgb(a * np.float32(2.0 ** exposure)).astype(np.float32)


def relmse_map(x: np.ndarray, ref: np.ndarray, eps: float = RELMSE_EPS) -> np.ndarray:
    """Per pixel, the mean over channels of ``(x - ref)^2 / (ref^2 + eps)`` (float64, (H, W))."""
    x, ref = _pair(x, ref)
    x = x.astype(np.float64)
    ref = ref.astype(np.float64)
    return np.mean((x - ref) ** 2 / (ref * ref + eps), axis=2)


def relmse(x: np.ndarray, ref: np.ndarray, mask: np.ndarray | None = None, eps: float = RELMSE_EPS) -> float:
    """Relative MSE: mean over the pixels (of ``mask``, if given) and channels of
    ``(x - ref)^2 / (ref^2 + eps)``, on linear images."""
    m = relmse_map(x, ref, eps)
    return _masked_mean(m, _mask(mask, m.shape))


def _ssim_window(shape: tuple[int, ...]) -> int:
    side = min(shape[:2])
    if side < 3:
        raise ValueError(f"SSIM needs images of at least 3x3 pixels, got {shape[1]}x{shape[0]}")
    return min(7, side if side % 2 else side - 1)


def ssim(x: np.ndarray, ref: np.ndarray, mask: np.ndarray | None = None, exposure: float = 0.0) -> float:
    """SSIM of the tonemapped images (:func:`tonemap`; ``data_range=1``, ``channel_axis=2``,
    scikit-image's defaults otherwise: a 7x7 uniform window); with ``mask``, the mean of the SSIM
    map over the mask's pixels. 1 for identical images."""
    x, ref = _pair(x, ref)
    metrics = _optional("skimage.metrics", "scikit-image")
    a, b = tonemap(ref, exposure), tonemap(x, exposure)
    win = _ssim_window(a.shape)
    m = _mask(mask, a.shape)
    if m is None:
        return float(metrics.structural_similarity(a, b, data_range=1.0, channel_axis=2, win_size=win))
    _, full = metrics.structural_similarity(a, b, data_range=1.0, channel_axis=2, win_size=win, full=True)
    return _masked_mean(full, m)


def flip_map(x: np.ndarray, ref: np.ndarray, mode: str = "ldr", exposure: float = 0.0,
             ppd: float = FLIP_PPD) -> np.ndarray:
    """The per-pixel FLIP error (H, W) in [0, 1]. ``mode="ldr"``: LDR-FLIP of the tonemapped
    sRGB images (:func:`tonemap`); ``"hdr"``: HDR-FLIP of the linear images times ``2**exposure``
    (its exposure range computed by FLIP from the reference)."""
    x, ref = _pair(x, ref)
    if mode not in FLIP_MODES:
        raise ValueError(f"unknown FLIP mode {mode!r} (choose from {', '.join(FLIP_MODES)})")
    if not (np.isfinite(ppd) and ppd > 0):
        raise ValueError(f"ppd must be a positive number, got {ppd}")
    fe = _optional("flip_evaluator", "flip-evaluator")
    if mode == "ldr":
        a, b = tonemap(ref, exposure), tonemap(x, exposure)
        result = fe.evaluate(np.ascontiguousarray(a), np.ascontiguousarray(b), "LDR", inputsRGB=True,
                             applyMagma=False, computeMeanError=False, parameters={"ppd": float(ppd)})
    else:
        scale = np.float32(2.0 ** exposure)
        a = np.nan_to_num(np.clip(np.asarray(ref, np.float32) * scale, 0, None), posinf=0.0)
        b = np.nan_to_num(np.clip(np.asarray(x, np.float32) * scale, 0, None), posinf=0.0)
        result = fe.evaluate(np.ascontiguousarray(a), np.ascontiguousarray(b), "HDR", applyMagma=False,
                             computeMeanError=False, parameters={"ppd": float(ppd)})
    return np.asarray(result[0], np.float32).reshape(x.shape[:2])


def flip(x: np.ndarray, ref: np.ndarray, mask: np.ndarray | None = None, mode: str = "ldr",
         exposure: float = 0.0, ppd: float = FLIP_PPD) -> float:
    """Mean FLIP error (over ``mask``'s pixels if given); 0 for identical images (see :func:`flip_map`)."""
    m = flip_map(x, ref, mode, exposure, ppd)
    return _masked_mean(m, _mask(mask, m.shape))


def temporal_instability(frames: Sequence[np.ndarray], mask: np.ndarray | None = None,
                         exposure: float | None = 0.0) -> list[float]:
    """``mean |D_t - D_{t-1}|`` for t = 1 .. N-1 (over pixels and channels, of ``mask`` if given):
    how much consecutive outputs of a static view change (flicker). On tonemapped images
    (:func:`tonemap`, values in [0, 1]); ``exposure=None`` compares the linear images."""
    if len(frames) < 2:
        return []
    prev = None
    out = []
    for f in frames:
        cur = np.asarray(f, np.float32) if exposure is None else tonemap(f, exposure)
        if prev is not None:
            if cur.shape != prev.shape:
                raise ValueError(f"frames differ in shape: {prev.shape} vs {cur.shape}")
            out.append(_masked_mean(np.abs(cur.astype(np.float64) - prev), _mask(mask, cur.shape)))
        prev = cur.astype(np.float64)
    return out


def lag_frames(errors: Sequence[float], threshold: float | Sequence[float]) -> int | None:
    """Frames after a change until the error falls under the threshold: the index of the first
    entry of ``errors`` (entry 0: the first frame rendered after the change) that is <= its
    threshold (a number, or one per entry). 0: no lag at all; None: never within the series."""
    errs = [float(e) for e in errors]
    if np.ndim(threshold) == 0:
        thr = [float(threshold)] * len(errs)  # type: ignore[arg-type]
    else:
        thr = [float(t) for t in threshold]  # type: ignore[union-attr]
        if len(thr) != len(errs):
            raise ValueError(f"{len(thr)} thresholds for {len(errs)} errors")
    for k, (e, t) in enumerate(zip(errs, thr)):
        if np.isfinite(e) and e <= t:
            return k
    return None


def luminance(image: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of a linear RGB image, (H, W) float64."""
    a = np.asarray(image, np.float64)
    return 0.2126 * a[..., 0] + 0.7152 * a[..., 1] + 0.0722 * a[..., 2]


def change_mask(before: np.ndarray, after: np.ndarray, rel: float = 0.1, floor: float = 1e-2) -> np.ndarray:
    """Pixels whose converged value changes: ``|L_after - L_before| > rel * max(L_before, L_after) + floor``
    on luminance (the region a light switch or a moved object affects)."""
    a, b = _pair(before, after)
    la, lb = luminance(a), luminance(b)
    return np.abs(lb - la) > rel * np.maximum(la, lb) + floor


def disocclusion_mask(prim_prev: np.ndarray, prim_cur: np.ndarray, motion: np.ndarray,
                      offscreen: float = 1.0e5) -> np.ndarray:
    """Pixels of the current frame that the previous frame did not see: the first hit's previous
    position (``p + motion``, motion in pixels, x right, y down, as the renderer's motion AOV) is off
    screen, or the previous frame's pixel there shows another object (ids of the ``mesh_id`` or
    ``prim_id`` AOV; -1 = a miss). (H, W) bool."""
    prim_prev = np.asarray(prim_prev)
    prim_cur = np.asarray(prim_cur)
    motion = np.asarray(motion, np.float64)
    h, w = prim_cur.shape
    if prim_prev.shape != (h, w) or motion.shape != (h, w, 2):
        raise ValueError(f"prim ids must be (H, W) and motion (H, W, 2), got {prim_prev.shape}, {prim_cur.shape}, "
                         f"{motion.shape}")
    ys, xs = np.mgrid[0:h, 0:w]
    px = np.floor(xs + 0.5 + motion[..., 0]).astype(np.int64)
    py = np.floor(ys + 0.5 + motion[..., 1]).astype(np.int64)
    off = (np.abs(motion).max(axis=2) >= offscreen) | ~np.isfinite(motion).all(axis=2)
    off |= (px < 0) | (px >= w) | (py < 0) | (py >= h)
    seen = np.zeros((h, w), bool)
    ok = ~off
    seen[ok] = prim_prev[py[ok], px[ok]] == prim_cur[ok]
    return ~seen
