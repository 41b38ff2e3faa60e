"""The seed's denoiser (``cl/denoise/blend.cl``): output = 0.7 x previous output + 0.3 x frame, with no
reprojection; the first frame after a reset is the frame itself. The seed, a note on a Vulkan/NRD
integration, shipped only this blend; it is kept as the baseline SVGF is measured against (it
ghosts under any motion and never converges further than a 0.3-weight moving average)."""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from pyclpt.common.checks import check_float, check_int
from pyclpt.denoise.svgf import BUILD_OPTIONS, COUNT_CHUNK, PROFILE_LIMIT, check_buffer
from pyclpt.device.context import Device, alloc, fill_buffer, get_device, take_count
from pyclpt.device.profile import KernelProfile
from pyclpt.device.program import build_program

#: The seed's weight of the previous output.
HISTORY_WEIGHT = 0.7


class Blend:
    """The fixed exponential blend of frames of ``width`` x ``height`` on one device."""

    def __init__(self, device: Device | str | None, width: int, height: int,
                 history_weight: float = HISTORY_WEIGHT) -> None:
        self.width = check_int(width, "denoiser width", lo=1, hi=65536)
        self.height = check_int(height, "denoiser height", lo=1, hi=65536)
        self.history_weight = check_float(history_weight, "history_weight", lo=0.0, hi=1.0)
        self.device = get_device(device)
        self.pixels = self.width * self.height
        self.profile = KernelProfile()
        self.output = alloc(self.device, 12 * self.pixels, f"blended image {self.width}x{self.height}")
        self._marks = alloc(self.device, self.pixels, "blend non-finite marks")
        self._dropped = alloc(self.device, 4, "blend non-finite counter")
        self._dropped_total = 0
        self._kernel = cl.Kernel(build_program(self.device, ["denoise/blend.cl"], options=BUILD_OPTIONS), "blend")
        self._count = cl.Kernel(build_program(self.device, ["film/count_dropped.cl"],
                                              defines={"COUNT_CHUNK": COUNT_CHUNK}), "count_dropped")
        fill_buffer(self.device.queue, self._dropped, np.int32(0), 0, 4)
        self.frames = 0

    def reset(self) -> None:
        """The next frame starts over (it is its own output)."""
        self.frames = 0

    def _record(self, name: str, event: cl.Event) -> cl.Event:
        if len(self.profile.sequence) >= PROFILE_LIMIT:
            self.profile.clear()
        self.profile.record(name, event)
        return event

    def blend(self, color: cl.Buffer) -> cl.Event:
        """The kernel: ``output`` = history_weight x output + (1 - history_weight) x color (color alone
        on the first frame), NaN/inf colours as 0 and marked."""
        ev = self._kernel(self.device.queue, (self.pixels,), None, color, self.output, self._marks,
                          np.int32(self.pixels), np.int32(1), np.int32(self.frames == 0),
                          np.float32(self.history_weight))
        return self._record("blend", ev)

    def count_dropped(self) -> cl.Event:
        chunks = -(-self.pixels // COUNT_CHUNK)
        ev = self._count(self.device.queue, (chunks,), None, self._marks, np.int32(self.pixels), self._dropped)
        return self._record("count_dropped", ev)

    def run(self, color: cl.Buffer, aovs: cl.Buffer | None = None) -> cl.Buffer:
        """Blend one frame (interleaved RGB float32); ``aovs`` is not used. Returns ``output``."""
        check_buffer(color, 12 * self.pixels, f"the colour buffer of a {self.width}x{self.height} frame", self.device)
        self.blend(color)
        self.count_dropped()
        self.frames += 1
        return self.output

    @property
    def dropped(self) -> int:
        """Pixels whose colour had a NaN/inf (replaced by 0) since the blend was made."""
        self._dropped_total += take_count(self.device, self._dropped)
        return self._dropped_total

    def history_length(self) -> np.ndarray:
        """Frames blended since the last reset, for every pixel, (H, W) int32."""
        return np.full((self.height, self.width), self.frames, np.int32)

    def image(self) -> np.ndarray:
        out = np.empty((self.height, self.width, 3), np.float32)
        cl.enqueue_copy(self.device.queue, out, self.output)
        return out
