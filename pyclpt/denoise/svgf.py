"""SVGF on the device: spatiotemporal variance-guided filtering (Schied et al. 2017, as Falcor's
SVGFPass), with NRD RELAX's fast history clipping the long one.

One frame is twelve passes, one kernel each in ``cl/denoise/`` and one method here of the same name:
:meth:`Svgf.demodulate` (sanitize, divide by the albedo, this frame's geometry),
:meth:`Svgf.reproject` (the footprint albedo that the sample is demodulated by, firefly clamp,
reproject and accumulate the fast history, moments and history length), :meth:`Svgf.clip_history` (clip
the long history into the fast one's neighbourhood and blend; the anti-lag statistic; the clamp's
deficit history), :meth:`Svgf.antilag` (cut the histories where the statistic says the lighting
changed, in the same frame), :meth:`Svgf.deficit` and :meth:`Svgf.deficit_gain` (per tile, the share
of the light that the firefly clamp took, which modulate gives back), :meth:`Svgf.variance` (temporal
or, on a short history, spatial variance),
:meth:`Svgf.atrous` (``iterations`` a-trous iterations), :meth:`Svgf.conserve` and
:meth:`Svgf.conserve_gain` (per tile, the gain that gives the filtered light the sum of the unfiltered
light, robust to a lone firefly) and :meth:`Svgf.modulate` (times the footprint albedo,
plus the emission's own temporal history: the emitted part of the colour is kept out of the filter).
:meth:`Svgf.count_dropped` adds up the NaN/inf inputs (``cl/film/count_dropped.cl``).

All state stays on the device. The history is double-buffered: each frame writes the buffers the
previous frame read from, and the two swap roles (nothing is copied); the a-trous iteration
``feedback_tap`` writes straight into the colour history.
"""
from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np
import pyopencl as cl

from pyclpt.common.checks import check_int
from pyclpt.denoise.gbuffer import AOV_COUNT
from pyclpt.denoise.settings import DenoiserSettings
from pyclpt.device.context import Device, alloc, check_memory, fill_buffer, get_device, take_count
from pyclpt.device.profile import KernelProfile
from pyclpt.device.program import build_program

log = logging.getLogger("pyclpt.denoise")

#: The passes of a frame, in launch order (each a kernel, a .cl file and a method of Svgf).
PASSES = ("demodulate", "count_dropped", "reproject", "light_change", "light_age", "clip_history", "antilag",
          "deficit", "deficit_gain", "variance", "atrous", "conserve", "conserve_gain", "modulate")
#: Side of the tiles over which the firefly clamp's deficit is measured (cl/denoise/svgf.h, DEFICIT_TILE).
DEFICIT_TILE = 16
#: Pixels summed by one work-item of light_change (cl/denoise/svgf.h, LIGHT_CHUNK), and the light age the
#: histories start with (LIGHT_AGE_MAX: the lighting changed long ago).
LIGHT_CHUNK = 1024
LIGHT_AGE_MAX = 1 << 20
#: Side of the tiles over which the a-trous filter's energy balance is kept (cl/denoise/svgf.h, CONSERVE_TILE).
CONSERVE_TILE = 8
#: Where the anti-lag statistic stays at or under this fraction of ``antilag``, what the history clipping
#: takes is the noise of a skewed 1-sample distribution, not a change of the lighting: it joins the
#: clamp's deficit (cl/denoise/clip_history.cl). 0.5 before; 1, up to where the anti-lag starts to cut,
#: brought the cornell-bunny's 32-frame means from 0.9958 / 0.9942 / 0.9933 to 0.9974 / 0.9960 / 0.9951
#: of the plain average's and the living room's from 0.9863 / 0.9907 / 0.9950 to 0.9866 / 0.9910 /
#: 0.9958, relMSE at frame 8 0.338 and 0.340 x the plain average's (docs/denoising.md, "Energy at 32
#: frames"; its light-change lag there).
CLIP_NOISE = 1.0
#: Channels of a geometry record (cl/denoise/svgf.h, GEO_COUNT).
GEO_COUNT = 8
#: Floats of padding before and after each internal buffer (cl/denoise/svgf.h, PAD).
PAD = 256
#: Marks summed by one work-item of cl/film/count_dropped.cl.
COUNT_CHUNK = 1024
#: Build options of the denoiser's programs. Denormals are flushed to zero: the a-trous weights
#: (a cosine to the 128th power, products of small exponentials) and their squares reach the
#: denormal range wherever neighbours differ strongly, and each denormal result costs the CPU a
#: microcode assist: at 1280x720 one a-trous iteration over random colours took 107 ms instead of
#: 20 on PoCL (73 instead of 15 on Intel's runtime). A weight of 1e-40 counts as nothing either
#: way. This is not fast math: every other IEEE rule (NaN, inf, rounding, no reassociation) still
#: holds. PoCL sets the CPU's flush mode per program, so the renderer's kernels keep their denormals.
BUILD_OPTIONS = ("-cl-denorms-are-zero",)
#: Kernel launches the profile keeps before it starts over (a renderer denoises every frame).
PROFILE_LIMIT = 20000


def local_size(device: Device, width: int) -> tuple[int, int]:
    """The work-group shape of the 2D passes: on a CPU a row of up to 256 pixels (the
    accumulator's, docs/accumulation.md), elsewhere 16x16 tiles (Falcor's)."""
    limit = int(device.device.max_work_group_size)
    if device.device.type & cl.device_type.CPU:
        lx = 1
        while lx < min(width, 256, limit):
            lx *= 2
        return (min(lx, limit), 1)
    side = 16
    while side * side > limit:
        side //= 2
    return (side, side)


def check_buffer(buf: object, nbytes: int, what: str, device: Device) -> cl.Buffer:
    """``buf`` if it is a buffer of ``device``'s context of at least ``nbytes``, else a TypeError or
    ValueError saying what is wrong (instead of an OpenCL error at the launch)."""
    if not isinstance(buf, cl.Buffer):
        raise TypeError(f"{what} must be a pyopencl Buffer, got {type(buf).__name__}")
    if buf.context != device.context:
        raise ValueError(f"{what} belongs to another OpenCL context than the denoiser's ({device.name})")
    if buf.size < nbytes:
        raise ValueError(f"{what} holds {buf.size} bytes, fewer than the {nbytes} it needs")
    return buf


class Svgf:
    """SVGF for frames of ``width`` x ``height`` on one device (see the module)."""

    def __init__(self, device: Device | str | None, width: int, height: int,
                 settings: DenoiserSettings | None = None) -> None:
        self.width = check_int(width, "denoiser width", lo=1, hi=65536)
        self.height = check_int(height, "denoiser height", lo=1, hi=65536)
        self.device = get_device(device)
        self.pixels = self.width * self.height
        self._settings = self._checked(settings)
        self.profile = KernelProfile()
        lx, ly = local_size(self.device, self.width)
        self.local = (lx, ly)
        self.global_size = (-(-self.width // lx) * lx, -(-self.height // ly) * ly)
        n, f = self.pixels, 4
        size = f"{self.width}x{self.height}"
        needs = {"denoiser history": 2 * f * n * (GEO_COUNT + 4 + 3 + 2 + 1 + 3 + 3 + 3),
                 "denoiser work buffers": f * n * (6 + 4 + 4 + 3 + 3 + 3 + 3) + n}
        check_memory(self.device, needs, hint="denoise a smaller image")
        self._padded: list[tuple[cl.Buffer, int]] = []
        self._geo = [self._alloc(GEO_COUNT, f"denoiser geometry {size}") for _ in range(2)]
        self._hist = [self._alloc(4, f"denoiser colour history {size}") for _ in range(2)]
        self._fast = [self._alloc(3, f"denoiser fast history {size}") for _ in range(2)]
        self._moments = [self._alloc(2, f"denoiser moments {size}") for _ in range(2)]
        self._len = [self._alloc(1, f"denoiser history length {size}") for _ in range(2)]
        self._emis = [self._alloc(3, f"denoiser emission history {size}") for _ in range(2)]
        self._deficit = [self._alloc(3, f"denoiser clamp deficit history {size}") for _ in range(2)]
        self._albedo = [self._alloc(3, f"denoiser albedo history {size}") for _ in range(2)]
        self._tiles_x = -(-self.width // DEFICIT_TILE)
        self._tiles_y = -(-self.height // DEFICIT_TILE)
        self._tiles = [alloc(self.device, f * 6 * self._tiles_x * self._tiles_y, f"denoiser deficit tiles {size}")
                       for _ in range(2)]
        self._ctiles_x = -(-self.width // CONSERVE_TILE)
        self._ctiles_y = -(-self.height // CONSERVE_TILE)
        self._conserve = [alloc(self.device, f * 3 * self._ctiles_x * self._ctiles_y, f"denoiser conserve tiles {size}")
                          for _ in range(2)]
        self._emission_pair = [self._alloc(3, f"denoiser frame emission {size}") for _ in range(2)]
        self._lag = self._alloc(3, f"denoiser anti-lag statistic {size}")
        self._temporal = self._alloc(6, f"denoiser temporal {size}")
        self._ping = [self._alloc(4, f"denoiser a-trous {size}") for _ in range(2)]
        self.output = alloc(self.device, f * n * 3, f"denoised image {size}")
        self._marks = alloc(self.device, n, f"denoiser non-finite marks {size}")
        self._dropped = alloc(self.device, 4, "denoiser non-finite counter")
        self._lit = alloc(self.device, n, f"denoiser emitter-change marks {size}")
        self._light_count = alloc(self.device, 4, "denoiser light-change count")
        self._light_age = alloc(self.device, 4, "denoiser light-change age")
        self._dropped_total = 0
        self._build()
        log.debug("svgf %s on %s: %s", size, self.device.name, self._settings)
        self._cur = 0
        self._src: cl.Buffer | None = None  # the a-trous input of the current frame
        self.frames = 0
        fill_buffer(self.device.queue, self._dropped, np.int32(0), 0, 4)
        fill_buffer(self.device.queue, self._marks, np.uint8(0), 0, n)
        fill_buffer(self.device.queue, self._lit, np.uint8(0), 0, n)
        for buf, nbytes in self._padded:  # the pads stay 0: finite values for taps outside the image
            fill_buffer(self.device.queue, buf, np.float32(0), 0, nbytes)
        self.reset()

    def _alloc(self, channels: int, what: str) -> cl.Buffer:
        """A planar buffer of ``channels`` floats per pixel with PAD floats before and after."""
        nbytes = 4 * (channels * self.pixels + 2 * PAD)
        buf = alloc(self.device, nbytes, what)
        self._padded.append((buf, nbytes))
        return buf

    # -- settings and programs -------------------------------------------------------------------
    @staticmethod
    def _checked(settings: object) -> DenoiserSettings:
        if settings is None:
            return DenoiserSettings()
        if not isinstance(settings, DenoiserSettings):
            raise TypeError(f"settings must be a DenoiserSettings or None, got {type(settings).__name__}")
        return settings.validate()

    @property
    def settings(self) -> DenoiserSettings:
        return self._settings

    @settings.setter
    def settings(self, settings: DenoiserSettings) -> None:
        """New settings take effect from the next frame (the history is kept). Changing a field of the
        current settings in place works too: the next frame checks them again first."""
        self._settings = self._checked(settings)
        self._build()

    def _build(self) -> None:
        d = self.device
        kernels = {}
        phi = self._settings.phi_normal
        power_of_two = phi >= 1 and phi == 2.0 ** int(math.log2(phi))
        squarings = {"NORMAL_SQUARINGS": int(math.log2(phi))} if power_of_two else {}
        for name in ("demodulate", "reproject", "light_change", "light_age", "antilag", "deficit", "deficit_gain",
                     "variance", "atrous", "conserve", "conserve_gain", "modulate"):
            defines = squarings if name in ("variance", "atrous") else {}
            kernels[name] = cl.Kernel(build_program(d, [f"denoise/{name}.cl"], defines=defines,
                                                    options=BUILD_OPTIONS), name)
        kernels["clip_history"] = cl.Kernel(
            build_program(d, ["denoise/clip_history.cl"], defines={"CLIP_RADIUS": self._settings.clip_radius},
                          options=BUILD_OPTIONS), "clip_history")
        kernels["count_dropped"] = cl.Kernel(
            build_program(d, ["film/count_dropped.cl"], defines={"COUNT_CHUNK": COUNT_CHUNK}), "count_dropped")
        self._kernels = kernels
        self._applied = dataclasses.replace(self._settings)  # what the programs were built for

    # -- state -----------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the history: the next frame starts over (history length 1 everywhere)."""
        q = self.device.queue
        n = self.pixels
        for bufs, channels in ((self._geo, GEO_COUNT), (self._hist, 4), (self._fast, 3), (self._moments, 2),
                               (self._len, 1), (self._emis, 3), (self._deficit, 3), (self._albedo, 3), ([self._lag], 3),
                               (self._emission_pair, 3)):
            for buf in bufs:
                fill_buffer(q, buf, np.float32(0), 4 * PAD, 4 * n * channels)
        fill_buffer(q, self._light_count, np.int32(0), 0, 4)
        fill_buffer(q, self._light_age, np.int32(LIGHT_AGE_MAX), 0, 4)  # the lighting changed long ago
        self.frames = 0

    @property
    def _prev(self) -> int:
        return 1 - self._cur

    def history_length(self) -> np.ndarray:
        """The history length N of each pixel after the last frame, (H, W) int32 (0 before any)."""
        out = np.empty(self.pixels, np.float32)
        cl.enqueue_copy(self.device.queue, out, self._len[self._cur], src_offset=4 * PAD)
        return out.astype(np.int32).reshape(self.height, self.width)

    def _planes(self, buf: cl.Buffer, first: int, count: int) -> np.ndarray:
        n = self.pixels
        out = np.empty(count * n, np.float32)
        cl.enqueue_copy(self.device.queue, out, buf, src_offset=4 * (PAD + first * n))
        return out.reshape(count, self.height, self.width).transpose(1, 2, 0).copy()

    def reprojected(self) -> np.ndarray:
        """The long colour history as the last frame's reproject fetched it (demodulated illumination,
        before clipping; 0 where disoccluded), (H, W, 3) float32: for tests and debugging."""
        return self._planes(self._temporal, 3, 3)

    def history(self) -> np.ndarray:
        """The colour history the next frame will reproject (demodulated illumination), (H, W, 3)."""
        return self._planes(self._hist[self._cur], 0, 3)

    @property
    def dropped(self) -> int:
        """Non-finite inputs replaced since the denoiser was made: one per pixel whose colour had a
        NaN/inf, one per pixel whose albedo had one, and one each for a NaN or -inf depth, a normal
        with a NaN/inf and a motion with a NaN/inf (+inf depth is the sky convention: not counted).
        A bad G-buffer value makes that pixel background (depth, normal) or not reprojected (motion)."""
        new = take_count(self.device, self._dropped)
        if new:
            log.info("svgf: %d non-finite inputs (colour, albedo or G-buffer values) replaced", new)
        self._dropped_total += new
        return self._dropped_total

    def _record(self, name: str, event: cl.Event) -> cl.Event:
        if len(self.profile.sequence) >= PROFILE_LIMIT:
            self.profile.clear()
        self.profile.record(name, event)
        return event

    def _args2d(self) -> tuple:
        return (np.int32(self.width), np.int32(self.height))

    # -- the passes ------------------------------------------------------------------------------
    def demodulate(self, color: cl.Buffer, aovs: cl.Buffer) -> cl.Event:
        """Pass 1 (cl/denoise/demodulate.cl): the sanitized, demodulated sample and its luminance (into
        the a-trous buffer, free until the variance pass), this frame's geometry, the NaN/inf marks."""
        ev = self._kernels["demodulate"](
            self.device.queue, self.global_size, self.local, color, aovs, self._ping[0], self._geo[self._cur],
            self._emission_pair[self._cur], self._marks, *self._args2d(), np.int32(1))
        return self._record("demodulate", ev)

    def reproject(self, aovs: cl.Buffer) -> cl.Event:
        """Pass 2 (cl/denoise/reproject.cl): the footprint albedo (the pixel's albedo divisors blended as its
        long history), the sample demodulated by it and firefly-clamped, the reprojected histories (a
        previous pixel is taken where it shows the same surface or its sample moves with this one's);
        the fast history, moments and history length of this frame (cut by :meth:`antilag`)."""
        s, c, p = self._settings, self._cur, self._prev
        ev = self._kernels["reproject"](
            self.device.queue, self.global_size, self.local, self._ping[0], self._emission_pair[c],
            self._emission_pair[p], self._geo[c], aovs,
            self._geo[p], self._hist[p], self._fast[p], self._moments[p], self._len[p], self._emis[p],
            self._deficit[p], self._albedo[p], self._temporal, self._deficit[c], self._albedo[c], self._fast[c],
            self._moments[c], self._len[c],
            self._emis[c], self._lit, *self._args2d(),
            np.float32(s.depth_threshold), np.float32(s.normal_threshold), np.float32(s.firefly_ratio),
            np.float32(s.firefly_sigma), np.float32(s.max_history), np.float32(s.alpha_min),
            np.float32(s.moments_alpha_min), np.float32(s.fast_alpha))
        return self._record("reproject", ev)

    def count_dropped(self) -> cl.Event:
        """Add this frame's non-finite marks to the counter (cl/film/count_dropped.cl)."""
        chunks = -(-self.pixels // COUNT_CHUNK)
        ev = self._kernels["count_dropped"](self.device.queue, (chunks,), None, self._marks,
                                            np.int32(self.pixels), self._dropped)
        return self._record("count_dropped", ev)

    @property
    def _accum(self) -> cl.Buffer:
        """Where clip_history writes the long history: the colour history itself when the history
        keeps the unfiltered accumulation (feedback_tap -1), else a scratch buffer."""
        return self._hist[self._cur] if self._settings.feedback_tap < 0 else self._ping[1]

    def light_change(self) -> cl.Event:
        """Pass 2b (cl/denoise/light_change.cl): how many pixels saw a light change this frame (reproject's marks)."""
        chunks = -(-self.pixels // LIGHT_CHUNK)
        ev = self._kernels["light_change"](self.device.queue, (chunks,), None, self._lit, np.int32(self.pixels),
                                           self._light_count)
        return self._record("light_change", ev)

    def light_age(self) -> cl.Event:
        """Pass 2c (cl/denoise/light_age.cl): frames since the lighting changed in view, which :meth:`antilag` reads."""
        ev = self._kernels["light_age"](self.device.queue, (1,), None, self._light_count, self._light_age,
                                        np.int32(self.pixels))
        return self._record("light_age", ev)

    def clip_history(self) -> cl.Event:
        """Pass 3 (cl/denoise/clip_history.cl): the long history clipped and blended (one work-item per
        pixel and channel); the anti-lag statistic that :meth:`antilag` reads."""
        s = self._settings
        ev = self._kernels["clip_history"](
            self.device.queue, (*self.global_size, 3), (*self.local, 1), self._temporal, self._fast[self._cur],
            self._len[self._cur], self._moments[self._cur], self._ping[0], self._deficit[self._cur], self._accum,
            self._lag, *self._args2d(),
            np.float32(s.alpha_min), np.float32(s.clip_gamma), np.float32(s.fast_alpha / (2.0 - s.fast_alpha)),
            np.float32(CLIP_NOISE * s.antilag if s.give_back else 0.0))
        return self._record("clip_history", ev)

    def antilag(self) -> cl.Event:
        """Pass 3b (cl/denoise/antilag.cl): where clip_history's statistic says the lighting changed, the
        history length, moments and fast and long histories of this frame cut, in place."""
        s, c = self._settings, self._cur
        ev = self._kernels["antilag"](
            self.device.queue, self.global_size, self.local, self._temporal, self._emission_pair[c], self._lag,
            self._ping[0],
            self._deficit[c], self._accum, self._fast[c], self._moments[c], self._len[c], self._emis[c],
            self._light_age, *self._args2d(),
            np.float32(s.antilag if s.clip_gamma >= 0 else 0.0), np.float32(s.antilag_changed),
            np.int32(s.antilag_frames), np.float32(s.alpha_min),
            np.float32(s.moments_alpha_min), np.float32(s.fast_alpha))
        return self._record("antilag", ev)

    def deficit(self, aovs: cl.Buffer) -> cl.Event:
        """Pass 3c (cl/denoise/deficit.cl): per tile of DEFICIT_TILE pixels, the share of its light that the
        firefly clamp took (the clamp's deficit history over the long one), which modulate gives back."""
        ev = self._kernels["deficit"](
            self.device.queue, (self._tiles_x, self._tiles_y), None, self._accum, self._deficit[self._cur],
            self._albedo[self._cur], self._len[self._cur], self._tiles[0], *self._args2d())
        return self._record("deficit", ev)

    def deficit_gain(self) -> cl.Event:
        """Pass 3d (cl/denoise/deficit_gain.cl): per tile, the share modulate gives back: the mean of the
        3x3 tiles' shares around it, the largest left out (a lone firefly's tile gives nothing back)."""
        ev = self._kernels["deficit_gain"](
            self.device.queue, (self._tiles_x, self._tiles_y), None, self._tiles[0], self._tiles[1],
            *self._args2d())
        return self._record("deficit_gain", ev)

    def variance(self) -> cl.Event:
        """Pass 4 (cl/denoise/variance.cl): illumination and variance, the a-trous input."""
        s, c = self._settings, self._cur
        ev = self._kernels["variance"](
            self.device.queue, self.global_size, self.local, self._accum, self._moments[c], self._len[c],
            self._geo[c], self._ping[0], *self._args2d(), np.int32(s.variance_radius), np.float32(s.phi_color),
            np.float32(s.phi_normal), np.float32(s.n_eff_max))
        self._src = self._ping[0]
        return self._record("variance", ev)

    def atrous(self, iteration: int) -> cl.Event:
        """Pass 5 (cl/denoise/atrous.cl), iteration ``iteration`` (step 2^iteration) of the a-trous
        filter, reading the previous iteration's output (or variance's)."""
        s = self._settings
        iteration = check_int(iteration, "a-trous iteration", lo=0, hi=30)
        src = self._src if self._src is not None else self._ping[0]
        if iteration == s.feedback_tap:
            dst = self._hist[self._cur]
        else:
            dst = self._ping[1] if src is self._ping[0] else self._ping[0]
        ev = self._kernels["atrous"](
            self.device.queue, self.global_size, self.local, src, self._geo[self._cur], self._len[self._cur], dst,
            *self._args2d(),
            np.int32(1 << iteration), np.float32(s.phi_color), np.float32(s.phi_normal), np.float32(s.phi_depth))
        self._src = dst
        return self._record("atrous", ev)

    def _conserving(self) -> bool:
        """Whether this frame keeps the filter's energy balance: ``conserve`` on and a filter to balance."""
        return self._settings.conserve and self._settings.iterations > 0

    def conserve(self, aovs: cl.Buffer) -> cl.Event:
        """Pass 5b (cl/denoise/conserve.cl): per tile of CONSERVE_TILE pixels, the gain that gives the
        filtered illumination the light of the unfiltered one (modulate applies it)."""
        src = self._src if self._src is not None else self._ping[0]
        ev = self._kernels["conserve"](
            self.device.queue, (self._ctiles_x, self._ctiles_y), None, self._accum, src, self._geo[self._cur],
            self._len[self._cur], self._albedo[self._cur], self._moments[self._cur], self._conserve[0],
            *self._args2d(), np.float32(self._settings.n_eff_max), np.float32(self._settings.conserve_sigma))
        return self._record("conserve", ev)

    def conserve_gain(self) -> cl.Event:
        """Pass 5c (cl/denoise/conserve_gain.cl): per tile, the gain modulate applies: the tile's own, its
        excess over 1 limited to a few times the robust mean of the 3x3 tiles' (a lone firefly's tile
        gets none)."""
        ev = self._kernels["conserve_gain"](
            self.device.queue, (self._ctiles_x, self._ctiles_y), None, self._conserve[0], self._conserve[1],
            *self._args2d())
        return self._record("conserve_gain", ev)

    def modulate(self, aovs: cl.Buffer) -> cl.Event:
        """Pass 6 (cl/denoise/modulate.cl): the filtered illumination (times the conserve gains) times the
        footprint albedo of :meth:`reproject`, plus the clamp's deficit and the emission history, into ``output``."""
        src = self._src if self._src is not None else self._ping[0]
        ev = self._kernels["modulate"](self.device.queue, self.global_size, self.local, src, self._albedo[self._cur],
                                       self._emis[self._cur], self._tiles[1], self._conserve[1], self._geo[self._cur],
                                       self._len[self._cur], self.output, *self._args2d(), np.int32(1),
                                       np.int32(1 if self._settings.give_back else 0),
                                       np.int32(1 if self._conserving() else 0))
        return self._record("modulate", ev)

    def run(self, color: cl.Buffer, aovs: cl.Buffer) -> cl.Buffer:
        """Denoise one frame: ``color`` interleaved RGB float32 (3 per pixel), ``aovs`` the planar G-buffer
        (cl/film/aovs.h). Returns ``output`` (interleaved RGB float32), overwritten by the next frame."""
        if self._settings != self._applied:  # changed in place: check and rebuild before any launch
            self.settings = self._settings
        size = f"{self.width}x{self.height}"
        check_buffer(color, 12 * self.pixels, f"the colour buffer of a {size} frame", self.device)
        check_buffer(aovs, 4 * AOV_COUNT * self.pixels, f"the AOV buffer of a {size} frame", self.device)
        self._cur = self._prev
        self.demodulate(color, aovs)
        self.count_dropped()
        self.reproject(aovs)
        self.light_change()
        self.light_age()
        self.clip_history()
        self.antilag()
        if self._settings.give_back:
            self.deficit(aovs)
            self.deficit_gain()
        self.variance()
        for i in range(self._settings.iterations):
            self.atrous(i)
        if self._conserving():
            self.conserve(aovs)
            self.conserve_gain()
        self.modulate(aovs)
        self.frames += 1
        return self.output

    def image(self) -> np.ndarray:
        """The last output as (H, W, 3) float32."""
        out = np.empty((self.height, self.width, 3), np.float32)
        cl.enqueue_copy(self.device.queue, out, self.output)
        return out

    def pass_times(self) -> dict[str, float]:
        """Mean milliseconds a frame spends in each pass so far (atrous: all its iterations together)."""
        frames = max(len(self.profile.events.get("modulate", [])), 1)
        return {row["kernel"]: float(row["total_ms"]) / frames for row in self.profile.table()}
