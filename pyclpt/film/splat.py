"""The splatting film: Mitsuba's estimator for the tent and gaussian reconstruction filters
(``ReconstructionFilter(estimator="splat")``, their default), deterministic.

Each camera ray is drawn uniformly in its pixel (the box's jitter) and its radiance goes to its film slot
as any sample's; after a batch, ``cl/film/splat.cl`` lets every pixel p sum, per frame, the samples of the
pixels around it that the filter reaches, each with weight w(x - cx_p) w(y - cy_p) at its film position,
recomputed from the counter-based random numbers (seed, pixel, sample) that placed it, and the sum of those
weights. Both go through the film's accumulators (the weighted radiance through the film's own, the weights
through a second, one channel), and the image is their ratio: sum w L / sum w over every sample, what
Mitsuba's film computes by splatting with atomics, here a gather in a fixed order, so every integrator and
layout give the same image for a seed. Per-frame values are scaled by 1 / (integral of w)^2, so that each
accumulator alone averages to about the image and 1.

The film renders a margin of :func:`reach` pixels around its window (``Film.pad``), inside the image or
beyond it: the pixels at the image's edge get the samples beyond it, as Mitsuba's ``sample_border = true``,
and a cropped film's pixels are exactly the whole image's. Its pixels are keyed by their index in the image
padded by the margin (``CONST_FILM_PAD``, ``film_pixel`` in ``cl/integrators/path.h``).

Split sample ranges merge by their two sums, pooled (``Film.sums``, :mod:`pyclpt.distributed.merge`); the
G-buffer and the denoisers' input are each window pixel's own samples, not splatted (``Film.denoiser_frame``,
docs/architecture.md, "Pixel filters").
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import pyopencl as cl

from pyclpt.device.context import Device, alloc
from pyclpt.device.program import build_program
from pyclpt.film.accumulator import Accumulator

if TYPE_CHECKING:
    from pyclpt.scene.model import ReconstructionFilter

SPLAT_FILTERS = {"tent": 1, "gaussian": 2}  # -DSPLAT_FILTER (FILTER_* of cl/scene/scene.h)


def splats(rfilter: ReconstructionFilter | None) -> bool:
    """Whether a film with this filter splats (a tent or gaussian with ``estimator="splat"``)."""
    return rfilter is not None and rfilter.estimator == "splat" and rfilter.kind in SPLAT_FILTERS


def reach(rfilter: ReconstructionFilter) -> int:
    """Neighbours on each side whose samples a pixel's weights can reach: ceil(extent + 1/2) - 1."""
    return max(0, math.ceil(rfilter.extent + 0.5) - 1)  # ReconstructionFilter.splat_reach for a splat


def weight(rfilter: ReconstructionFilter, x: np.ndarray) -> np.ndarray:
    """w(x) as cl/film/splat.h evaluates it (Mitsuba's definitions), in float64."""
    x = np.abs(np.asarray(x, np.float64))
    if rfilter.kind == "tent":
        return np.maximum(0.0, 1.0 - x / rfilter.radius)
    alpha = -1.0 / (2.0 * rfilter.stddev ** 2)
    return np.maximum(0.0, np.exp(alpha * x * x) - math.exp(-8.0))


def integral_to(rfilter: ReconstructionFilter, x: np.ndarray) -> np.ndarray:
    """The integral of w from -extent to x (float64)."""
    e = rfilter.extent
    t = np.clip(np.asarray(x, np.float64), -e, e)
    a = np.abs(t)
    if rfilter.kind == "tent":
        half = a - a * a / (2.0 * e)
        total = e / 2.0
    else:
        s = rfilter.stddev
        erf = np.vectorize(math.erf, otypes=[np.float64])
        k = s * math.sqrt(math.pi / 2.0)
        half = k * erf(a / (s * math.sqrt(2.0))) - math.exp(-8.0) * a
        total = k * math.erf(4.0 / math.sqrt(2.0)) - math.exp(-8.0) * e
    return total + np.sign(t) * half


def integral(rfilter: ReconstructionFilter) -> float:
    """The integral of w over its support (per axis)."""
    return float(integral_to(rfilter, np.array(rfilter.extent)))


def expected_weights(rfilter: ReconstructionFilter, n: int, pad: int | None = None) -> np.ndarray:
    """(n,) float64: per axis, the expected sum of a pixel's weights per frame for the samples of a row (or
    column) of n pixels with ``pad`` more on each side (by default the reach: every pixel gets the integral of
    w); pixel i's is the integral of w over [-i - pad - 1/2, n + pad - i - 1/2]. A pixel's is the product of its
    column's and row's."""
    pad = reach(rfilter) if pad is None else pad
    i = np.arange(n, dtype=np.float64)
    return integral_to(rfilter, n + pad - i - 0.5) - integral_to(rfilter, -i - pad - 0.5)


def gather_reference(rfilter: ReconstructionFilter, frame: np.ndarray, pos: np.ndarray) -> tuple[np.ndarray,
                                                                                                  np.ndarray]:
    """numpy's gather for one frame (tests): ``frame`` (H + 2 k, W + 2 k, 3) the samples of the window and
    its margin of k = reach pixels, ``pos`` (H + 2 k, W + 2 k, 2) their positions in their pixels; returns
    sum w L and sum w per window pixel, (H, W, 3) and (H, W), float64, unscaled."""
    k = reach(rfilter)
    h, w = frame.shape[0] - 2 * k, frame.shape[1] - 2 * k
    num, den = np.zeros((h, w, 3)), np.zeros((h, w))
    for dy in range(-k, k + 1):
        for dx in range(-k, k + 1):
            # the sample of q = p + (dx, dy) at offset dx - 1/2 + pos from p's centre
            ys, xs = slice(k + dy, k + dy + h), slice(k + dx, k + dx + w)
            q = pos[ys, xs].astype(np.float64)
            wq = weight(rfilter, dx - 0.5 + q[..., 0]) * weight(rfilter, dy - 0.5 + q[..., 1])
            num += wq[..., None] * frame[ys, xs]
            den += wq
    return num, den


class SplatFilm:
    """The gather pass and the weights' accumulator of a splatting film of width x height pixels, the
    window at (crop_x, crop_y) of an image image_width pixels wide, whose frames hold the window with a margin
    of :func:`reach` pixels on each side."""

    def __init__(self, device: Device, rfilter: ReconstructionFilter, width: int, height: int, batch: int,
                 image_width: int, crop_x: int = 0, crop_y: int = 0, **accumulator_options) -> None:
        self.device = device
        self.rfilter = rfilter
        self.width, self.height, self.batch = width, height, batch
        self.image_width, self.crop_x, self.crop_y = image_width, crop_x, crop_y
        self.reach = reach(rfilter)
        self.padded_width = image_width + 2 * self.reach
        self.inv_norm = 1.0 / integral(rfilter) ** 2
        pixels = width * height
        self.out = alloc(device, 4 * 3 * pixels * batch, f"splatted frames {width}x{height}x{batch}")
        self.weights = alloc(device, 4 * pixels * batch, f"splat weights {width}x{height}x{batch}")
        program = build_program(device, ["film/splat.cl"], defines={"SPLAT_FILTER": SPLAT_FILTERS[rfilter.kind]})
        self._axes_kernel = cl.Kernel(program, "splat_axes")
        self._kernel = cl.Kernel(program, "splat_gather")
        taps = 2 * self.reach + 1
        traced = (width + 2 * self.reach) * (height + 2 * self.reach)
        self.axes = alloc(device, 4 * 2 * taps * traced * batch, f"splat axis weights {width}x{height}x{batch}")
        self.accumulator = Accumulator(device, width, height, channels=1, input_type="float",
                                       **accumulator_options)

    def gather(self, frame: cl.Buffer, count: int, seed: int, first_sample: int) -> cl.Event:
        """The splatted frames and weights of the first ``count`` frames of ``frame`` (the margined window;
        samples first_sample, first_sample + 1, ... of seed ``seed``), into :attr:`out` and :attr:`weights`."""
        q, size, k = self.device.queue, (np.int32(self.width), np.int32(self.height)), np.int32(self.reach)
        self._axes_kernel(q, (self.width + 2 * self.reach, self.height + 2 * self.reach, count), None, self.axes,
                          *size, np.int32(self.padded_width), np.int32(self.crop_x), np.int32(self.crop_y),
                          np.uint32(seed), np.uint32(first_sample), k, np.float32(self.rfilter.extent))
        return self._kernel(q, (self.width, self.height, count), None, frame, self.axes, self.out, self.weights,
                            *size, k, np.float32(self.inv_norm))

    def mean_weights(self, frame: cl.Buffer, spp: int, seed: int) -> np.ndarray:
        """(H, W) float64: each pixel's sum of weights over samples [0, spp) of ``seed``, over spp (the
        weights alone: gathered from ``frame``, whatever it holds, into the weights' accumulator, which
        this restarts)."""
        self.accumulator.reset()
        s = 0
        while s < spp:
            frames = min(self.batch, spp - s)
            self.gather(frame, frames, seed, s)
            self.accumulator.add_batch(self.weights, frames)
            s += frames
        return self.accumulator.image(np.float64)[..., 0] / self.inv_norm
