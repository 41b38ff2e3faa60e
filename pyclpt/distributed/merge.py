"""Merging the workers' partial sums, in a fixed order, into the image of one machine.

A worker returns the sum of its sample range as the film's accumulator keeps it (float32 samples
added in sample order in double, :meth:`~pyclpt.rendering.renderer.Renderer.render_sum`) with the
range. :func:`merge` checks that the ranges tile the render's sample range and adds the sums in
sample order (whatever order the tasks finished in), so the result is reproducible; it differs from
one machine's single running sum only by the rounding of the few double additions that join the
ranges: at most a few units in the last place of double (tested: relative difference <= 1e-12).
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
    instead. ``crop``: the tile of the image they cover (None: all of it). ``gbuffer``: a denoised
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


def merge(parts: Iterable[PartialSum], spp: int, first_sample: int = 0) -> tuple[np.ndarray, int]:
    """The sum over [first_sample, first_sample + spp) as (H, W, 3) float64 and its dropped-sample count:
    the partial sums added in sample order."""
    ordered = _in_order(parts, first_sample, spp)
    total = ordered[0].total.astype(np.float64, copy=True)
    for p in ordered[1:]:
        total += p.total
    return total, sum(p.dropped for p in ordered)


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


def running_averages(parts: Iterable[PartialSum], spp: int) -> list[np.ndarray]:
    """From per-sample parts covering [0, spp): the image after each sample, (H, W, 3) float32 each, as a
    progressive render's accumulation gives them (the frames added one by one, in order, in double)."""
    total, out = None, []
    for p in _in_order(parts, 0, spp):
        for frame in p.frames:
            total = frame.astype(np.float64) if total is None else total + frame
            out.append(average(total, len(out) + 1))
    return out
