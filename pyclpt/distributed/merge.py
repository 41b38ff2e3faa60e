"""Merging the workers' partial sums, in a fixed order, into the image of one machine.

A worker returns the sum of its sample range as the film's accumulator keeps it (float32 samples
added in sample order in double, :meth:`~pyclpt.rendering.renderer.Renderer.render_sum`) with the
range. :func:`merge` checks that the ranges tile the render's sample range and adds the sums in
sample order (whatever order the tasks finished in), so the result is reproducible; it differs from
one machine's single running sum only by the rounding of the few double additions that join the
ranges: at most a few units in the last place of double (tested: relative difference <= 1e-12).

A splatting film (:mod:`pyclpt.film.splat`) returns two sums, its weighted radiance's (``total``) and its
weights' (``weights``), since its image is their ratio over every sample: the merge adds each over the
ranges and divides once (pooled), so a split render is the one-shot render within the same bound; the
average of per-range ratios would not be.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from pyclpt.film.crop import Crop


@dataclass
class PartialSum:
    """Samples [first_sample, first_sample + count) of one view, summed per pixel and channel (H, W, 3)
    float64; ``frames``: with a per-sample task, each sample's own (count, H, W, 3) float32 frame
    instead. ``weights``: a splatting film's sum of weights, (H, W) float64, ``total`` then the sum of its
    weighted radiance (per-sample: ``frame_weights``, (count, H, W) float32, beside ``frames``; None: a film
    that does not splat). ``crop``: the tile of the image they cover (None: all of it). ``gbuffer``: a denoised
    sequence's frame's G-buffer, (AOV_COUNT, H, W) float32 (``AovFilm.read()``). ``worker``, ``seconds``:
    who rendered it and how long the rendering took there."""

    first_sample: int
    count: int
    total: np.ndarray | None
    frame: int = 0
    dropped: int = 0
    worker: str = ""
    seconds: float = 0.0
    frames: np.ndarray | None = None
    crop: Crop | None = None
    gbuffer: np.ndarray | None = None
    weights: np.ndarray | None = None
    frame_weights: np.ndarray | None = None


def _checked(parts: Iterable[PartialSum]) -> list[PartialSum]:
    """``parts`` as a list, TypeError naming the first that is not a PartialSum (a cancelled or failed
    task's exception is not a result: a lost scheduler cancels every task)."""
    parts = list(parts)
    for p in parts:
        if not isinstance(p, PartialSum):
            what = "a cancelled or failed task's exception" if isinstance(p, BaseException) else "not a result"
            raise TypeError(f"cannot merge {type(p).__name__} {str(p)[:120]!r} ({what}): every part must be a "
                            f"PartialSum")
    return parts


def _in_order(parts: Iterable[PartialSum], first_sample: int, spp: int) -> list[PartialSum]:
    ordered = sorted(_checked(parts), key=lambda p: p.first_sample)
    s = first_sample
    for p in ordered:
        if p.first_sample != s:
            what = "overlap" if p.first_sample < s else "leave a gap"
            raise ValueError(f"partial sums {what} at sample {s}: next range starts at {p.first_sample}")
        s += p.count
    if s != first_sample + spp:
        raise ValueError(f"partial sums cover samples {first_sample}..{s - 1}, "
                         f"not {first_sample}..{first_sample + spp - 1}")
    return ordered


def pooled(total: np.ndarray, weights: np.ndarray | None, spp: int) -> np.ndarray:
    """A splatting film's sum of weighted radiance ``total`` and of weights ``weights`` as the sum of ``spp``
    samples of its image, (H, W, 3) float64: total / weights * spp (0 where no weight), as
    :meth:`pyclpt.film.film.Film.sum`; ``weights`` None: ``total`` itself."""
    if weights is None:
        return total
    w = np.asarray(weights, np.float64)[..., None]
    return np.divide(total, w, out=np.zeros_like(total), where=w > 0) * float(spp)


def merge(parts: Iterable[PartialSum], spp: int, first_sample: int = 0) -> tuple[np.ndarray, int]:
    """The sum over [first_sample, first_sample + spp) as (H, W, 3) float64 and its dropped-sample count:
    the partial sums added in sample order (a splatting film's: its weighted radiance and its weights
    added apart, then :func:`pooled`)."""
    ordered = _in_order(parts, first_sample, spp)
    if (ordered[0].weights is None) != any(p.weights is None for p in ordered):
        raise ValueError("cannot merge a splatting film's partial sums with another film's")
    total = ordered[0].total.astype(np.float64, copy=True)
    weights = None if ordered[0].weights is None else ordered[0].weights.astype(np.float64, copy=True)
    for p in ordered[1:]:
        total += p.total
        if weights is not None:
            weights += p.weights
    return pooled(total, weights, spp), sum(p.dropped for p in ordered)


def merge_tiles(parts: Iterable[PartialSum], spp: int, width: int, height: int,
                first_sample: int = 0) -> tuple[np.ndarray, int]:
    r"""The sum over [first_sample, first_sample + spp) of a width x height image whose tiles were rendered
    apart, (H, W, 3) float64, and its dropped-sample count: each tile's sums :func:`merge`\ d, and put in
    its place. ValueError unless the tiles cover the image once."""
    by_tile: dict[Crop, list[PartialSum]] = {}
    for p in _checked(parts):
        by_tile.setdefault(p.crop or Crop(0, 0, width, height), []).append(p)
    covered = np.zeros((height, width), np.int32)
    total, dropped = np.empty((height, width, 3), np.float64), 0
    for crop, tile_parts in by_tile.items():
        total[crop.slices()], n = merge(tile_parts, spp, first_sample)
        covered[crop.slices()] += 1
        dropped += n
    if not (covered == 1).all():
        y, x = np.argwhere(covered != 1)[0]
        raise ValueError(f"the tiles cover pixel ({x}, {y}) of the {width}x{height} image "
                         f"{covered[y, x]} times, not once")
    return total, dropped


def average(total: np.ndarray, spp: int) -> np.ndarray:
    """The image of a sum of ``spp`` samples, (H, W, 3) float32 (the accumulator's resolve: sum / n,
    rounded to float)."""
    return (total / float(spp)).astype(np.float32)


def splat_average(total: np.ndarray, weights: np.ndarray | None, n: int) -> np.ndarray:
    """A splatting film's image from its sums over ``n`` samples, (H, W, 3) float32, as
    :meth:`pyclpt.film.film.Film.image` resolves it: each sum's average rounded to float, then their ratio
    (0 where no weight); ``weights`` None (a film that does not splat): :func:`average`."""
    if weights is None:
        return average(total, n)
    num, w = average(total, n), average(np.asarray(weights)[..., None], n)
    return np.divide(num, w, out=np.zeros_like(num), where=w > 0)


class RunningAverage:
    """Frames added one by one, in order, in double, as a progressive render's accumulation adds them
    (a splatting film's: its weighted radiance and its weights apart); :meth:`add` returns the image after
    each, (H, W, 3) float32."""

    def __init__(self) -> None:
        self.total: np.ndarray | None = None
        self.weights: np.ndarray | None = None
        self.count = 0

    def add(self, frame: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """Add the next frame (a splatting film's: its weighted radiance and its ``weights``); the image so far."""
        self.total = frame.astype(np.float64) if self.total is None else self.total + frame
        if weights is not None:
            self.weights = weights.astype(np.float64) if self.weights is None else self.weights + weights
        self.count += 1
        return splat_average(self.total, self.weights, self.count)

    def add_part(self, part: PartialSum) -> list[np.ndarray]:
        """A per-sample part's frames, in order: the image after each."""
        fw = part.frame_weights
        return [self.add(frame, None if fw is None else fw[k]) for k, frame in enumerate(part.frames)]


def running_averages(parts: Iterable[PartialSum], spp: int) -> list[np.ndarray]:
    """From per-sample parts covering [0, spp): the image after each sample, (H, W, 3) float32 each, as a
    progressive render's accumulation gives them (the frames added one by one, in order, in double)."""
    acc, out = RunningAverage(), []
    for p in _in_order(parts, 0, spp):
        out += acc.add_part(p)
    return out
