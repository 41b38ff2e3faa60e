"""The film: a frame buffer of ``batch`` frames that an integrator fills with one sample per
pixel each (frame j: sample ``first + j`` of a batch, so small images fill a wave with several
samples), averaged on the device by an :class:`~pyclpt.film.accumulator.Accumulator`.

Frames are added in sample order, so the sum does not depend on the order in
which paths finished, nor on how many frames a batch held. NaN/inf samples never reach the frame: the integrators'
kernels write 0 instead and mark the pixel in ``drop_marks`` (one byte a pixel,
a plain add, so no kernel that commits a path needs an atomic), and
:meth:`count_dropped`, run by the integrator after each frame, adds the marks to
``dropped`` and clears them (``cl/film/count_dropped.cl``).

A film whose reconstruction filter splats (``ReconstructionFilter(estimator="splat")``,
:mod:`pyclpt.film.splat`) runs its gather pass over each batch before the accumulator: the accumulator
then sums the weighted radiance, a second one the weights, and :meth:`Film.image` is their ratio. Split
sample ranges (distributed tasks) merge exactly by pooling both sums (:meth:`Film.sums`,
:func:`pyclpt.distributed.merge.merge`), never their per-range ratios. Its G-buffer and the frame the
real-time denoisers read (:meth:`Film.denoiser_frame`), and the average OIDN reads
(:meth:`Film.denoiser_image`), are each window pixel's own samples, not splatted (docs/architecture.md, "Pixel
filters").
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pyopencl as cl

from pyclpt.device.context import Device, alloc, fill_buffer
from pyclpt.device.program import build_program
from pyclpt.film.accumulator import Accumulator
from pyclpt.film.aovs import AovFilm
from pyclpt.film.crop import Crop
from pyclpt.film.splat import SplatFilm, splats

if TYPE_CHECKING:
    from pyclpt.scene.model import ReconstructionFilter

# Renderer.render's precision: the sum of the samples in double (emulated double-float on a device
# without cl_khr_fp64), so a long render's mean is as exact as its float samples allow; the
# accumulation is one add per pixel per frame, negligible next to the paths.
DEFAULT_PRECISION = "double"
COUNT_CHUNK = 1024  # marks summed per work-item of cl/film/count_dropped.cl (-DCOUNT_CHUNK)


MAX_BATCH = 64  # frames a batch holds at most (frames_per_batch)
#: Every -D name :attr:`Film.defines` gives.
FILM_DEFINES = ("AOVS", "FILM_CROP")


def frames_per_batch(pixels: int, paths: int) -> int:
    """Frames of a batch: as many as ``paths`` (an integrator's launch or wave size) holds, 1 to
    MAX_BATCH."""
    return max(1, min(MAX_BATCH, paths // max(pixels, 1)))


class Film:
    """A film of an image of width x height pixels, or with ``crop`` of that window of it (the film's own
    ``width``/``height`` are then the window's; :mod:`pyclpt.film.crop`). ``rfilter``: the scene's filter;
    one that splats makes the film splat (:mod:`pyclpt.film.splat`), any other is the kernels' business.
    A splatting film renders its window with a margin of ``pad`` pixels on each side (its ``width``,
    ``height``, ``pixels`` and frames are the margined window's, :attr:`traced`; its image is the window's,
    ``out_width`` x ``out_height``)."""

    def __init__(self, device: Device, width: int, height: int, precision: str = DEFAULT_PRECISION,
                 batch: int = 1, aovs: bool = False, crop: Crop | None = None,
                 rfilter: ReconstructionFilter | None = None, **accumulator_options) -> None:
        if not 1 <= batch <= MAX_BATCH:
            raise ValueError(f"a film batch holds 1 to {MAX_BATCH} frames, got {batch}")
        self.device = device
        self.image_width, self.image_height = width, height
        self.crop = None if crop is None or crop.covers(width, height) else crop
        if self.crop is not None:
            width, height = self.crop.width, self.crop.height
        self.out_width, self.out_height = width, height
        self.pad = rfilter.splat_reach if splats(rfilter) else 0
        x0, y0 = (self.crop.x, self.crop.y) if self.crop is not None else (0, 0)
        #: the window the integrators render: the film's with its margin, possibly beyond the image
        self.traced = Crop(x0 - self.pad, y0 - self.pad, width + 2 * self.pad, height + 2 * self.pad)
        self.width, self.height = self.traced.width, self.traced.height
        self.pixels = self.width * self.height
        self.batch = batch
        width, height = self.width, self.height
        self.frame = alloc(device, 4 * self.pixels * 3 * batch, f"frame buffer {width}x{height}x{batch}")
        self.dropped = alloc(device, 4, "dropped-sample counter")
        self.drop_marks = alloc(device, self.pixels * batch, "dropped-sample marks")
        program = build_program(device, ["film/count_dropped.cl"], defines={"COUNT_CHUNK": COUNT_CHUNK})
        self._count_kernel = cl.Kernel(program, "count_dropped")
        self.accumulator = Accumulator(device, self.out_width, self.out_height, channels=3, precision=precision,
                                       input_type="float", **accumulator_options)
        self.splat: SplatFilm | None = None
        if splats(rfilter):
            self.splat = SplatFilm(device, rfilter, self.out_width, self.out_height, batch, self.image_width, x0, y0,
                                   precision=precision, **accumulator_options)
        # the G-buffer, when the integrators record one (-DAOVS: pyclpt/film/aovs.py); of the window's pixels
        self.aov = AovFilm(device, self.out_width, self.out_height, batch, pad=self.pad) if aovs else None
        # a splatting film with a G-buffer: its frames cropped to the window (frame 0: the real-time
        # denoisers' input, denoiser_frame) and their average (OIDN's, denoiser_image)
        self._own = self.own_accumulator = None
        if self.pad and aovs:
            ow, oh = self.out_width, self.out_height
            self._own = alloc(device, 4 * 3 * ow * oh * batch, f"denoiser frames {ow}x{oh}x{batch}")
            self.own_accumulator = Accumulator(device, ow, oh, channels=3, precision=precision, input_type="float",
                                               **accumulator_options)
        self._no_aovs = None if aovs else alloc(device, 4, "no G-buffer")
        self.clear()

    @property
    def defines(self) -> dict:
        """-D options of the integrators' programs for this film: AOVS when it has a G-buffer, FILM_CROP
        when it holds a crop window or a margin."""
        crop = self.crop is not None or self.pad > 0
        return {**({"AOVS": 1} if self.aov is not None else {}), **({"FILM_CROP": 1} if crop else {})}

    @property
    def view(self) -> tuple[int, int, Crop | None]:
        """The image's width and height and the window the integrators render (None: all of it; a splatting
        film's: its window with the margin, :attr:`traced`): what the scene's constants need
        (``SceneBuffers.args``)."""
        return self.image_width, self.image_height, self.traced if self.pad else self.crop

    def aov_args(self) -> tuple:
        """The integrators' last two kernel arguments (aovs, aov_n): the G-buffer records, or an unused
        placeholder."""
        return self.aov.args() if self.aov is not None else (self._no_aovs, np.int32(0))

    @property
    def frames(self) -> int:
        """Frames in the current average."""
        return self.accumulator.frame_count

    def clear(self) -> None:
        q = self.device.queue
        self.accumulator.reset()
        if self.splat is not None:
            self.splat.accumulator.reset()
        if self.own_accumulator is not None:
            self.own_accumulator.reset()
        fill_buffer(q, self.frame, np.float32(0), 0, 4 * self.pixels * 3 * self.batch)
        fill_buffer(q, self.dropped, np.int32(0), 0, 4)
        fill_buffer(q, self.drop_marks, np.uint8(0), 0, self.pixels * self.batch)
        if self.aov is not None:
            self.aov.clear()

    def count_dropped(self, frames: int = 1) -> cl.Event:
        """Add the dropped-sample marks of the first ``frames`` frames to the counter and clear them
        (after each batch)."""
        n = self.pixels * frames
        chunks = -(-n // COUNT_CHUNK)
        return self._count_kernel(self.device.queue, (chunks,), None, self.drop_marks, np.int32(n), self.dropped)

    def add_frames(self, count: int, seed: int = 0, first_sample: int = 0) -> cl.Event | None:
        """Add the first ``count`` frames of the buffer to the accumulation, in order (None when the
        accumulator has stopped), and their G-buffer records to the G-buffer. ``seed``, ``first_sample``:
        the frames' samples' (a splatting film recomputes their positions from them)."""
        if self.aov is not None:
            self.aov.add_frames(count)
        if self.splat is None:
            return self.accumulator.add_batch(self.frame, count)
        sp = self.splat
        wanted = {**self.accumulator.options, "channels": 1}
        if sp.accumulator.options != wanted:  # follow the film's accumulator (configure restarts both)
            sp.accumulator.configure(**wanted)
        sp.gather(self.frame, count, seed, first_sample)
        sp.accumulator.add_batch(sp.weights, count)
        if self.own_accumulator is not None:
            if self.own_accumulator.options != self.accumulator.options:
                self.own_accumulator.configure(**self.accumulator.options)
            self.own_accumulator.add_batch(self._crop_frames(count), count)
        return self.accumulator.add_batch(sp.out, count)

    def _crop_frames(self, count: int) -> cl.Buffer:
        """The first ``count`` frames cropped to the window (the margin left out), into the denoiser's
        frames, which it returns."""
        row, trow = 12 * self.out_width, 12 * self.width
        cl.enqueue_copy(self.device.queue, self._own, self.frame, src_origin=(12 * self.pad, self.pad, 0),
                        dst_origin=(0, 0, 0), region=(row, self.out_height, count),
                        src_pitches=(trow, trow * self.height), dst_pitches=(row, row * self.out_height))
        return self._own

    def add_frame(self, seed: int = 0, sample: int = 0) -> cl.Event | None:
        """Add the first frame of the buffer to the accumulation (None when the accumulator has stopped)."""
        return self.add_frames(1, seed, sample)

    def keep_accumulation(self, old: Film) -> None:
        """Go on with ``old``'s accumulation (a progressive renderer rebuilt under a changed scene): its
        accumulator, and a splatting film's weights when both splat (else this film's start over)."""
        if (self.splat is None) != (old.splat is None):
            return
        self.accumulator = old.accumulator
        if self.splat is not None and old.splat is not None:
            self.splat.accumulator = old.splat.accumulator
        if self.own_accumulator is not None and old.own_accumulator is not None:
            self.own_accumulator = old.own_accumulator

    def warm_up(self) -> None:
        self.accumulator.warm_up()
        if self.splat is not None:
            self.splat.accumulator.warm_up()
        if self.own_accumulator is not None:
            self.own_accumulator.warm_up()

    def denoiser_frame(self) -> cl.Buffer:
        """Frame 0's own samples of the window, one per pixel, interleaved RGB float32 on the device: what the
        real-time denoisers read with the G-buffer (:attr:`aov` ``.mean``). A film without a margin: the
        frame buffer itself; a splatting film: its frame cropped to the window, not splatted (a splatted
        frame's noise is correlated between neighbours, which the denoisers do not expect; its G-buffer is
        of the same samples)."""
        if self.pad == 0:
            return self.frame
        if self._own is None:
            raise ValueError("this film records no G-buffer: it has no denoiser frame")
        return self._crop_frames(1)

    def denoiser_image(self) -> np.ndarray:
        """The average OIDN denoises with the G-buffer's averaged guides, (H, W, 3) float32: :meth:`image`,
        except for a splatting film, whose window pixels' own samples it averages (the splatted image's
        noise is correlated between neighbours; OIDN does not support weighted pixel sampling)."""
        if self.own_accumulator is None:
            if self.pad:
                raise ValueError("this film records no G-buffer: it has no denoiser image")
            return self.image()
        return self.own_accumulator.image()

    def read_own_frame(self, j: int = 0) -> np.ndarray:
        """Frame ``j``'s own samples of the window, (H, W, 3) float32: :meth:`read_frame` without a margin; a
        splatting film's samples before the gather (frame 0: :meth:`denoiser_frame`)."""
        out = np.empty((self.height, self.width, 3), np.float32)
        cl.enqueue_copy(self.device.queue, out, self.frame, src_offset=4 * 3 * self.pixels * j)
        p = self.pad
        return np.ascontiguousarray(out[p:p + self.out_height, p:p + self.out_width])

    def read_frame(self, j: int = 0) -> np.ndarray:
        """Frame ``j`` of the buffer, (H, W, 3) float32 (a splatting film: that frame's splatted image of its
        window, sum w L / sum w, after :meth:`add_frames`)."""
        if self.splat is not None:
            sp, n = self.splat, self.out_width * self.out_height
            out = np.empty((self.out_height, self.out_width, 3), np.float32)
            w = np.empty((self.out_height, self.out_width, 1), np.float32)
            cl.enqueue_copy(self.device.queue, out, sp.out, src_offset=4 * 3 * n * j)
            cl.enqueue_copy(self.device.queue, w, sp.weights, src_offset=4 * n * j)
            return np.divide(out, w, out=np.zeros_like(out), where=w > 0)
        out = np.empty((self.height, self.width, 3), np.float32)
        cl.enqueue_copy(self.device.queue, out, self.frame, src_offset=4 * 3 * self.pixels * j)
        return out

    def image(self) -> np.ndarray:
        """The average of the frames added so far, (H, W, 3) float32 (a splatting film: the weighted
        radiance's over the weights', 0 where a pixel has no weight)."""
        image = self.accumulator.image()
        if self.splat is None:
            return image
        w = self.splat.accumulator.image()
        return np.divide(image, w, out=np.zeros_like(image), where=w > 0)

    def sums(self) -> tuple[np.ndarray, np.ndarray | None]:
        """What sample ranges merge by: the accumulator's sum as it keeps it, (H, W, 3) float64, and None; a
        splatting film: the sum of its weighted radiance and that of its weights, (H, W) float64, the image
        being their ratio. Both add over split sample ranges, so pooled they give the one-shot image up
        to the rounding of the adds that join them (:func:`pyclpt.distributed.merge.merge`)."""
        total = self.accumulator.sum()
        if self.splat is None:
            return total, None
        return total, self.splat.accumulator.sum()[..., 0]

    def sum(self) -> np.ndarray:
        """The sum of the frames added so far as the accumulator keeps it, (H, W, 3) float64 (a splatting
        film: its image, sum w L / sum w, in float64, times the frames added: per range a ratio, which
        does not add up over split ranges; :meth:`sums` does)."""
        total = self.accumulator.sum()
        if self.splat is None:
            return total
        w = self.splat.accumulator.sum()
        return np.divide(total, w, out=np.zeros_like(total), where=w > 0) * self.accumulator.divisor

    def dropped_samples(self) -> int:
        out = np.zeros(1, np.int32)
        cl.enqueue_copy(self.device.queue, out, self.dropped)
        return int(out[0])
