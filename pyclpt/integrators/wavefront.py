"""The wavefront (streaming) integrator: the path loop split into seven small
kernels that pass paths to each other through compacted queues (``cl/*.cl``,
one file per stage; see docs/wavefront.md).

Per wave (a chunk of at most ``wave_size`` film slots of a batch of frames: slot f is pixel
f % pixels of sample first + f / pixels, so small images fill a wave with several samples):

    path_init -> [ intersect, C -> miss -> process_hit, C -> shadow_test, C
                   -> light_contribution -> sample_bsdf, C ] per bounce -> finish_paths

where C is the order-preserving compaction (``compact_count``, ``compact_scatter``)
that builds the next queue(s) from the flags the stage before wrote, so every queue
lists path slots in ascending order and no stage needs an atomic. Once at most
``tail_paths`` paths are left (after the first bounce), ``finish_paths`` runs each of
them to its end in one work-item, as the megakernel does: the same image, without a
bounce's nine launches for a few paths.

Each method of :class:`Wavefront` named after a stage launches that stage's
kernel. Paths in flight never exceed ``wave_size`` whatever the image size or
spp, and the state of each path is stored in the SoA or AoS layout generated
from :mod:`pyclpt.integrators.path_state`.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from pyclpt.buffers.scene import SCENE_DEFINES, SceneBuffers
from pyclpt.device.context import Device, alloc, fill_buffer
from pyclpt.device.profile import KernelProfile
from pyclpt.device.program import build_program, register_cap_options
from pyclpt.film.film import FILM_DEFINES, Film
from pyclpt.integrators.path_state import PathStorage, bytes_per_path, opencl_header

STAGES = ("path_init", "intersect", "miss", "process_hit", "shadow_test", "light_contribution", "sample_bsdf",
          "compact_count", "compact_scatter", "finish_paths")
# counter order, as Q_* in cl/integrators/wavefront/wavefront.h
QUEUES = ("rays", "hits", "misses", "shadow_rays", "unoccluded")
Q_COUNT = len(QUEUES)
Q_RAY, Q_HIT, Q_MISS, Q_SHADOW, Q_LIGHT = range(Q_COUNT)
COMPACT_BLOCK = 1024  # queue entries per work-item of the compaction (-DCOMPACT_BLOCK for compact_*.cl)
#: GPU class: lanes of the work-group that compacts one block (-DCOMPACT_GROUP; cl/integrators/wavefront/
#: compact.h), instead of one work-item looping over its COMPACT_BLOCK entries as CPUs prefer.
COMPACT_GROUP = 256
# six int queues and one flag byte per path
QUEUE_BYTES_PER_PATH = 6 * 4 + 1
SCHEDULES = ("readback", "pipelined", "capacity")
DEFAULT_WAVE_SIZE = 1 << 18
#: GPUs: a wave holds a whole 1920x1080 frame. Every wave pays each stage's launch (about 15-100 us of host
#: time on NVIDIA's OpenCL, docs/gpu.md) and its tail's latency, and a GPU needs ~10^5 paths in flight to
#: fill, so waves as large as memory allows; CPUs keep 2^18 (the state of a wave stays in their caches).
GPU_WAVE_SIZE = 1 << 21
GPU_WAVE_MEMORY_FRACTION = 8  # at most an eighth of the device's memory for the path state and queues
CAPACITY_CHECK = 4
TAIL_FRACTION = 4  # default tail_paths: a quarter of the wave (docs/wavefront.md, "The tail")


_KNOWN_DEFINES = frozenset(SCENE_DEFINES + FILM_DEFINES)
_TRAVERSAL = frozenset({"BVH_WIDTH", "BVH_LEAF_PACKETS", "BVH_STACK_DISTANCES", "SCENE_HAS_MASKS",
                        "SCENE_HAS_INSTANCES", "DEVICE_CLASS_GPU", "FILM_CROP"})
_SHADING = frozenset({"SCENE_MATERIALS", "SCENE_HAS_TEXTURES", "SCENE_HAS_BUMPMAPS", "SCENE_HAS_INSTANCES",
                      "SCENE_HAS_ANISOTROPY", "SCENE_HAS_BACK_MATERIALS", "AOVS", "FILM_CROP", "DEVICE_CLASS_GPU"})
#: Of the scene's and the film's -D specialisations (SCENE_DEFINES, FILM_DEFINES), the ones each stage's code reads.
#: A stage is built with those alone: the others leave its compiled code as it is (tests/test_gpu_isa.py switches them
#: all and compares the front end's optimised code), so scenes and films that differ only there share the stage's
#: program: light_contribution's is one for every scene, path_init's one per camera, filter and crop, intersect's one
#: per BVH layout, mask and instancing. Fewer programs to compile when the scene or the film changes. A define named in
#: neither tuple reaches every stage.
STAGE_DEFINES: dict[str, frozenset[str]] = {
    "path_init": frozenset({"SCENE_CAMERA", "SCENE_FILTER", "FILM_CROP"}),
    "intersect": _TRAVERSAL,
    "miss": frozenset({"SCENE_LIGHTS", "SCENE_CAMERA", "AOVS", "DEVICE_CLASS_GPU"}),
    "process_hit": _SHADING | {"SCENE_LIGHTS", "SCENE_HAS_EMITTER_TEXTURES", "SCENE_CAMERA"},
    "shadow_test": _TRAVERSAL | {"SCENE_LIGHTS"},  # an environment's deferred radiance (lights.h, ENV_DEFERRED)
    "light_contribution": frozenset(),
    "sample_bsdf": _SHADING,
    "finish_paths": _KNOWN_DEFINES,  # the whole path loop
}


def stage_defines(stage: str, defines: dict) -> dict:
    """The -D specialisations of ``defines`` (a scene's and a film's) that ``stage`` is built with (STAGE_DEFINES)."""
    return {k: v for k, v in defines.items() if k in STAGE_DEFINES[stage] or k not in _KNOWN_DEFINES}


def expected_rays(last: int, before: int) -> int:
    """The pipelined schedule's guess at a bounce's ray count, for the tail's test: the last bounce's count
    ``last`` times the ratio of the two bounces before (``before``: the count of the bounce before the last);
    0 only when no ray is left."""
    return max(1, last * last // max(1, before)) if last else 0


def default_wave_size(device: Device) -> int:
    """The wave size a renderer uses on ``device`` when none is given: DEFAULT_WAVE_SIZE on a CPU,
    GPU_WAVE_SIZE on other devices unless an eighth of their memory (or their largest buffer, the AoS
    state) holds fewer paths."""
    if device.is_cpu:
        return DEFAULT_WAVE_SIZE
    per_path = bytes_per_path() + QUEUE_BYTES_PER_PATH
    fits = min(device.global_mem // GPU_WAVE_MEMORY_FRACTION // per_path, device.max_alloc // bytes_per_path())
    return int(max(DEFAULT_WAVE_SIZE, min(GPU_WAVE_SIZE, fits)))


class Wavefront:
    name = "wavefront"

    def __init__(self, device: Device, scene: SceneBuffers, film: Film, max_depth: int, *,
                 layout: str = "soa", wave_size: int = DEFAULT_WAVE_SIZE, schedule: str = "readback",
                 local_size: int = 64, tail_paths: int | None = None) -> None:
        if schedule not in SCHEDULES:
            raise ValueError(f"unknown wavefront schedule {schedule!r} ({', '.join(SCHEDULES)})")
        if max_depth < 0:
            raise ValueError("the wavefront needs a finite max_depth (the renderer caps -1)")
        if wave_size < 1:
            raise ValueError(f"wave_size must be positive, got {wave_size}")
        self.device, self.scene, self.film = device, scene, film
        self.max_depth, self.layout, self.schedule = max_depth, layout, schedule
        self.local_size = local_size
        self.capacity = min(wave_size, film.pixels * film.batch)
        # paths left at which finish_paths takes over (the readback and pipelined schedules; 0: never)
        self.tail_paths = self.capacity // TAIL_FRACTION if tail_paths is None else int(tail_paths)
        if self.tail_paths < 0:
            raise ValueError(f"tail_paths must be >= 0, got {tail_paths}")
        self.paths = PathStorage(device, layout, self.capacity)
        nbytes = 4 * self.capacity
        self.ray_queues = [alloc(device, nbytes, "ray queue"), alloc(device, nbytes, "ray queue")]
        self.hit_queue = alloc(device, nbytes, "hit queue")
        self.miss_queue = alloc(device, nbytes, "miss queue")
        self.shadow_queue = alloc(device, nbytes, "shadow queue")
        self.light_queue = alloc(device, nbytes, "light-contribution queue")
        self.flags = alloc(device, self.capacity, "queue flags")
        self.block_counts = alloc(device, 4 * -(-self.capacity // COMPACT_BLOCK), "compaction block counts")
        self.counters = alloc(device, 4 * Q_COUNT * (max_depth + 2), "queue counters")
        # the paths finish_paths ran alive at each later bounce (bounce_stats), read and cleared after each tail
        self.tail_counts = alloc(device, 4 * (max_depth + 2), "tail path counts")
        generated = {"path_state.h": opencl_header(layout)}
        # GPU class (the scene's layout): a work-group per compaction block (COMPACT_GROUP)
        self.compact_group = COMPACT_GROUP if scene.defines.get("DEVICE_CLASS_GPU") else 0
        defines = {**scene.defines, **film.defines}
        # the compaction knows queues only (cl/integrators/wavefront/compact.h): one program for every scene
        compact_defines = {"COMPACT_BLOCK": COMPACT_BLOCK, "COMPACT_GROUP": self.compact_group or None}
        self.kernels = {}
        for s in STAGES:
            compaction = s.startswith("compact_")
            program = build_program(device, [f"integrators/wavefront/{s}.cl"],
                                    generated=None if compaction else generated,
                                    defines=compact_defines if compaction else stage_defines(s, defines),
                                    options=register_cap_options(device, s))
            self.kernels[s] = cl.Kernel(program, s)
        self.profile = KernelProfile()
        self._bounce_totals = np.zeros((max_depth + 2, Q_COUNT), np.int64)
        self._tail_totals = np.zeros(max_depth + 2, np.int64)  # paths finish_paths took at each bounce
        self._tail_alive_totals = np.zeros(max_depth + 2, np.int64)  # ... and ran alive at each later bounce
        self._tail_alive = np.zeros(max_depth + 2, np.int32)
        fill_buffer(device.queue, self.tail_counts, np.int32(0), 0, self._tail_alive.nbytes)
        self._counts = np.zeros((max_depth + 2, Q_COUNT), np.int32)
        # the pipelined schedule: each bounce's ray count, read without blocking, and the reads' events
        self._ray_counts = np.zeros(max_depth + 2, np.int32)
        self._ray_reads: list[cl.Event | None] = []
        self._args_set: dict[str, tuple] = {}  # per stage, the arguments its kernel holds (_set_args)

    @property
    def bytes_per_path(self) -> int:
        """Path state plus one entry in each of the six queues and one flag byte."""
        return bytes_per_path() + QUEUE_BYTES_PER_PATH

    # -- stages: each launches the kernel of the same name --------------------------
    def _launch(self, stage: str, n: int, *args) -> None:
        if n <= 0:
            return
        # A fixed work-group size: PoCL compiles a kernel once per work-group size, and the
        # kernels ignore the work-items past their queue's count.
        g = -(-n // self.local_size) * self.local_size
        self._enqueue(stage, g, self.local_size, args)

    def _enqueue(self, stage: str, global_size: int, local_size: int, args: tuple) -> None:
        kernel = self._set_args(stage, args)
        ev = cl.enqueue_nd_range_kernel(self.device.queue, kernel, (global_size,), (local_size,))
        self.profile.record(stage, ev)

    def _set_args(self, stage: str, args: tuple) -> cl.Kernel:
        """The stage's kernel with ``args`` set, setting only those that differ from its last launch's: a
        stage takes up to ~40 arguments (the scene's buffers) and only the bounce and its seed change, while
        each clSetKernelArg costs ~2 us on NVIDIA's OpenCL (docs/gpu.md, "Host overhead")."""
        kernel = self.kernels[stage]
        held = self._args_set.get(stage)
        if held is None or len(held) != len(args):
            kernel.set_args(*args)
        else:
            for i, (new, old) in enumerate(zip(args, held)):
                if new is old:
                    continue
                if isinstance(new, np.generic) and isinstance(old, np.generic) and new.dtype == old.dtype \
                        and new == old:
                    continue
                kernel.set_arg(i, new)
        self._args_set[stage] = args
        return kernel

    def _common(self, bounce: int) -> tuple:
        return (*self.paths.buffers, self.counters, np.int32(bounce))

    def path_init(self, n: int, seed: int, first_sample: int, offset: int) -> None:
        f = self.film
        self._launch("path_init", n, *self._scene_args, *self._common(0), self.ray_queues[0], f.frame,
                     f.drop_marks, np.uint32(seed), np.uint32(first_sample), np.int32(offset), np.int32(n),
                     np.int32(self.max_depth))

    def intersect(self, n: int, bounce: int, seed: int, first_sample: int) -> None:
        self._launch("intersect", n, *self._scene_args, *self._common(bounce), self.ray_queues[bounce % 2],
                     self.flags, np.uint32(seed), np.uint32(first_sample))

    def miss(self, n: int, bounce: int) -> None:
        self._launch("miss", n, *self._scene_args, *self._common(bounce), self.miss_queue, self.film.frame,
                     self.film.drop_marks, *self.film.aov_args())

    def process_hit(self, n: int, bounce: int, seed: int, first_sample: int) -> None:
        self._launch("process_hit", n, *self._scene_args, *self._common(bounce), self.hit_queue,
                     self.flags, np.uint32(seed), np.uint32(first_sample), np.int32(self.max_depth),
                     *self.film.aov_args())

    def shadow_test(self, n: int, bounce: int, seed: int, first_sample: int) -> None:
        self._launch("shadow_test", n, *self._scene_args, *self._common(bounce), self.shadow_queue,
                     self.flags, np.uint32(seed), np.uint32(first_sample))

    def light_contribution(self, n: int, bounce: int) -> None:
        self._launch("light_contribution", n, *self._common(bounce), self.light_queue)

    def sample_bsdf(self, n: int, bounce: int, seed: int, first_sample: int) -> None:
        self._launch("sample_bsdf", n, *self._scene_args, *self._common(bounce), self.hit_queue,
                     self.flags, self.film.frame, self.film.drop_marks,
                     np.uint32(seed), np.uint32(first_sample), np.int32(self.max_depth))

    def finish_paths(self, n: int, bounce: int, seed: int, first_sample: int) -> None:
        """Run the ``n`` paths of the ray queue of ``bounce`` to their ends, one per work-item."""
        self._launch("finish_paths", n, *self._scene_args, *self._common(bounce), self.ray_queues[bounce % 2],
                     self.film.frame, self.film.drop_marks, np.uint32(seed), np.uint32(first_sample),
                     np.int32(self.max_depth), *self.film.aov_args(), self.tail_counts)

    def _launch_blocks(self, stage: str, n: int, *args) -> None:
        """A compaction stage over the blocks of ``n`` queue entries: a work-item a block, or on the GPU
        class a work-group of COMPACT_GROUP lanes a block."""
        blocks = -(-n // COMPACT_BLOCK)
        if not self.compact_group or blocks <= 0:
            self._launch(stage, blocks, *args)
            return
        g = self.compact_group
        self._enqueue(stage, blocks * g, g, args)

    def compact_count(self, n: int, bounce: int, src_q: int) -> None:
        """Count the flagged entries per block of the queue ``src_q`` (at most ``n`` entries)."""
        self._launch_blocks("compact_count", n, self.counters, np.int32(bounce), np.int32(src_q),
                            self.flags, self.block_counts)

    def compact_scatter(self, n: int, bounce: int, src_q: int, src: cl.Buffer, out: cl.Buffer,
                        out_q: int, out_bounce: int, rest: cl.Buffer | None = None, rest_q: int = -1) -> None:
        """Copy the flagged entries of ``src`` to ``out`` (the others to ``rest``), in order."""
        self._launch_blocks("compact_scatter", n, self.counters, np.int32(bounce), np.int32(src_q),
                            self.flags, self.block_counts, src, out, np.int32(out_bounce), np.int32(out_q),
                            out if rest is None else rest, np.int32(rest_q))

    def compact(self, n: int, bounce: int, src_q: int, src: cl.Buffer, out: cl.Buffer, out_q: int,
                out_bounce: int | None = None, rest: cl.Buffer | None = None, rest_q: int = -1) -> None:
        """The order-preserving compaction after a stage: compact_count, then compact_scatter."""
        self.compact_count(n, bounce, src_q)
        self.compact_scatter(n, bounce, src_q, src, out, out_q, bounce if out_bounce is None else out_bounce,
                             rest, rest_q)

    def bounce(self, rays: int, bounce: int, seed: int, first_sample: int) -> None:
        """The launches of one bounce; ``rays`` bounds every queue of the bounce."""
        self.intersect(rays, bounce, seed, first_sample)
        self.compact(rays, bounce, Q_RAY, self.ray_queues[bounce % 2], self.hit_queue, Q_HIT,
                     rest=self.miss_queue, rest_q=Q_MISS)
        self.miss(rays, bounce)
        self.process_hit(rays, bounce, seed, first_sample)
        self.compact(rays, bounce, Q_HIT, self.hit_queue, self.shadow_queue, Q_SHADOW)
        self.shadow_test(rays, bounce, seed, first_sample)
        self.compact(rays, bounce, Q_SHADOW, self.shadow_queue, self.light_queue, Q_LIGHT)
        self.light_contribution(rays, bounce)
        self.sample_bsdf(rays, bounce, seed, first_sample)
        self.compact(rays, bounce, Q_HIT, self.hit_queue, self.ray_queues[(bounce + 1) % 2], Q_RAY,
                     out_bounce=bounce + 1)

    def warm_up(self) -> None:
        """Launch every stage once with empty queues, so that the driver's lazy compilation
        (PoCL builds a work-group function on first launch) is counted as compile time."""
        self._scene_args = self.scene.args(*self.film.view)
        q = self.device.queue
        fill_buffer(q, self.counters, np.int32(0), 0, self._counts.nbytes)
        self.path_init(1, 0, 0, 0)
        fill_buffer(q, self.counters, np.int32(0), 0, self._counts.nbytes)
        self.bounce(1, 0, 0, 0)
        fill_buffer(q, self.counters, np.int32(0), 0, self._counts.nbytes)
        self.finish_paths(1, 0, 0, 0)  # an empty queue: compiled, nothing run
        fill_buffer(q, self.film.frame, np.float32(0), 0, 4 * 3 * self.film.pixels * self.film.batch)
        q.finish()
        self.profile.clear()

    # -- the host loop -------------------------------------------------------------
    def render_frame(self, seed: int, sample: int) -> None:
        """Render sample ``sample`` of every pixel into the film's first frame, wave by wave."""
        self.render_frames(seed, sample, 1)

    def render_frames(self, seed: int, first_sample: int, frames: int) -> None:
        """Render samples ``first_sample .. first_sample + frames - 1`` of every pixel into the film's
        frames 0 .. frames - 1, wave by wave over the film slots. The stages get the batch's first sample
        and derive each path's own from its film slot."""
        if not 1 <= frames <= self.film.batch:
            raise ValueError(f"frames must be 1..{self.film.batch} (the film's batch), got {frames}")
        self._scene_args = self.scene.args(*self.film.view)
        q = self.device.queue
        total = self.film.pixels * frames
        for offset in range(0, total, self.capacity):
            n = min(self.capacity, total - offset)
            fill_buffer(q, self.counters, np.int32(0), 0, self._counts.nbytes)
            self.path_init(n, seed, first_sample, offset)
            rays = n if self.max_depth != 0 else 0
            self._ray_reads = [None] * (self.max_depth + 2)
            tail_bounce = -1
            for bounce in range(self.max_depth):
                if self.schedule == "capacity":
                    # launch at capacity; kernels read their counts on the device. The host
                    # looks at the ray count only every CAPACITY_CHECK bounces to stop early.
                    rays = n
                    if bounce and bounce % CAPACITY_CHECK == 0 and self._read_count(bounce, 0) == 0:
                        break
                else:
                    # readback: this bounce's ray count; pipelined: a bound (_pipelined_bound)
                    if self.schedule == "readback":
                        rays = expected = self._read_count(bounce, Q_RAY)
                    else:
                        rays, expected = self._pipelined_bound(bounce, n)
                    if rays == 0:
                        break
                    if bounce > 0 and expected <= self.tail_paths:
                        self.finish_paths(rays, bounce, seed, first_sample)
                        tail_bounce = bounce
                        cl.enqueue_copy(q, self._tail_alive, self.tail_counts)
                        fill_buffer(q, self.tail_counts, np.int32(0), 0, self._tail_alive.nbytes)
                        self._tail_alive_totals += self._tail_alive
                        break
                self.bounce(rays, bounce, seed, first_sample)
                if self.schedule == "pipelined":
                    self._start_ray_count(bounce + 1)
            cl.enqueue_copy(q, self._counts, self.counters)
            self._bounce_totals += self._counts
            if tail_bounce >= 0:  # the paths finish_paths took: that bounce's ray count
                self._tail_totals[tail_bounce] += self._counts[tail_bounce, Q_RAY]
        self.film.count_dropped(frames)

    def _read_count(self, bounce: int, queue: int) -> int:
        out = np.zeros(1, np.int32)
        cl.enqueue_copy(self.device.queue, out, self.counters,
                        src_offset=4 * (bounce * Q_COUNT + queue))
        return int(out[0])

    def _pipelined_bound(self, bounce: int, n: int) -> tuple[int, int]:
        """The pipelined schedule's launch size for ``bounce`` and the ray count it expects there (for the tail's
        test): the ray count of the bounce before, an upper bound (queues only shrink) whose read was queued
        ahead of the bounce before's launches, and that count times the ratio of the two bounces before (the
        wave's ``n`` paths at bounces 0 and 1)."""
        if bounce < 2:
            return n, n
        last = self._await_ray_count(bounce - 1)
        before = int(self._ray_counts[bounce - 2]) if bounce > 2 else n
        return last, expected_rays(last, before)

    def _start_ray_count(self, bounce: int) -> None:
        """Start reading the ray count of ``bounce`` (written by the last compaction of the bounce before)
        without waiting for it, and submit what is queued, so the device runs on while the host goes on."""
        self._ray_reads[bounce] = cl.enqueue_copy(self.device.queue, self._ray_counts[bounce:bounce + 1],
                                                  self.counters, src_offset=4 * (bounce * Q_COUNT + Q_RAY),
                                                  is_blocking=False)
        self.device.queue.flush()

    def _await_ray_count(self, bounce: int) -> int:
        """The ray count of ``bounce`` from its read started by :meth:`_start_ray_count`, waiting for it: the
        launches of ``bounce`` were queued behind it, so the device has work while the host waits."""
        event = self._ray_reads[bounce]
        if event is None:
            raise RuntimeError(f"no read of bounce {bounce}'s ray count was started")
        event.wait()
        return int(self._ray_counts[bounce])

    def bounce_stats(self) -> list[dict[str, int]]:
        """Per bounce since the last reset: paths alive (rays), hits, misses, shadow rays, unoccluded, and
        the paths finish_paths ran to their ends from this bounce on (``tail``; their later bounces
        are in :meth:`tail_alive`, not here)."""
        rows = []
        for b in range(self.max_depth + 1):
            row = {"bounce": b, **{name: int(self._bounce_totals[b, i]) for i, name in enumerate(QUEUES)},
                   "tail": int(self._tail_totals[b])}
            if row["rays"] == 0 and b > 0:
                break
            rows.append(row)
        return rows

    def tail_alive(self) -> list[int]:
        """Per bounce since the last reset, the paths finish_paths (the tail) had alive there: a ray it traced
        at that bounce, counted in no queue of :meth:`bounce_stats`. Empty when the tail traced none; paths
        alive at bounce b: ``bounce_stats()[b]["rays"] + tail_alive()[b]``."""
        n = int(np.flatnonzero(self._tail_alive_totals)[-1]) + 1 if self._tail_alive_totals.any() else 0
        return [int(v) for v in self._tail_alive_totals[:n]]

    def reset_stats(self) -> None:
        self._bounce_totals[:] = 0
        self._tail_totals[:] = 0
        self._tail_alive_totals[:] = 0
