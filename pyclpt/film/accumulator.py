"""The accumulator: frames averaged on the device (``cl/film/accumulate.cl``, ``cl/film/accumulate.h``).

A path tracer renders one sample of every pixel per frame; the accumulator keeps a running
sum per pixel and channel on the device and gives back the average. Falcor's AccumulatePass,
in OpenCL:

- ``precision``: ``single`` (float sum), ``compensated`` (Kahan: float sum plus a float
  correction, its own program built without any fast/unsafe math option), ``double`` (the sum
  in double, stored as two uint words per channel; on a device without ``cl_khr_fp64`` an
  emulated double-float sum, a pair of floats hi + lo, takes its place, also forced with
  ``force_emulated_double=True`` or ``PYCLPT_EMULATE_FP64=1``).
- ``max_frame_count`` (0 = unlimited) and ``overflow``: once that many frames are summed,
  ``stop`` keeps the image (later frames are ignored and counted), ``reset`` starts over,
  ``ema`` continues as an exponential moving average with weight 1 / min(n, max).
- ``input_type``: ``float``, ``uint`` or ``int`` frames of ``channels`` (1..4) values per pixel
  (3: the integrators' RGB; 4: RGBA).
- ``enabled=False``: no accumulation, the image is the last frame.

HDR guard: a pixel sample with a NaN or infinite value is added as zero (so it never corrupts
the sum, and an image is the same whether the integrator or the accumulator dropped the
sample) and counted in ``skipped_samples``; a pixel sample whose sum would overflow float
(in ``single`` or ``compensated``) is not added, counted in ``overflowed_samples`` and logged.

Frames are added in the order given: :meth:`add` (one frame) and :meth:`add_batch` (many
frames stacked in one buffer, one launch) run the same kernel, so they give identical sums.
"""
from __future__ import annotations

import logging
from typing import Any

import numpy as np
import pyopencl as cl

from pyclpt.common import env
from pyclpt.common.checks import check_bool, check_choice, check_int
from pyclpt.device.context import Device, alloc, check_alloc, fill_buffer, get_device
from pyclpt.device.program import build_program

log = logging.getLogger("pyclpt.film.accumulator")

PRECISIONS = ("single", "compensated", "double")
OVERFLOW_MODES = ("stop", "reset", "ema")
INPUT_TYPES = {"float": np.dtype(np.float32), "uint": np.dtype(np.uint32), "int": np.dtype(np.int32)}
# The implementations of the sums, as numbered in cl/film/accumulate.h (ACC_PRECISION).
IMPLEMENTATIONS = {"single": 0, "compensated": 1, "double": 2, "double-float": 3}
_INPUT_CODES = {"float": 0, "uint": 1, "int": 2}
# Options that let a compiler reassociate or drop the Kahan correction; never used for it.
UNSAFE_MATH_OPTIONS = ("-cl-fast-relaxed-math", "-cl-unsafe-math-optimizations", "-cl-finite-math-only",
                       "-cl-mad-enable", "-cl-no-signed-zeros")
EMULATE_FP64_ENV = "PYCLPT_EMULATE_FP64"
# Work-group shape: Falcor's 16x16 tiles on GPUs; on a CPU driver (PoCL) a row of 256 pixels,
# on which 16x16 took 1.5x (single) to 1.7x (double) the time at 1920x1080
# (bench/studies/accumulation.py; docs/accumulation.md).
GPU_LOCAL_SIZE = (16, 16)
CPU_LOCAL_SIZE = (256, 1)


def default_local_size(device: Device) -> tuple[int, int]:
    """The work-group shape the accumulator uses on ``device`` unless told otherwise."""
    limit = int(device.device.max_work_group_size)
    if device.device.type & cl.device_type.CPU:
        return (min(CPU_LOCAL_SIZE[0], limit), 1)
    side = GPU_LOCAL_SIZE[0]
    while side * side > limit:
        side //= 2
    return (side, side)

_COUNTER_LIMIT = 2**32 - 1
# The kernels' `opaque` argument: always 0; the Kahan step XORs its sum with it, so that no compiler
# can prove the correction term is zero (cl/film/accumulate.h, KAHAN_GUARD).
_OPAQUE_ZERO = np.uint32(0)


class AccumulatorError(ValueError):
    """An accumulator option, or a combination of options, that is refused (the message says why)."""


def check_options(*, precision: str = "single", overflow: str = "stop", max_frame_count: int = 0,
                  input_type: str = "float", channels: int = 3, enabled: bool = True) -> dict[str, Any]:
    """The normalised options, or AccumulatorError naming the bad value and why it is refused."""
    check_choice(precision, "accumulation precision", PRECISIONS, error=AccumulatorError)
    check_choice(overflow, "overflow mode", OVERFLOW_MODES, error=AccumulatorError)
    check_choice(input_type, "input type", INPUT_TYPES, error=AccumulatorError)
    channels = check_int(channels, "channels", lo=1, hi=4, error=AccumulatorError)
    max_frame_count = check_int(max_frame_count, "max_frame_count", lo=0, hi=_COUNTER_LIMIT,
                                error=AccumulatorError, note=" (0 = unlimited)")
    enabled = check_bool(enabled, "enabled")
    if overflow != "stop" and max_frame_count == 0:
        raise AccumulatorError(
            f"overflow={overflow!r} acts when max_frame_count frames have been accumulated, but "
            f"max_frame_count=0 means unlimited, so it would never act: set max_frame_count > 0 "
            f"or leave overflow='stop'")
    if not enabled and max_frame_count:
        raise AccumulatorError(
            f"max_frame_count={max_frame_count} with enabled=False: a disabled accumulator passes each "
            f"frame through, there is no count to limit")
    return {"precision": precision, "overflow": overflow, "max_frame_count": int(max_frame_count),
            "input_type": input_type, "channels": int(channels), "enabled": bool(enabled)}


class Accumulator:
    """A running per-pixel sum of frames on one device, and its average."""

    def __init__(self, device: Device | str | None, width: int, height: int, *, channels: int = 3,
                 precision: str = "single", input_type: str = "float", max_frame_count: int = 0,
                 overflow: str = "stop", enabled: bool = True, force_emulated_double: bool | None = None,
                 local_size: tuple[int, int] | None = None) -> None:
        width = check_int(width, "accumulator width", lo=1, hi=65536, error=AccumulatorError)
        height = check_int(height, "accumulator height", lo=1, hi=65536, error=AccumulatorError)
        if local_size is not None and (not isinstance(local_size, (tuple, list)) or len(local_size) != 2):
            raise TypeError(f"local_size must be a pair of integers (x, y) or None, got {local_size!r}")
        force_emulated_double = (None if force_emulated_double is None
                                 else check_bool(force_emulated_double, "force_emulated_double"))
        self.device = get_device(device)
        lx, ly = (check_int(v, "local_size", lo=0) for v in (local_size or default_local_size(self.device)))
        if lx < 1 or ly < 1 or lx * ly > self.device.device.max_work_group_size:
            raise AccumulatorError(f"work-group size {lx}x{ly} is not possible on {self.device.name} "
                                   f"(at most {self.device.device.max_work_group_size} work-items)")
        self.width, self.height = int(width), int(height)
        self.pixels = self.width * self.height
        self.local_size = (lx, ly)
        self.force_emulated_double = (env.flag(EMULATE_FP64_ENV) if force_emulated_double is None
                                      else bool(force_emulated_double))
        self._opts = check_options(precision=precision, overflow=overflow, max_frame_count=max_frame_count,
                                   input_type=input_type, channels=channels, enabled=enabled)
        self.counters = alloc(self.device, 8, "accumulator counters")
        fill_buffer(self.device.queue, self.counters, np.uint32(0), 0, 8)
        self._staging: cl.Buffer | None = None
        self._staging_bytes = 0
        self._state: cl.Buffer | None = None
        self._output: cl.Buffer | None = None
        self._layout: tuple | None = None
        self.skipped_total = 0
        self.overflowed_total = 0
        self.ignored_frames = 0
        self._pending = 0  # upper bound of the device counters' growth since they were last read
        self._build()
        self.reset()

    # -- options -------------------------------------------------------------------------------
    @property
    def options(self) -> dict[str, Any]:
        """The current options (a copy); change them with :meth:`configure`."""
        return dict(self._opts)

    precision = property(lambda self: self._opts["precision"],
                         doc="single, compensated or double (how it is kept: :attr:`implementation`).")
    overflow = property(lambda self: self._opts["overflow"],
                        doc="What happens once ``max_frame_count`` frames are summed (the overflow mode).")
    max_frame_count = property(lambda self: self._opts["max_frame_count"],
                               doc="Frames summed before the overflow mode acts (0: unlimited).")
    input_type = property(lambda self: self._opts["input_type"],
                          doc="The frames' value type: ``float``, ``uint`` or ``int``.")
    channels = property(lambda self: self._opts["channels"], doc="Values per pixel (1 to 4).")
    enabled = property(lambda self: self._opts["enabled"],
                       doc="False: no accumulation, the image is the last frame.")

    def configure(self, **changes: Any) -> None:
        """Change options (validated together, as the constructor does); the accumulation restarts."""
        unknown = set(changes) - set(self._opts)
        if unknown:
            raise AccumulatorError(f"unknown accumulator option(s) {', '.join(sorted(unknown))} "
                                   f"(options: {', '.join(self._opts)})")
        self._opts = check_options(**{**self._opts, **changes})
        self._build()
        self.reset()

    @property
    def implementation(self) -> str:
        """How the sum is kept: single, compensated, double (native fp64) or double-float (emulated)."""
        p = self.precision
        if p == "double" and (self.force_emulated_double or not self.device.has_fp64):
            return "double-float"
        return p

    @property
    def emulated_double(self) -> bool:
        """Whether double precision is emulated with float pairs (no fp64 on the device)."""
        return self.implementation == "double-float"

    @property
    def build_options(self) -> list[str]:
        """The options the accumulation program was built with (never a fast/unsafe math one)."""
        return self.program.get_build_info(self.device.device, cl.program_build_info.OPTIONS).split()

    def _build(self) -> None:
        impl = self.implementation
        if self.precision == "double" and impl == "double-float" and not self.force_emulated_double:
            log.info("%s has no cl_khr_fp64: precision 'double' uses the emulated double-float sum",
                     self.device.name)
        defines = {"ACC_PRECISION": IMPLEMENTATIONS[impl], "ACC_INPUT": _INPUT_CODES[self.input_type],
                   "ACC_CHANNELS": self.channels, "ACC_LOCAL_X": self.local_size[0],
                   "ACC_LOCAL_Y": self.local_size[1]}
        # No program of the accumulator uses fast or unsafe math; compensated and double-float
        # depend on it (their error terms would be folded to zero).
        self.program = build_program(self.device, ["film/accumulate.cl"], defines=defines, options=(),
                                     name=f"accumulate.cl[{impl}]")
        bad = [o for o in self.build_options if o in UNSAFE_MATH_OPTIONS]
        if bad and impl in ("compensated", "double-float"):
            raise AccumulatorError(f"the {impl} accumulation program was built with {' '.join(bad)}, "
                                   f"which lets the compiler cancel its error terms")
        self._batch_kernel = cl.Kernel(self.program, "accumulate_batch")
        self._frame_kernel = cl.Kernel(self.program, "accumulate_frame")
        self._resolve = cl.Kernel(self.program, "resolve")
        value_bytes = 4 if impl == "single" else 8
        layout = (impl, self.channels)
        if layout != self._layout:
            n = self.pixels * self.channels
            self._state = alloc(self.device, value_bytes * n, f"accumulation sum {self.width}x{self.height} ({impl})")
            self._output = alloc(self.device, 4 * n, f"accumulated image {self.width}x{self.height}")
            self._layout = layout
        self.state_bytes = value_bytes * self.pixels * self.channels

    # -- accumulation ----------------------------------------------------------------------------
    def reset(self) -> None:
        """Start over: the sum and the frame count go to zero (the counters of skipped, overflowed
        and ignored samples are kept; they count over the accumulator's life)."""
        q = self.device.queue
        fill_buffer(q, self._state, np.uint32(0), 0, self.state_bytes)
        self.frame_count = 0

    @property
    def frame_stride(self) -> int:
        """Values per frame (width * height * channels)."""
        return self.pixels * self.channels

    @property
    def stopped(self) -> bool:
        """True once overflow='stop' has reached max_frame_count: further frames are ignored."""
        m = self.max_frame_count
        return self.overflow == "stop" and m > 0 and self.frame_count >= m

    @property
    def divisor(self) -> int:
        """What the sum is divided by: the frame count, at most max_frame_count with EMA."""
        n = self.frame_count
        if self.overflow == "ema" and self.max_frame_count:
            n = min(n, self.max_frame_count)
        return n

    def add(self, frame: cl.Buffer | np.ndarray) -> cl.Event | None:
        """Add one frame (a device buffer or an (H, W, C) array of the input type).

        Returns the kernel's event, or None when the frame was ignored (overflow='stop')."""
        return self.add_batch(frame, 1)

    def add_batch(self, frames: cl.Buffer | np.ndarray, count: int | None = None, *,
                  first_frame: int = 0) -> cl.Event | None:
        """Add ``count`` frames stacked in ``frames`` (frame k at value offset k * frame_stride),
        in order, in one launch per stretch between overflow events.

        ``frames``: a device buffer of the input type, or a (count, H, W, C) array.
        ``first_frame``: skip that many frames at the start of a device buffer.
        Gives the same sum as ``count`` calls of :meth:`add`."""
        buf, count = self._frames_buffer(frames, count, first_frame)
        if count == 0:
            return None
        first = first_frame * self.frame_stride
        if not self.enabled:  # pass-through: the image is the last frame
            self.reset()
            return self._launch(buf, first + (count - 1) * self.frame_stride, 1, 0)
        event = None
        m, mode = self.max_frame_count, self.overflow
        while count:
            if m and self.frame_count >= m:
                if mode == "stop":
                    self.ignored_frames += count
                    break
                if mode == "reset":
                    self.reset()
            chunk = count if (not m or mode == "ema") else min(count, m - self.frame_count)
            event = self._launch(buf, first, chunk, m if mode == "ema" else 0)
            first += chunk * self.frame_stride
            count -= chunk
        return event

    def _launch(self, buf: cl.Buffer, first: int, count: int, ema_max: int) -> cl.Event:
        if self._pending + self.pixels * count > _COUNTER_LIMIT:
            self._drain_counters()
        self._pending += self.pixels * count
        q, gsize, lsize = self.device.queue, self._global_size(), self.local_size
        size = (np.int32(self.width), np.int32(self.height))
        if count == 1:
            ev = self._frame_kernel(q, gsize, lsize, self._state, buf, *size, np.uint64(first),
                                    np.uint32(self.frame_count), np.uint32(ema_max), _OPAQUE_ZERO, self.counters)
        else:
            ev = self._batch_kernel(q, gsize, lsize, self._state, buf, *size, np.uint64(first),
                                    np.uint64(self.frame_stride), np.int32(count), np.uint32(self.frame_count),
                                    np.uint32(ema_max), _OPAQUE_ZERO, self.counters)
        self.frame_count += count
        return ev

    def _frames_buffer(self, frames, count: int | None, first_frame: int) -> tuple[cl.Buffer, int]:
        dtype = INPUT_TYPES[self.input_type]
        if isinstance(frames, cl.Buffer):
            if count is None:
                count = frames.size // (dtype.itemsize * self.frame_stride) - first_frame
            count = int(count)
            if count < 0 or first_frame < 0:
                raise AccumulatorError(f"frame count and first_frame must be >= 0, got {count}, {first_frame}")
            need = (first_frame + count) * self.frame_stride * dtype.itemsize
            if frames.size < need:
                raise AccumulatorError(
                    f"the frame buffer holds {frames.size} bytes, but {count} frames of {self.width}x{self.height}"
                    f"x{self.channels} {self.input_type} values from frame {first_frame} need {need}")
            return frames, count
        arr = np.asarray(frames)
        if arr.dtype.kind not in {"float": "f", "uint": "u", "int": "iu"}[self.input_type]:
            raise AccumulatorError(f"frames of dtype {arr.dtype} do not match input_type={self.input_type!r} "
                                   f"({dtype}); convert them or make the accumulator with another input_type")
        if arr.dtype.kind in "iu" and arr.size and not np.can_cast(arr.dtype, dtype, "safe"):
            lo, hi = np.iinfo(dtype).min, np.iinfo(dtype).max
            if arr.min() < lo or arr.max() > hi:
                raise AccumulatorError(f"frame values {arr.min()}..{arr.max()} are outside the range of "
                                       f"input_type={self.input_type!r} ({dtype})")
        frame_shape = (self.height, self.width, self.channels)
        if first_frame:
            raise AccumulatorError("first_frame is for device buffers; slice the array instead")
        if count is None:
            count = 1 if arr.shape == frame_shape else (arr.shape[0] if arr.ndim == 4 else -1)
        count = int(count)
        fits = arr.shape == (count,) + frame_shape or (count == 1 and arr.shape == frame_shape) or (
            arr.ndim == 1 and arr.size == count * self.frame_stride)
        if count < 0 or not fits:
            raise AccumulatorError(f"frames of shape {arr.shape} do not fit the accumulator: expected "
                                   f"{frame_shape} for one frame or (count, {', '.join(map(str, frame_shape))})")
        data = np.ascontiguousarray(arr, dtype=dtype)
        if data.nbytes > self._staging_bytes:
            check_alloc(self.device, data.nbytes, "accumulator upload buffer")
            self._staging = cl.Buffer(self.device.context, cl.mem_flags.READ_ONLY, size=max(data.nbytes, 4))
            self._staging_bytes = data.nbytes
        if data.nbytes:
            cl.enqueue_copy(self.device.queue, self._staging, data)
        return self._staging, int(count)

    # -- results ---------------------------------------------------------------------------------
    def _global_size(self) -> tuple[int, int]:
        lx, ly = self.local_size
        return (-(-self.width // lx) * lx, -(-self.height // ly) * ly)

    def resolve(self) -> cl.Buffer:
        """The average as a device buffer of float32 (H, W, C), for display or later kernels."""
        self._resolve(self.device.queue, self._global_size(), self.local_size, self._state, self._output,
                      np.int32(self.width), np.int32(self.height), np.uint32(max(self.divisor, 1)))
        return self._output

    def image(self, dtype=np.float32) -> np.ndarray:
        """The average of the frames, (H, W, C): float32 computed on the device (the default), or
        float64 computed on the host from the sum as kept (the full precision of ``double``)."""
        shape = (self.height, self.width, self.channels)
        if np.dtype(dtype) == np.float64:
            return self.sum() / max(self.divisor, 1)
        if np.dtype(dtype) != np.float32:
            raise AccumulatorError(f"image dtype must be float32 or float64, got {np.dtype(dtype)}")
        out = np.empty(shape, np.float32)
        cl.enqueue_copy(self.device.queue, out, self.resolve())
        self._drain_counters()
        return out

    def sum(self) -> np.ndarray:
        """The running sum as kept on the device, as float64 (H, W, C). With EMA past the limit this is
        max_frame_count times the moving average."""
        impl = self.implementation
        n = self.pixels * self.channels
        raw = np.empty(n * (1 if impl == "single" else 2), np.uint32)
        cl.enqueue_copy(self.device.queue, raw, self._state)
        self._drain_counters()
        if impl == "single":
            total = raw.view(np.float32).astype(np.float64)
        elif impl == "double":
            total = raw.view(np.float64).copy()  # as_uint2 keeps the double's bytes in memory order
        else:
            pair = raw.view(np.float32).reshape(n, 2).astype(np.float64)
            # compensated: s - c; double-float: hi + lo
            total = pair[:, 0] - pair[:, 1] if impl == "compensated" else pair[:, 0] + pair[:, 1]
        return total.reshape(self.height, self.width, self.channels)

    def _drain_counters(self) -> None:
        if self._pending == 0:
            return
        c = np.zeros(2, np.uint32)
        cl.enqueue_copy(self.device.queue, c, self.counters)
        fill_buffer(self.device.queue, self.counters, np.uint32(0), 0, 8)
        self._pending = 0
        self.skipped_total += int(c[0])
        if c[1]:
            self.overflowed_total += int(c[1])
            log.warning("accumulation in %s precision: %d pixel samples were not added because the sum would "
                        "overflow float (%d so far); use precision='double' or overflow='ema'",
                        self.implementation, int(c[1]), self.overflowed_total)

    @property
    def skipped_samples(self) -> int:
        """Pixel samples with a NaN or infinite value, added as zero."""
        self._drain_counters()
        return self.skipped_total

    @property
    def overflowed_samples(self) -> int:
        """Pixel samples not added because the float sum would have overflowed."""
        self._drain_counters()
        return self.overflowed_total

    def stats(self) -> dict[str, Any]:
        """The options, the implementation, the frame count, the counters and the state's size."""
        return {**self.options, "implementation": self.implementation, "frame_count": self.frame_count,
                "skipped_samples": self.skipped_samples, "overflowed_samples": self.overflowed_samples,
                "ignored_frames": self.ignored_frames, "state_bytes": self.state_bytes,
                "local_size": list(self.local_size)}

    def warm_up(self) -> None:
        """Launch both kernels once on nothing, so that the driver's lazy compilation counts as
        compile time; the sum is untouched."""
        q, lsize, none = self.device.queue, self.local_size, (np.int32(0), np.int32(0))
        self._batch_kernel(q, lsize, lsize, self._state, self._output, *none, np.uint64(0), np.uint64(0),
                           np.int32(0), np.uint32(0), np.uint32(0), _OPAQUE_ZERO, self.counters)
        self._frame_kernel(q, lsize, lsize, self._state, self._output, *none, np.uint64(0), np.uint32(0),
                           np.uint32(0), _OPAQUE_ZERO, self.counters)
        self._resolve(q, lsize, lsize, self._state, self._output, *none, np.uint32(1))
        self.device.queue.finish()
