"""The G-buffer a denoiser reads, built from numpy arrays in the layout of ``cl/film/aovs.h``.

Planar float32: channel c of pixel p = y * width + x at ``aovs[c * pixels + p]``; the ids (prim,
material) are int32 bits in float32 slots. :func:`build_aovs` checks each array's shape and kind and
fills what is not given; :func:`split_aovs` takes such a buffer apart again.
"""
from __future__ import annotations

import numpy as np

from pyclpt.film.aovs import (  # the channels of cl/film/aovs.h
    AOV_ALBEDO,
    AOV_COUNT,
    AOV_DEPTH,
    AOV_EMISSION,
    AOV_HITDIST,
    AOV_MATERIAL,
    AOV_MOTION,
    AOV_NORMAL,
    AOV_PRIM,
    AOV_ROUGHNESS,
)
from pyclpt.film.aovs import OFFSCREEN as AOV_OFFSCREEN  # noqa: F401  (the motion of an unseen point)

#: The material id of a miss (the background).
MISS_ID = -1

_INT32 = np.iinfo(np.int32)


def _floats(value: object, name: str, shape: tuple[int, ...]) -> np.ndarray:
    try:
        arr = np.asarray(value)
    except Exception as exc:  # ragged lists and the like
        raise TypeError(f"{name} must be an array of shape {shape}, got {type(value).__name__} ({exc})") from None
    if arr.dtype.kind not in "fiub":
        raise TypeError(f"{name} must hold numbers, got an array of dtype {arr.dtype}")
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape} (height, width{', channels' if len(shape) == 3 else ''}), "
                         f"got {arr.shape}")
    return arr.astype(np.float32, copy=False)


def _ids(value: object, name: str, shape: tuple[int, int]) -> np.ndarray:
    arr = np.asarray(value)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape} (height, width), got {arr.shape}")
    if arr.dtype.kind not in "iu":
        raise TypeError(f"{name} must be an integer array (ids), got dtype {arr.dtype}")
    if arr.size and (arr.min() < _INT32.min or arr.max() > _INT32.max):
        raise ValueError(f"{name} values must fit int32, got {arr.min()}..{arr.max()}")
    return arr.astype(np.int32)


def image_shape(color: object, name: str = "color") -> tuple[int, int]:
    """(height, width) of an (H, W, 3) colour image, or an error naming ``name``."""
    arr = np.asarray(color)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(f"{name} must have shape (height, width, 3), got {arr.shape}")
    return int(arr.shape[0]), int(arr.shape[1])


def build_aovs(albedo: object, normal: object, depth: object, motion: object | None = None,
               material_id: object | None = None, roughness: object | None = None,
               hitdist: object | None = None, prim_id: object | None = None,
               emission: object | None = None) -> np.ndarray:
    """The planar AOV buffer (``AOV_COUNT * H * W`` float32) of one frame.

    albedo (H, W, 3), normal (H, W, 3, world space, any length; 0 = unknown or a miss), depth (H, W:
    view depth > 0, 0 = background); optional: motion (H, W, 2: pixels to the previous position,
    x right, y down; default 0), material_id (H, W, integers; default 0 where depth > 0, else -1),
    roughness and hitdist (H, W; default 0), prim_id (H, W, integers; default = material_id), emission
    (H, W, 3: radiance emitted towards the camera at the first hit, left unfiltered; default 0)."""
    alb = np.asarray(albedo)
    if alb.ndim != 3 or alb.shape[2] != 3:
        raise ValueError(f"albedo must have shape (height, width, 3), got {alb.shape}")
    h, w = alb.shape[:2]
    n = h * w
    out = np.zeros((AOV_COUNT, n), np.float32)
    out[AOV_ALBEDO:AOV_ALBEDO + 3] = _floats(albedo, "albedo", (h, w, 3)).reshape(n, 3).T
    out[AOV_NORMAL:AOV_NORMAL + 3] = _floats(normal, "normal", (h, w, 3)).reshape(n, 3).T
    z = _floats(depth, "depth", (h, w))
    out[AOV_DEPTH] = z.reshape(n)
    if motion is not None:
        out[AOV_MOTION:AOV_MOTION + 2] = _floats(motion, "motion", (h, w, 2)).reshape(n, 2).T
    if emission is not None:
        out[AOV_EMISSION:AOV_EMISSION + 3] = _floats(emission, "emission", (h, w, 3)).reshape(n, 3).T
    if roughness is not None:
        out[AOV_ROUGHNESS] = _floats(roughness, "roughness", (h, w)).reshape(n)
    if hitdist is not None:
        out[AOV_HITDIST] = _floats(hitdist, "hitdist", (h, w)).reshape(n)
    if material_id is None:
        mat = np.where(z > 0, 0, MISS_ID).astype(np.int32)
    else:
        mat = _ids(material_id, "material_id", (h, w))
    prim = mat if prim_id is None else _ids(prim_id, "prim_id", (h, w))
    ids = out.view(np.int32)
    ids[AOV_MATERIAL] = mat.reshape(n)
    ids[AOV_PRIM] = prim.reshape(n)
    return out.reshape(-1)


def split_aovs(aovs: np.ndarray, width: int, height: int) -> dict[str, np.ndarray]:
    """The channels of a planar AOV buffer as (H, W[, C]) arrays (ids as int32)."""
    arr = np.asarray(aovs, dtype=np.float32).reshape(-1)
    n = width * height
    if arr.size != AOV_COUNT * n:
        raise ValueError(f"an AOV buffer of {width}x{height} holds {AOV_COUNT * n} floats, got {arr.size}")
    planes = arr.reshape(AOV_COUNT, n)

    def image(first: int, count: int) -> np.ndarray:
        block = planes[first:first + count].T.reshape(height, width, count)
        return block[..., 0].copy() if count == 1 else block.copy()

    return {"albedo": image(AOV_ALBEDO, 3), "normal": image(AOV_NORMAL, 3), "roughness": image(AOV_ROUGHNESS, 1),
            "depth": image(AOV_DEPTH, 1), "hitdist": image(AOV_HITDIST, 1), "motion": image(AOV_MOTION, 2),
            "emission": image(AOV_EMISSION, 3),
            "prim_id": planes[AOV_PRIM].view(np.int32).reshape(height, width).copy(),
            "material_id": planes[AOV_MATERIAL].view(np.int32).reshape(height, width).copy()}
