"""The film: one frame buffer that an integrator fills with one sample per
pixel, summed on the device into the image (``cl/accumulate.cl``).

Frames are added in sample order, so the sum does not depend on the order in
which paths finished. NaN/inf samples never reach the frame: the kernels drop
them and count them in ``dropped``.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from .device import Device, alloc
from .program import build_program


class Film:
    def __init__(self, device: Device, width: int, height: int) -> None:
        self.device = device
        self.width, self.height = width, height
        self.pixels = width * height
        n = self.pixels * 3
        self.frame = alloc(device, 4 * n, f"frame buffer {width}x{height}")
        self.sum = alloc(device, 4 * n, f"film {width}x{height}")
        self.dropped = alloc(device, 4, "dropped-sample counter")
        self._accumulate = cl.Kernel(build_program(device, ["accumulate.cl"]), "accumulate")
        self.frames = 0
        self.clear()

    def clear(self) -> None:
        q = self.device.queue
        cl.enqueue_fill_buffer(q, self.sum, np.float32(0), 0, 4 * self.pixels * 3)
        cl.enqueue_fill_buffer(q, self.frame, np.float32(0), 0, 4 * self.pixels * 3)
        cl.enqueue_fill_buffer(q, self.dropped, np.int32(0), 0, 4)
        self.frames = 0

    def add_frame(self) -> cl.Event:
        n = self.pixels * 3
        self.frames += 1
        g = -(-n // 64) * 64
        return self._accumulate(self.device.queue, (g,), (64,), self.sum, self.frame, np.int32(n))

    def warm_up(self) -> None:
        self._accumulate(self.device.queue, (64,), (64,), self.sum, self.frame, np.int32(0))
        self.device.queue.finish()

    def read_frame(self) -> np.ndarray:
        out = np.empty((self.height, self.width, 3), np.float32)
        cl.enqueue_copy(self.device.queue, out, self.frame)
        return out

    def image(self) -> np.ndarray:
        """The average of the frames added so far, (H, W, 3) float32."""
        out = np.empty((self.height, self.width, 3), np.float32)
        cl.enqueue_copy(self.device.queue, out, self.sum)
        if self.frames:
            out /= np.float32(self.frames)
        return out

    def dropped_samples(self) -> int:
        out = np.zeros(1, np.int32)
        cl.enqueue_copy(self.device.queue, out, self.dropped)
        return int(out[0])
