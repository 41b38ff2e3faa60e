"""The megakernel integrator: one work-item runs one whole path (``cl/integrators/megakernel.cl``).

The baseline against which the wavefront integrator is measured; it runs the
same estimator (``cl/integrators/path.h``) on the same random numbers.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from pyclpt.buffers.scene import SceneBuffers
from pyclpt.device.context import Device
from pyclpt.device.profile import KernelProfile
from pyclpt.device.program import build_program, register_cap_options
from pyclpt.film.film import Film

MEGAKERNEL_LAUNCH = 1 << 20  # default wave_size: paths (film slots) per launch


class Megakernel:
    name = "megakernel"

    def __init__(self, device: Device, scene: SceneBuffers, film: Film, max_depth: int,
                 wave_size: int = MEGAKERNEL_LAUNCH, local_size: int = 64) -> None:
        self.device, self.scene, self.film = device, scene, film
        self.max_depth = max_depth
        self.wave_size = wave_size
        self.local_size = local_size
        program = build_program(device, ["integrators/megakernel.cl"], defines={**scene.defines, **film.defines},
                                options=register_cap_options(device, "megakernel"))
        self.kernel = cl.Kernel(program, "megakernel")
        self.profile = KernelProfile()

    def warm_up(self) -> None:
        """One empty launch, so that the driver's lazy compilation counts as compile time."""
        args = self.scene.args(*self.film.view)
        self.kernel(self.device.queue, (self.local_size,), (self.local_size,), *args, self.film.frame,
                    self.film.drop_marks, np.uint32(0), np.uint32(0), np.int32(0), np.int32(0),
                    np.int32(self.max_depth), *self.film.aov_args())
        self.device.queue.finish()

    def render_frame(self, seed: int, sample: int) -> None:
        """Render sample ``sample`` of every pixel into the film's first frame."""
        self.render_frames(seed, sample, 1)

    def render_frames(self, seed: int, first_sample: int, frames: int) -> None:
        """Render samples ``first_sample .. first_sample + frames - 1`` of every pixel into the film's
        frames 0 .. frames - 1 (film slot f: pixel f % pixels, sample first_sample + f / pixels),
        ``wave_size`` paths per launch."""
        if not 1 <= frames <= self.film.batch:
            raise ValueError(f"frames must be 1..{self.film.batch} (the film's batch), got {frames}")
        args = self.scene.args(*self.film.view)
        total = self.film.pixels * frames
        for offset in range(0, total, self.wave_size):
            count = min(self.wave_size, total - offset)
            # fixed work-group size: PoCL compiles once per size; extra work-items return at once
            g = -(-count // self.local_size) * self.local_size
            ev = self.kernel(self.device.queue, (g,), (self.local_size,), *args, self.film.frame, self.film.drop_marks,
                             np.uint32(seed), np.uint32(first_sample), np.int32(offset), np.int32(count),
                             np.int32(self.max_depth), *self.film.aov_args())
            self.profile.record("megakernel", ev)
        self.film.count_dropped(frames)
