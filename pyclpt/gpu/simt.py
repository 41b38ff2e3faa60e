"""A SIMT model of the streaming paper's claim: what a GPU would make of pyclpt's megakernel and
wavefront, predicted from the paths themselves (docs/gpu.md, "A SIMT model of the paper's claim").

Two parts:

* **The instrumented render** (:func:`trace_paths`). The megakernel built with ``-DPATH_TRACE``
  (``cl/integrators/path.h``, ``cl/scene/mask.h``; the ``BVH_COUNT`` hook of ``cl/scene/bvh.h``)
  records, per film slot (path) and bounce, what the path did: alive, hit or miss, a shadow ray cast,
  unoccluded, light and BSDF sampling allowed by the depth limit, the path going on, the material kind
  hit, and the BVH nodes visited and triangles tested by its closest-hit ray and by its shadow ray.
  The image is the plain render's bit for bit. Because the estimator is shared and every random
  number is keyed by (seed, pixel, sample, bounce, dimension), the wavefront's paths are these paths,
  and its queues are ordered (``compact_scatter.cl`` copies flagged entries in source order,
  ``path_init.cl`` starts from slots 0..n-1): the ray queue of bounce b is exactly the slots alive at
  b, ascending; the hit, miss, shadow and light-contribution queues are the matching subsets in the
  same order. So one trace gives every queue of every bounce.
* **The simulation** (:func:`simulate`). Work grouped as a GPU schedules it, in warps of
  ``width`` lanes (32: NVIDIA warps, AMD RDNA wave32; 64: AMD CDNA wave64): the megakernel's warps are
  consecutive film slots, each looping until its longest path ends, a bounce's traversal costing the
  largest of its active lanes' and each branch costing the warp if any lane takes it; the wavefront's
  stages run over their compacted queues (full warps but the last). Each warp's instructions come from
  :class:`CostModel` (stated estimates), path-state traffic from the 128-byte lines each warp's loads
  and stores touch in the SoA or AoS layout (:mod:`pyclpt.integrators.path_state`), and a kernel's
  time from a small roofline with a latency-hiding factor that grows with the resident warps its
  registers allow (:data:`REGISTERS`, :class:`Gpu`).

What the model leaves out: real warp schedulers (independent thread scheduling, reconvergence
points: a traversal's divergence is costed as the longest lane's, a lower bound), caches beyond
counting a warp's distinct lines (scene data, BVH nodes and triangles are not counted as traffic; they
are the same in both integrators), ray-tracing cores (the paper traversed with OptiX on RT cores;
here traversal is the software loop of ``bvh.h``), texture units, clocks and power.

May import: :mod:`pyclpt.rendering` and below (never :mod:`pyclpt.distributed`, the command line or
``bench``).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import pyopencl as cl

from pyclpt.device.context import alloc, fill_buffer
from pyclpt.device.profile import KernelProfile
from pyclpt.device.program import build_program
from pyclpt.gpu.targets import resident_slots, target
from pyclpt.integrators.megakernel import MEGAKERNEL_LAUNCH, Megakernel
from pyclpt.integrators.path_state import FIELDS
from pyclpt.integrators.wavefront import COMPACT_BLOCK, COMPACT_GROUP, GPU_WAVE_SIZE, expected_rays

# -- the trace -------------------------------------------------------------------------------------
# word 0's flags, as PATH_TRACE_* in cl/integrators/path.h
ALIVE, HIT, SHADOW, LIT, CONTINUED, NEXT, ENV_LIT = 1, 2, 4, 8, 16, 32, 64
TRACE_WORDS = 5  # flags | material << 8, closest nodes, closest triangles, shadow nodes, shadow triangles
MAX_TRACE_ROWS = 256  # bounces recorded at most (max_depth -1 renders up to 1024)


@dataclass
class PathTrace:
    """What every path of a render did at every bounce: arrays of shape (bounces, slots), slot f being
    film slot f of the render's batches in order (pixel f % pixels of sample f // pixels)."""

    flags: np.ndarray          # int32: ALIVE | HIT | SHADOW | LIT | CONTINUED | NEXT | ENV_LIT
    material: np.ndarray       # int16: material kind hit (MAT_* of cl/scene/bsdf.h), -1 where none
    closest_nodes: np.ndarray  # int32: BVH nodes the closest-hit ray visited
    closest_prims: np.ndarray  # int32: triangles it tested
    shadow_nodes: np.ndarray   # int32: the shadow ray's (0 where none was cast)
    shadow_prims: np.ndarray
    max_depth: int
    width: int = 0
    height: int = 0
    spp: int = 1
    scene: str = ""
    image: np.ndarray | None = field(default=None, repr=False)

    @property
    def bounces(self) -> int:
        return self.flags.shape[0]

    @property
    def slots(self) -> int:
        return self.flags.shape[1]

    def has(self, bit: int) -> np.ndarray:
        return (self.flags & bit) != 0

    @property
    def alive(self) -> np.ndarray:
        return self.has(ALIVE)

    def alive_counts(self) -> np.ndarray:
        """Paths alive (rays traced) at each bounce: the wavefront's ray-queue sizes."""
        return self.alive.sum(axis=1)

    def counts(self) -> list[dict[str, int]]:
        """Per bounce, the wavefront's queue sizes as its ``bounce_stats()`` names them."""
        rows = []
        for b in range(self.bounces):
            rays = int(self.alive[b].sum())
            if rays == 0 and b > 0:
                break
            hits = int(self.has(HIT)[b].sum())
            rows.append({"bounce": b, "rays": rays, "hits": hits, "misses": rays - hits,
                         "shadow_rays": int(self.has(SHADOW)[b].sum()), "unoccluded": int(self.has(LIT)[b].sum())})
        return rows

    def truncated(self, depth: int) -> PathTrace:
        """The trace a render at max depth ``depth`` (1 .. this one's) would record: the same paths
        (same random numbers), cut at bounce depth - 1, where only emission is gathered."""
        if not 1 <= depth <= self.max_depth:
            raise ValueError(f"depth must be 1..{self.max_depth} (the traced max depth), got {depth}")
        if depth > self.bounces:  # every path ended before that depth's last bounce: nothing changes
            return replace(self, max_depth=depth, image=None)
        f = self.flags[:depth].copy()
        sn, sp = self.shadow_nodes[:depth].copy(), self.shadow_prims[:depth].copy()
        f[depth - 1] &= ~(SHADOW | LIT | CONTINUED | NEXT | ENV_LIT)
        sn[depth - 1] = 0
        sp[depth - 1] = 0
        return replace(self, flags=f, material=self.material[:depth], closest_nodes=self.closest_nodes[:depth],
                       closest_prims=self.closest_prims[:depth], shadow_nodes=sn, shadow_prims=sp,
                       max_depth=depth, image=None)

    @classmethod
    def from_words(cls, words: np.ndarray, max_depth: int, **meta) -> PathTrace:
        """From the device's record, (TRACE_WORDS, bounces, slots) int32."""
        w0 = words[0]
        flags = (w0 & 0xFF).astype(np.int32)
        material = np.where((flags & HIT) != 0, (w0 >> 8) & 0xFF, -1).astype(np.int16)
        # bounces no path reached are left out
        alive_rows = np.flatnonzero((flags & ALIVE).any(axis=1))
        rows = int(alive_rows[-1]) + 1 if alive_rows.size else 1
        return cls(flags[:rows], material[:rows], words[1, :rows].copy(), words[2, :rows].copy(),
                   words[3, :rows].copy(), words[4, :rows].copy(), max_depth=max_depth, **meta)


class TracedMegakernel(Megakernel):
    """The megakernel built with ``-DPATH_TRACE``: it renders the same image and records each path's
    bounces (at most ``rows``) in a trace buffer, read back after every batch into :attr:`words`."""

    name = "megakernel"

    def __init__(self, device, scene, film, max_depth: int, rows: int,
                 wave_size: int = MEGAKERNEL_LAUNCH, local_size: int = 64) -> None:
        self.device, self.scene, self.film = device, scene, film
        self.max_depth, self.wave_size, self.local_size = max_depth, wave_size, local_size
        self.rows = int(rows)
        program = build_program(device, ["integrators/megakernel.cl"],
                                defines={**scene.defines, **film.defines, "PATH_TRACE": 1})
        self.kernel = cl.Kernel(program, "megakernel")
        self.profile = KernelProfile()
        self.words: list[np.ndarray] = []  # one (TRACE_WORDS, rows, slots) array per batch

    def _args(self, seed: int, first_sample: int, offset: int, count: int, trace, slots: int) -> tuple:
        return (*self.scene.args(*self.film.view), self.film.frame, self.film.drop_marks, np.uint32(seed),
                np.uint32(first_sample), np.int32(offset), np.int32(count), np.int32(self.max_depth),
                *self.film.aov_args(), trace, np.int32(slots), np.int32(self.rows))

    def warm_up(self) -> None:
        trace = alloc(self.device, 4, "path trace")
        self.kernel(self.device.queue, (self.local_size,), (self.local_size,), *self._args(0, 0, 0, 0, trace, 0))
        self.device.queue.finish()

    def render_frames(self, seed: int, first_sample: int, frames: int) -> None:
        if not 1 <= frames <= self.film.batch:
            raise ValueError(f"frames must be 1..{self.film.batch} (the film's batch), got {frames}")
        total = self.film.pixels * frames
        q = self.device.queue
        nbytes = 4 * TRACE_WORDS * self.rows * total
        trace = alloc(self.device, nbytes, f"path trace ({total} paths x {self.rows} bounces)")
        fill_buffer(q, trace, np.int32(0), 0, nbytes)
        for offset in range(0, total, self.wave_size):
            count = min(self.wave_size, total - offset)
            g = -(-count // self.local_size) * self.local_size
            ev = self.kernel(q, (g,), (self.local_size,), *self._args(seed, first_sample, offset, count, trace, total))
            self.profile.record("megakernel", ev)
        out = np.empty((TRACE_WORDS, self.rows, total), np.int32)
        cl.enqueue_copy(q, out, trace)
        self.words.append(out)
        self.film.count_dropped(frames)


def trace_paths(scene, *, spp: int = 1, max_depth: int | None = None, width: int | None = None,
                height: int | None = None, seed: int = 0, device=None, rows: int | None = None) -> PathTrace:
    """Render ``scene`` (a Scene or a scene name/file) with the instrumented megakernel and return the
    trace of every path (slots = pixels x spp) with the image (:attr:`PathTrace.image`)."""
    from pyclpt.rendering.renderer import Renderer
    from pyclpt.scene.library import load

    if not hasattr(scene, "film"):
        scene = load(scene)
    r = Renderer(scene, integrator="megakernel", max_depth=max_depth, width=width, height=height, device=device)
    depth = r.depth_limit
    rows = max(1, min(depth, MAX_TRACE_ROWS)) if rows is None else int(rows)
    tm = TracedMegakernel(r.device, r.scene_buffers, r.film, depth, rows, local_size=r.integrator.local_size)
    tm.warm_up()
    r.integrator = tm
    image = r.render(spp, seed=seed)
    words = np.concatenate(tm.words, axis=2)
    return PathTrace.from_words(words, depth, width=r.width, height=r.height, spp=spp, scene=scene.name, image=image)


# -- the machine and the cost model ---------------------------------------------------------------------
#: Registers per thread of each kernel on sm_90, the occupancy input: the GPU layout's kernels of the Cornell
#: box without the G-buffer (`pyclpt gpu-isa`, docs/benchmarks/gpu-isa.json; docs/gpu.md; process_hit and
#: sample_bsdf in steps, "The shading stages in steps"; the megakernel and finish_paths without the driver's cap).
#: Scenes with more material kinds need more (bench/gpu/simt_model.py --isa takes each scene's from a gpu-isa report).
REGISTERS: dict[str, int] = {
    "megakernel": 113, "finish_paths": 114, "intersect": 47, "shadow_test": 40, "sample_bsdf": 51,
    "process_hit": 44, "path_init": 27, "miss": 17, "light_contribution": 20, "compact_count": 19,
    "compact_scatter": 30, "compact": 24,  # compact: the scan compaction of the what-if (_scan_compaction)
}
#: The same before the GPU layout (the CPU's 8-wide BVH with a 1.5 KB stack), for comparison.
REGISTERS_CPU_LAYOUT: dict[str, int] = {
    "megakernel": 170, "finish_paths": 170, "intersect": 125, "shadow_test": 116, "sample_bsdf": 73,
    "process_hit": 60, "path_init": 24, "miss": 24, "light_contribution": 24, "compact_count": 24,
    "compact_scatter": 24, "compact": 24,
}
WAVEFRONT_STAGES = ("path_init", "intersect", "miss", "process_hit", "shadow_test", "light_contribution",
                    "sample_bsdf", "compact_count", "compact_scatter")


@dataclass(frozen=True)
class Gpu:
    """The machine. Defaults: the paper's RTX 3090 (GA102: 82 SMs, 1.695 GHz boost, 936 GB/s GDDR6X, 4
    warp schedulers per SM) with the sm_90 register-file rule of :mod:`pyclpt.gpu.targets` (65,536
    registers per SM in 4 slices, 64 warps, allocation in units of 8 registers a thread = 256 a warp);
    GA102 itself allows 48 warps per SM, which changes nothing for the kernels above 32 registers."""

    sms: int = 82
    clock_ghz: float = 1.695
    schedulers: int = 4           # warp instructions issued per SM per cycle at most
    bandwidth_gbs: float = 936.0  # DRAM
    line_bytes: int = 128
    registers: int = 65536
    partitions: int = 4
    granule: int = 8              # registers per thread
    max_warps: int = 64

    def resident_warps(self, registers: int, lanes: int = 32) -> int:
        """Warps per SM that fit ``registers`` per thread: sm_90's rule (pyclpt.gpu.targets) on this
        machine's register file."""
        t = replace(target("sm_90"), registers=self.registers, partitions=self.partitions, granule=self.granule,
                    max_slots=self.max_warps, lanes=lanes)
        return resident_slots(t, registers)

    def occupancy(self, registers: dict[str, int] | None = None) -> dict[str, float]:
        """{kernel: fraction of the SM's warp slots resident} from registers per thread."""
        regs = REGISTERS if registers is None else registers
        return {k: self.resident_warps(r) / self.max_warps for k, r in regs.items()}


@dataclass(frozen=True)
class CostModel:
    """Warp instructions of each piece of the estimator (a warp executing it once, whatever its active
    lanes), and the latency and launch constants. The instruction counts are estimates read off the
    OpenCL source (cl/), not measured: a Philox 4x32-10 draw is 10 rounds of 2 mul.lo + 2 mul.hi + 4
    xor/add plus the key schedule, about 80; an 8-wide BVH node (bvh_wide_node + bvh_wide_push) is 6
    eight-float rows, 48 subtract-multiplies, 48 min/max, 8 compare-selects, up to 8 pushes and their
    insertion sort, about 180; a triangle of a leaf packet about 30. Everything else is a few tens
    of instructions per function (docs/gpu.md lists them). Their sensitivity is tabulated there."""

    philox: float = 80.0
    node: float = 180.0           # one BVH node visited
    prim: float = 30.0            # one leaf triangle tested
    ray_setup: float = 20.0       # bvh_make_ray, scene_alpha
    camera: float = 140.0         # camera_path: one draw + the camera ray
    miss: float = 40.0            # path_miss (constant environment, MIS)
    surface: float = 90.0         # surface_hit: vertices, normals, uvs, frame
    surface_kept: float = 55.0    # surface_hit_shaded: vertices, uvs, the frame of the kept normal (GPU steps)
    step: float = 6.0             # a step boundary of the GPU's shading stages: the flag store, the entry read again
    emission: float = 25.0        # path_hit_emission (mostly not an emitter)
    bsdf_at: float = 40.0         # the material record (textures not counted)
    nee: float = 200.0            # path_sample_light minus the material: 1 draw (rng_light), light_sample, MIS, spawn
    material_eval: float = 80.0   # bsdf_eval of one material kind (per distinct kind in a warp)
    sample: float = 150.0         # path_sample_bsdf minus the material: 1 draw (rng_bsdf), frame, spawn, roulette
    material_sample: float = 100.0  # bsdf_sample of one material kind (per distinct kind in a warp)
    light_add: float = 10.0       # adding an unoccluded light sample
    commit: float = 15.0          # film_commit
    loop: float = 10.0            # the megakernel's loop bookkeeping per bounce
    stage: float = 20.0           # a wavefront stage's prologue: id, bounds, queue entry, Scene init
    key: float = 30.0             # path_key: film slot -> pixel, sample (integer division), rng key
    compact_flag: float = 4.0     # compact_count: per flag counted (a byte load, add, loop)
    compact_entry: float = 6.0    # compact_scatter: per entry copied
    compact_block: float = 2.0    # compact_scatter: per earlier block's count summed
    scan: float = 30.0            # a GPU scan compaction per entry: ballot, popcount, look-back, store
    group_scan_step: float = 8.0  # a step of the GPU class's work-group scan (compact_group_scan): load, add,
    #                               two barriers, store, per lane; log2(COMPACT_GROUP) steps a scan
    warps_to_hide: float = 32.0   # resident warps per SM at which memory latency is hidden
    launch_us: float = 4.0        # per kernel launch, back to back in one queue
    readback_us: float = 15.0     # the host's read of the ray count before each bounce (readback schedule)
    exit: float = 8.0             # a lane past its queue's count: id, the count's load, compare, return

    def hiding(self, warps: float) -> float:
        """Fraction of the SM's issue rate reached with ``warps`` resident warps: min(1, warps / warps_to_hide)."""
        return min(1.0, max(warps, 1e-9) / self.warps_to_hide)


# -- warp-level evaluation ---------------------------------------------------------------------------------
def _pack(slots: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Slots in lanes: (warps, width) indices (0 padding) and the valid mask."""
    n = slots.size
    w = max(1, -(-n // width))
    idx = np.zeros(w * width, np.int64)
    idx[:n] = slots
    valid = np.zeros(w * width, bool)
    valid[:n] = True
    return idx.reshape(w, width), valid.reshape(w, width)


def _distinct(ids: np.ndarray) -> np.ndarray:
    """Distinct non-negative values per row of ``ids`` (-1 = nothing)."""
    if ids.shape[1] == 0:
        return np.zeros(ids.shape[0], np.int64)
    s = np.sort(ids, axis=1)
    new = np.empty(s.shape, bool)
    new[:, 0] = True
    new[:, 1:] = s[:, 1:] != s[:, :-1]
    return (new & (s >= 0)).sum(axis=1)


@dataclass
class Work:
    """A kernel's warps: instructions issued per warp (memory replays included), lane-instructions
    spent by active lanes (compute), path-state lines (distinct per warp) and requests (distinct lines
    per instruction, summed), and the launches."""

    warp: np.ndarray
    lane: np.ndarray
    lines: float = 0.0
    requests: float = 0.0
    launches: int = 0
    width: int = 32
    compute_issue: float | None = None  # instructions without the memory replays (utilisation's base)

    @property
    def compute(self) -> float:
        return float(self.warp.sum()) if self.compute_issue is None else self.compute_issue

    def utilisation(self, compute_issue: float) -> float:
        return float(self.lane.sum()) / (self.width * compute_issue) if compute_issue > 0 else 1.0


def warp_cost(terms: list[tuple], valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Instructions per warp and active lane-instructions per warp of a piece of code, from ``terms``:

    * ``("any", mask, cost)``: a branch: the warp pays ``cost`` if any lane of ``mask`` takes it, each such
      lane uses it;
    * ``("max", mask, per_lane)``: a loop: the warp pays the longest of its ``mask`` lanes' ``per_lane``
      (a traversal), each lane uses its own;
    * ``("kinds", mask, (kinds, cost))``: a dispatch: the warp pays ``cost`` per distinct kind among its
      ``mask`` lanes (each kind's code runs with the others' lanes idle), each lane uses one.

    Masks are (warps, width) and are and-ed with ``valid``."""
    warps = valid.shape[0]
    warp = np.zeros(warps)
    lane = np.zeros(warps)
    for mode, mask, value in terms:
        m = mask & valid
        if mode == "any":
            warp += value * m.any(axis=1)
            lane += value * m.sum(axis=1)
        elif mode == "max":
            v = np.where(m, value, 0.0)
            warp += v.max(axis=1) if v.shape[1] else 0.0
            lane += v.sum(axis=1)
        elif mode == "kinds":
            kinds, cost = value
            warp += cost * _distinct(np.where(m, kinds, -1))
            lane += cost * m.sum(axis=1)
        else:
            raise ValueError(f"unknown term {mode!r}")
    return warp, lane


# -- path-state traffic ------------------------------------------------------------------------------------
def _components() -> dict[str, int]:
    """Scalar component name -> its word in an AoS record (= its SoA buffer's index), from FIELDS."""
    out, w = {}, 0
    for f in FIELDS:
        names = [f.name] if f.width == 1 else [f"{f.name}_{a}" for a in "xyz"[: f.width]]
        for n in names:
            out[n] = w
            w += 1
    return out


COMPONENTS = _components()
RECORD_WORDS = len(COMPONENTS)


def _expand(names: tuple[str, ...]) -> list[str]:
    out = []
    for n in names:
        out += [n] if n in COMPONENTS else [f"{n}_{a}" for a in "xyz"]
    for n in out:
        if n not in COMPONENTS:
            raise KeyError(f"no path-state component {n!r} (pyclpt/integrators/path_state.py)")
    return out


#: What each wavefront stage reads and writes of the path state, read off cl/integrators/wavefront/*.cl and
#: wavefront.h (path_load_shading, path_store_ray, path_store_hit, path_store_shadow, path_key, the GPU steps'
#: path_keep_hit_normal and path_hit_surface), as the GPU layout builds them (-DDEVICE_CLASS_GPU), without
#: -DAOVS: (predicate, "r"/"w", fields). Predicates: "all" lanes of the queue, "hit" (intersect's hits),
#: "next" (the depth limit allows light and BSDF sampling), "shadow", "continued", "ended" (sample_bsdf's
#: paths that end), "env_lit" (shadow_test's unoccluded environment samples, whose contribution it multiplies by
#: the environment's radiance: ENV_DEFERRED, cl/scene/lights.h). One scalar access per component (the accessors
#: are scalar in both layouts).
STAGE_ACCESS: dict[str, list[tuple[str, str, tuple[str, ...]]]] = {
    "path_init": [("all", "w", ("film_slot", "L", "org", "dir", "beta", "rr_scale", "prev_pdf", "flags",
                                "depth"))],
    "intersect": [("all", "r", ("film_slot", "org", "dir")),
                  ("hit", "w", ("hit_t", "hit_u", "hit_v", "hit_prim"))],
    "miss": [("all", "r", ("dir", "beta", "L", "flags", "prev_pdf", "film_slot"))],
    "process_hit": [("all", "r", ("dir", "beta", "L", "flags", "prev_pdf", "hit_prim", "hit_u", "hit_v",
                                  "hit_t")),
                    ("all", "w", ("L", "org")),  # org: the kept shading normal (wavefront.h, path_keep_hit_normal)
                    ("next", "r", ("film_slot",)),
                    # the light sample kept in the shadow ray's slots between two steps (the steps' reads of what
                    # an earlier step wrote or read hit the same lines and are not counted again)
                    ("next", "w", ("shadow_org", "shadow_dir", "shadow_tmax", "shadow_contrib"))],
    "shadow_test": [("all", "r", ("film_slot", "shadow_org", "shadow_dir", "shadow_tmax")),
                    ("env_lit", "r", ("shadow_contrib",)), ("env_lit", "w", ("shadow_contrib",))],
    "light_contribution": [("all", "r", ("L", "shadow_contrib")), ("all", "w", ("L",))],
    "sample_bsdf": [("all", "r", ("dir", "beta", "rr_scale", "hit_prim", "hit_u", "hit_v", "org", "film_slot")),
                    ("continued", "w", ("org", "dir", "beta", "rr_scale", "prev_pdf", "flags", "depth")),
                    ("ended", "r", ("L",))],
}


def line_ids(index: np.ndarray, word: int, layout: str, line_bytes: int = 128) -> np.ndarray:
    """The 128-byte line holding component ``word`` of the path at ``index`` (slot): SoA, one array per
    component, each aligned to a line (OpenCL buffers are); AoS, one record of RECORD_WORDS words per
    path. Ids of different SoA arrays never collide."""
    if layout == "soa":
        return word * (1 << 40) + (4 * index) // line_bytes
    if layout == "aos":
        return (4 * (RECORD_WORDS * index + word)) // line_bytes
    raise ValueError(f"unknown layout {layout!r} (soa, aos)")


def state_traffic(index: np.ndarray, masks: dict[str, np.ndarray], accesses, layout: str,
                  line_bytes: int = 128) -> tuple[np.ndarray, np.ndarray]:
    """Per warp of a stage: (distinct lines touched by all its path-state accesses, requests = distinct
    lines of each access instruction summed). ``index``: (warps, width) path indices the state is
    indexed by; ``masks``: predicate -> (warps, width) lanes; ``accesses``: a STAGE_ACCESS entry."""
    warps = index.shape[0]
    requests = np.zeros(warps, np.int64)
    all_ids = []
    for pred, _, names in accesses:
        m = masks[pred]
        for n in _expand(names):
            ids = np.where(m, line_ids(index, COMPONENTS[n], layout, line_bytes), -1)
            requests += _distinct(ids)
            all_ids.append(ids)
    lines = _distinct(np.concatenate(all_ids, axis=1)) if all_ids else np.zeros(warps, np.int64)
    return lines, requests


# -- the two integrators, warp by warp ---------------------------------------------------------------------
def _lane_steps(trace: PathTrace, c: CostModel, b: int, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    closest = trace.closest_nodes[b, idx] * c.node + trace.closest_prims[b, idx] * c.prim
    shadow = trace.shadow_nodes[b, idx] * c.node + trace.shadow_prims[b, idx] * c.prim
    return closest, shadow


def megakernel_work(trace: PathTrace, c: CostModel, width: int = 32, slots: np.ndarray | None = None,
                    first_bounce: int = 0) -> tuple[Work, dict]:
    """The megakernel's warps (consecutive ``slots``, all by default) running their paths' loop from
    ``first_bounce`` until the warp's longest path ends (finish_paths: a queue's paths from its bounce).
    Returns the per-warp work and, per bounce, warps running, lanes alive and lane utilisation."""
    slots = np.arange(trace.slots) if slots is None else slots
    idx, valid = _pack(slots, width)
    warp = np.zeros(idx.shape[0])
    lane = np.zeros(idx.shape[0])
    if first_bounce == 0:  # camera_path, once per path
        w, l_ = warp_cost([("any", valid, c.camera)], valid)
        warp += w
        lane += l_
    per_bounce = {"warps": [], "alive": [], "utilisation": []}
    for b in range(first_bounce, trace.bounces):
        f = trace.flags[b][idx]
        alive = ((f & ALIVE) != 0) & valid
        if not alive.any():
            break
        hit, nxt = (f & HIT) != 0, (f & NEXT) != 0
        shadow, lit, cont = (f & SHADOW) != 0, (f & LIT) != 0, (f & CONTINUED) != 0
        closest, shadow_cost = _lane_steps(trace, c, b, idx)
        kinds = trace.material[b][idx]
        ended = (alive & ~hit) | (hit & ~cont)
        terms = [("any", alive, c.loop + c.ray_setup), ("max", alive, closest),
                 ("any", alive & ~hit, c.miss), ("any", hit, c.surface + c.emission),
                 ("any", nxt, c.bsdf_at + c.nee + c.sample),
                 ("kinds", nxt, (kinds, c.material_eval + c.material_sample)),
                 ("any", shadow, c.ray_setup), ("max", shadow, shadow_cost), ("any", lit, c.light_add),
                 ("any", ended, c.commit)]
        w, l_ = warp_cost(terms, alive)
        running = alive.any(axis=1)
        warp += w
        lane += l_
        per_bounce["warps"].append(int(running.sum()))
        per_bounce["alive"].append(int(alive.sum()))
        per_bounce["utilisation"].append(float(l_.sum() / (width * w.sum())) if w.sum() else 1.0)
    return Work(warp, lane, launches=1, width=width), per_bounce


def _queue_masks(trace: PathTrace, b: int, idx: np.ndarray, valid: np.ndarray) -> dict[str, np.ndarray]:
    f = trace.flags[b, idx]
    hit, cont = (f & HIT) != 0, (f & CONTINUED) != 0
    return {"all": valid, "hit": valid & hit, "next": valid & ((f & NEXT) != 0), "shadow": valid & ((f & SHADOW) != 0),
            "continued": valid & cont, "ended": valid & hit & ~cont, "env_lit": valid & ((f & ENV_LIT) != 0)}


def _stage_terms(stage: str, trace: PathTrace, c: CostModel, b: int, idx: np.ndarray, masks: dict) -> list[tuple]:
    v = masks["all"]
    closest, shadow_cost = _lane_steps(trace, c, b, idx)
    kinds = trace.material[b, idx]
    if stage == "path_init":
        return [("any", v, c.stage + c.camera)]
    if stage == "intersect":
        return [("any", v, c.stage + c.key + c.ray_setup), ("max", v, closest)]
    if stage == "miss":
        return [("any", v, c.stage + c.miss + c.commit)]
    if stage == "process_hit":  # in steps (cl/integrators/wavefront/process_hit.cl, DEVICE_CLASS_GPU): the normal
        # kept, the emission, the light sample, the textures, the BSDF at it, each on a surface rebuilt from the
        # kept normal after a step boundary
        return [("any", v, c.stage + c.surface + c.step + c.surface_kept + c.emission),
                ("any", masks["next"], c.key + 3 * (c.step + c.surface_kept) + c.bsdf_at + c.nee),
                ("kinds", masks["next"], (kinds, c.material_eval))]
    if stage == "shadow_test":
        return [("any", v, c.stage + c.key + c.ray_setup), ("max", v, shadow_cost)]
    if stage == "light_contribution":
        return [("any", v, c.stage + c.light_add)]
    if stage == "sample_bsdf":
        # in steps (sample_bsdf.cl, DEVICE_CLASS_GPU): the textures, the BSDF's sample, the next ray, each on a
        # surface rebuilt from the kept normal after a step boundary
        return [("any", v, c.stage + 2 * c.step),
                ("any", masks["next"], c.key + 3 * c.surface_kept + c.step + c.bsdf_at + c.sample),
                ("kinds", masks["next"], (kinds, c.material_sample)), ("any", masks["ended"], c.commit)]
    raise ValueError(stage)


def _queue_traffic(n: int, width: int, line_bytes: int) -> tuple[np.ndarray, np.ndarray]:
    """Per warp of a queue of n entries: the queue entries read (4 bytes a lane) and flags written (1 byte)."""
    warps = max(1, -(-n // width))
    i = np.arange(warps * width).reshape(warps, width)
    m = i < n
    lines = _distinct(np.where(m, (4 * i) // line_bytes, -1)) + _distinct(np.where(m, (1 << 40) + i // line_bytes, -1))
    return lines, lines


def _compaction(n: float, c: CostModel, width: int, line_bytes: int = 128, block: int = 1024) -> tuple[Work, Work]:
    """pyclpt's order-preserving compaction of a queue of n entries (compact_count, compact_scatter:
    one work-item per block of ``block`` entries, looping over it)."""
    items = max(1, math.ceil(n / block))
    full, last = divmod(n, block)
    per_item = np.full(items, float(block))
    if last or not full:
        per_item[-1] = last if last else max(n, 0)
    warps = -(-items // width)
    pad = np.zeros(warps * width)
    pad[:items] = per_item
    entries = pad.reshape(warps, width)
    blocks = np.arange(warps * width, dtype=float).reshape(warps, width)
    count_lane = c.stage + c.compact_flag * entries
    scatter_lane = c.stage + c.compact_entry * entries + c.compact_block * np.where(entries > 0, blocks, 0)
    valid = entries > 0
    lines = (n + 4 * n + 4 * n) / line_bytes  # flags read, queue read, queue written (at most)
    out = []
    for per_lane, lns in ((count_lane, (n + items * 4) / line_bytes), (scatter_lane, lines)):
        w, l_ = warp_cost([("max", valid, per_lane)], valid)
        out.append(Work(w, l_, lines=lns, requests=lns, launches=1, width=width))
    return out[0], out[1]


def _group_compaction(n: float, c: CostModel, width: int, line_bytes: int = 128, block: int = COMPACT_BLOCK,
                      group: int = COMPACT_GROUP, launched: float = 0.0) -> tuple[Work, Work]:
    """The GPU class's order-preserving compaction of n entries (``-DCOMPACT_GROUP``: compact_count and
    compact_scatter with a work-group of ``group`` lanes a block of ``block`` entries, each lane owning
    block / group consecutive entries): the count's lanes load their flags and scan the group's counts; the
    scatter's lanes first sum the earlier blocks' counts (strided, then a scan), scan again for their own
    offsets and copy their entries. Launched over ``launched`` entries (the bounce's bound), the work-groups
    past the queue's blocks exit at once (``c.exit`` a warp)."""
    per_lane = block // group
    lanes = max(1, math.ceil(n / per_lane))
    blocks = max(1, math.ceil(n / block))
    warps = -(-lanes // width)
    lane = np.arange(warps * width)
    entries = np.clip(n - lane * per_lane, 0, per_lane).astype(float)
    valid = (entries > 0).reshape(warps, width)
    own_block = lane // group
    steps = math.log2(group)
    scan = c.group_scan_step * steps
    count_lane = c.stage + c.compact_flag * entries + scan
    earlier = np.ceil(own_block / group)  # the strided sum: a lane's share of the earlier blocks
    scatter_lane = c.stage + c.compact_block * earlier + 2 * scan + (c.compact_flag + c.compact_entry) * entries
    counts_read = 4 * blocks * (blocks - 1) / 2  # each block's group reads the earlier blocks' counts
    idle = max(0, math.ceil(launched / block) - (blocks if n > 0 else 0)) * -(-group // width)
    out = []
    for per, lns in ((count_lane, (n + 4 * blocks) / line_bytes),
                     (scatter_lane, (n + 4 * n + 4 * n + counts_read) / line_bytes)):
        w, l_ = warp_cost([("max", valid, per.reshape(warps, width))], valid)
        w, l_ = np.concatenate([w, np.full(idle, c.exit)]), np.concatenate([l_, np.zeros(idle)])
        out.append(Work(w, l_, lines=lns, requests=lns, launches=1, width=width))
    return out[0], out[1]


def _scan_compaction(n: float, c: CostModel, width: int, moved_words: int = 0, line_bytes: int = 128) -> Work:
    """A GPU's order-preserving compaction of n entries in one launch (a warp-ballot prefix sum per warp and
    a decoupled look-back across warps: every entry one lane, ``c.scan`` instructions), moving
    ``moved_words`` words of state per entry with it (0: only the queue)."""
    lanes = int(round(n))
    warps = max(1, -(-lanes // width))
    valid = (np.arange(warps * width) < lanes).reshape(warps, width)
    w, l_ = warp_cost([("any", valid, c.stage + c.scan + 2 * moved_words)], valid)
    lines = (n + 4 * n + 4 * n + 2 * 4 * moved_words * n) / line_bytes
    return Work(w, l_, lines=lines, requests=lines, launches=1, width=width)


def _stage_work(stage: str, trace: PathTrace, c: CostModel, slots: np.ndarray, bounce, paths: np.ndarray | None,
                layout: str, width: int, line_bytes: int, launched: int, where: np.ndarray | None = None) -> Work:
    """One launch of a wavefront stage over the queue ``slots`` (the path-state slots, in queue order) holding the
    traced ``paths`` (None: the slots' own, as in pyclpt's wavefront) at ``bounce`` (an int, or one per entry),
    launched over ``launched`` lanes: the warps past the queue exit (``c.exit`` each). ``where``: the state's index
    when it is not the slot (the queue-indexed what-if)."""
    idle = np.full(max(0, -(-launched // width) - -(-slots.size // width)), c.exit)
    if slots.size == 0:  # launched all the same (readback: every stage over the ray count), all exit
        return Work(idle, np.zeros(idle.size), launches=1, width=width)
    idx, valid = _pack(slots, width)
    pidx = idx if paths is None else _pack(paths, width)[0]
    b = bounce if np.isscalar(bounce) else _pack(np.asarray(bounce), width)[0]
    masks = _queue_masks(trace, b, pidx, valid)
    warp, lane = warp_cost(_stage_terms(stage, trace, c, b, pidx, masks), valid)
    lines, requests = state_traffic(idx if where is None else _pack(where, width)[0], masks, STAGE_ACCESS[stage],
                                    layout, line_bytes)
    ql, qr = _queue_traffic(slots.size, width, line_bytes)
    return Work(np.concatenate([warp + requests + qr, idle]), np.concatenate([lane, np.zeros(idle.size)]),
                lines=float(lines.sum() + ql.sum()), requests=float(requests.sum() + qr.sum()), launches=1,
                width=width, compute_issue=float(warp.sum()))


def wavefront_work(trace: PathTrace, c: CostModel, layout: str = "soa", width: int = 32, line_bytes: int = 128,
                   scale: float = 1.0, tail_from: int | None = None, compaction: str = "ordered",
                   indexing: str = "slot", schedule: str = "readback") -> tuple[dict[str, list[Work]], dict]:
    """The wavefront's launches: {kernel: [Work per launch]} and per bounce {stage: utilisation, queue
    sizes}. Stages run over their ordered queues (the trace's subsets in slot order); the path state is
    indexed by slot, as the stages do (``path_get_*(&P, slot)``). ``scale`` multiplies the queue sizes
    for the compaction (a traced wave standing for a larger one). ``tail_from``: from that bounce on the
    paths go to finish_paths (a megakernel loop over the queue's paths), as pyclpt's tail does.
    ``compaction``: "ordered" (pyclpt's compact_count + compact_scatter on CPUs, a work-item a block of 1,024
    entries, 4 pairs a bounce), "group" (the same pair as the GPU class builds it, a work-group of 256 lanes a
    block: :func:`_group_compaction`) or "scan" (a GPU's one-launch scan, :func:`_scan_compaction`).
    ``indexing``: "slot" (pyclpt: state at the path's slot) or "queue" (what if: the state moved with its
    queue, at the queue position, so a warp's lanes read consecutive entries; the scan then moves every
    continuing path's record once a bounce). ``schedule``: "readback" (each bounce's launches sized by its ray
    count) or "pipelined" (by the ray count of the bounce before, from the third bounce; the wave's before:
    the lanes past a queue's count exit, ``c.exit`` each; :class:`pyclpt.integrators.wavefront.Wavefront`)."""
    if compaction not in ("ordered", "group", "scan"):
        raise ValueError(f"unknown compaction {compaction!r} (ordered, group, scan)")
    if schedule not in ("readback", "pipelined"):
        raise ValueError(f"unknown schedule {schedule!r} (readback, pipelined)")
    if indexing not in ("slot", "queue"):
        raise ValueError(f"unknown indexing {indexing!r} (slot, queue)")
    launches: dict[str, list[Work]] = {s: [] for s in (*WAVEFRONT_STAGES, "compact", "finish_paths")}
    per_bounce: list[dict] = []

    def run(stage: str, b: int, slots: np.ndarray) -> None:
        work = _stage_work(stage, trace, c, slots, b, None, layout, width, line_bytes, bound,
                           None if indexing == "slot" else np.arange(slots.size))
        launches[stage].append(work)
        if slots.size:
            row[stage] = work.utilisation(work.compute)

    all_slots = np.arange(trace.slots)
    row: dict = {}
    bound = trace.slots  # the pipelined schedule's launch size: the wave, then the ray count of the bounce before
    run("path_init", 0, all_slots)
    alive = trace.alive_counts()
    for b in range(trace.bounces):
        f = trace.flags[b]
        rays = np.flatnonzero(f & ALIVE)
        # every stage and compaction of a bounce is launched over the bound (Wavefront.bounce): the ray count
        # (readback), or the ray count of the bounce before (pipelined; the wave's for the first two)
        bound = rays.size if schedule == "readback" else trace.slots if b < 2 else int(alive[b - 1])
        if bound == 0:
            break
        row = {"bounce": b, "rays": int(rays.size)}
        if tail_from is not None and b >= tail_from:  # finish_paths over the bound: its lanes past the rays exit
            if rays.size == 0:
                break
            work, _ = megakernel_work(trace, c, width, rays, first_bounce=b)
            launches["finish_paths"].append(work)
            row["finish_paths"] = work.utilisation(work.compute)
            per_bounce.append(row)
            break
        hits = np.flatnonzero((f & (ALIVE | HIT)) == (ALIVE | HIT))
        misses = np.flatnonzero((f & (ALIVE | HIT)) == ALIVE)
        shadows = np.flatnonzero(f & SHADOW)
        lit = np.flatnonzero(f & LIT)
        nxt = np.flatnonzero(f & CONTINUED)
        run("intersect", b, rays)
        run("miss", b, misses)
        run("process_hit", b, hits)
        run("shadow_test", b, shadows)
        run("light_contribution", b, lit)
        run("sample_bsdf", b, hits)
        # the four compactions of a bounce (wavefront.py: Wavefront.bounce), sized by their source queues
        for k, n in enumerate((rays.size, hits.size, shadows.size, hits.size)):
            if compaction in ("ordered", "group"):
                if compaction == "ordered":
                    cc, cs = _compaction(n * scale, c, width, line_bytes)
                else:
                    cc, cs = _group_compaction(n * scale, c, width, line_bytes, launched=bound * scale)
                launches["compact_count"].append(cc)
                launches["compact_scatter"].append(cs)
            else:
                # queue-indexed state moves with its queue: whole records into the hit/miss split and the
                # next ray queue, the shadow ray and film slot (11 words) into the shadow queue, the
                # contribution (4) into the light queue; an approximation of such a design
                moved = (RECORD_WORDS, 11, 4, RECORD_WORDS)[k] if indexing == "queue" else 0
                launches["compact"].append(_scan_compaction(n * scale, c, width, moved, line_bytes))
        row.update(hits=int(hits.size), misses=int(misses.size), shadow_rays=int(shadows.size),
                   unoccluded=int(lit.size), continued=int(nxt.size))
        per_bounce.append(row)
    return launches, {"bounces": per_bounce}


def regenerating_work(trace: PathTrace, c: CostModel, layout: str = "soa", width: int = 32, line_bytes: int = 128,
                      pool: int | None = None, passes: int = 4,
                      scale: float = 1.0) -> tuple[dict[str, list[Work]], dict]:
    """What if the wavefront regenerated paths (a design, not pyclpt's code; docs/gpu.md, "Regeneration"): a pool
    of ``pool`` slots (default: a quarter of the trace) fed from a stream of ``passes`` times the traced paths, as
    a render of many samples per pixel would be, the paper's Fig. 6 (1,024 spp). Each step runs one bounce of every
    path in the pool, whatever its own bounce: intersect, miss, process_hit, shadow_test, light_contribution and
    sample_bsdf over their queues, and the three compactions between them as now; then the slots whose path ended
    (its miss, or sample_bsdf ending it) are listed (a compaction over the pool), path_init starts the stream's
    next paths in them (their camera rays), and the next ray queue is the pool's live slots in slot order (a
    second compaction over the pool): a queue that kept the new paths apart would mix its order bounce after
    bounce, and SoA's loads with it. Launches are sized by their queues (the readback schedule). ``scale``
    multiplies the compactions' sizes (a traced pool standing for a larger one).

    Only the steady steps are returned, {kernel: [Work]}: from the step at which the pool has turned over once
    (the first pool's paths started in step and bounce lockstep) to the step at which the stream runs out (then
    the pool drains); a render of many samples per pixel is nearly all such steps. The second value:
    {"steps": per step simulated, its rays, new paths and ended paths, "window": (first, last + 1) step priced,
    "paths": the paths that ended in those steps}."""
    paths = trace.slots
    slots = paths // 4 if pool is None else int(pool)
    if not 1 <= slots <= paths:
        raise ValueError(f"pool must be 1..{paths} (the traced paths), got {pool}")
    if passes < 3:
        raise ValueError(f"passes must be at least 3 (a turn-over of the pool, then steady steps), got {passes}")
    total = paths * passes
    launches: dict[str, list[Work]] = {s: [] for s in (*WAVEFRONT_STAGES, "compact_count", "compact_scatter")}
    instance = np.arange(slots)  # the stream's path each slot holds (the traced path instance % paths)
    bounce = np.zeros(slots, np.int64)
    started, priced = slots, 0
    steps: list[dict] = []
    first = None

    def run(stage: str, q: np.ndarray) -> None:
        if q.size and first is not None:
            launches[stage].append(_stage_work(stage, trace, c, q, bounce[q], instance[q] % paths, layout, width,
                                               line_bytes, q.size))

    def compaction(n: int) -> None:
        if first is not None:
            cc, cs = _group_compaction(n * scale, c, width, line_bytes, launched=n * scale)
            launches["compact_count"].append(cc)
            launches["compact_scatter"].append(cs)

    queue = np.arange(slots)
    while started < total:
        if first is None and started >= 2 * slots:
            first = len(steps)
        f = trace.flags[bounce[queue], instance[queue] % paths]
        hit = (f & HIT) != 0
        going = (f & CONTINUED) != 0
        for stage, q in (("intersect", queue), ("miss", queue[~hit]), ("process_hit", queue[hit]),
                         ("shadow_test", queue[(f & SHADOW) != 0]), ("light_contribution", queue[(f & LIT) != 0]),
                         ("sample_bsdf", queue[hit])):
            run(stage, q)
        for n in (queue.size, int(hit.sum()), int(((f & SHADOW) != 0).sum())):
            compaction(n)
        ended = queue[~going]  # in slot order, as the queue is
        new = ended[:min(ended.size, total - started)]
        bounce[queue[going]] += 1
        compaction(slots)  # the free slots
        instance[new] = np.arange(started, started + new.size)
        bounce[new] = 0
        started += new.size
        run("path_init", new)
        compaction(slots)  # the live slots: the next ray queue
        if first is not None:
            priced += ended.size
        steps.append({"rays": int(queue.size), "new": int(new.size), "ended": int(ended.size)})
        queue = np.sort(np.concatenate([queue[going], new]))
        if queue.size == 0:
            raise ValueError("the pool emptied while the stream had paths left")
    if first is None or priced == 0:
        raise ValueError(f"no steady step: a longer stream (passes > {passes}) or a smaller pool")
    return launches, {"steps": steps, "window": (first, len(steps)), "paths": priced}


# -- time -----------------------------------------------------------------------------------------------------
def kernel_time_us(work: Work, occupancy: float, gpu: Gpu, c: CostModel, scale: float = 1.0,
                   scaled_compaction: bool = False) -> dict[str, float]:
    """One launch's predicted time (µs): max(issue-bound, bandwidth-bound, its longest warp alone) plus
    the launch. ``scale``: the traced warps stand for ``scale`` times as many (a larger image)."""
    s = 1.0 if scaled_compaction else scale
    n_warps = work.warp.size * s
    if n_warps <= 0 or work.warp.sum() <= 0:
        return {"issue_us": 0.0, "memory_us": 0.0, "critical_us": 0.0, "time_us": c.launch_us}
    resident = max(1, occupancy * gpu.max_warps)
    sms = min(gpu.sms, n_warps)
    per_sm = min(resident, n_warps / sms)
    clock = gpu.clock_ghz * 1e3  # cycles per µs
    issue = work.warp.sum() * s / (sms * gpu.schedulers * c.hiding(per_sm) * clock)
    memory = work.lines * s * gpu.line_bytes / (gpu.bandwidth_gbs * 1e3)  # bytes / (bytes per µs)
    critical = work.warp.max() * max(c.warps_to_hide, per_sm) / gpu.schedulers / clock
    return {"issue_us": issue, "memory_us": memory, "critical_us": critical,
            "time_us": max(issue, memory, critical) + c.launch_us}


def _expected_rays(counts: np.ndarray, b: int, schedule: str, n: int) -> int:
    """The ray count the host expects at bounce ``b`` for the tail's test (Wavefront.render_frames): the count
    itself (readback), or under the pipelined schedule the count of the bounce before times the ratio of the two
    before (``n``, the wave, at bounces 0 and 1: Wavefront._pipelined_bound)."""
    if schedule == "readback":
        return int(counts[b])
    if b < 2:
        return n
    return expected_rays(int(counts[b - 1]), int(counts[b - 2]) if b > 2 else n)


#: The wavefront variants :func:`simulate` predicts by default.
WAVEFRONTS: dict[str, dict] = {"wavefront_soa": {"layout": "soa"}, "wavefront_aos": {"layout": "aos"}}


@dataclass
class Prediction:
    """Predicted times (ms) and utilisations of one trace."""

    scene: str
    max_depth: int
    width: int
    traced_slots: int
    target_slots: int
    times_ms: dict[str, float]
    kernels: dict[str, dict[str, dict[str, float]]]
    utilisation: dict[str, dict[str, float]]
    per_bounce: dict[str, list]
    lines: dict[str, dict[str, float]]

    def ratio(self, a: str, b: str) -> float:
        """time of b / time of a: how many times faster a is than b."""
        return self.times_ms[b] / self.times_ms[a]

    def as_dict(self) -> dict:
        return asdict(self)


def simulate(trace: PathTrace, *, width: int = 32, occupancy: dict[str, float] | None = None,
             gpu: Gpu | None = None, cost: CostModel | None = None, target_slots: int | None = None,
             wavefronts: dict[str, dict] | None = None) -> Prediction:
    """Predict the megakernel's and the wavefront's (SoA and AoS) frame times on ``gpu`` from ``trace``.

    ``occupancy``: {kernel: fraction of the SM's warp slots resident} (default: from :data:`REGISTERS` by
    :meth:`Gpu.occupancy`; pyclpt.gpu.targets gives it for other targets). ``target_slots``: the paths a
    frame has on the GPU (the paper's 1280x720 = 921,600 at 1 spp), the traced ones standing for them
    (work and traffic scale with the path count; the longest warp does not); default: the traced count.
    ``wavefronts``: {name: options} of the wavefront variants to predict, options being ``layout`` ("soa",
    "aos"), ``compaction`` and ``indexing`` (:func:`wavefront_work`) and ``tail`` (a fraction of the wave:
    finish_paths takes the paths from the first bounce after 0 whose ray queue holds at most that many,
    as pyclpt's tail, default 1/4; None: no tail) or ``regenerate`` (a design, :func:`regenerating_work`: the
    fraction of the traced paths its pool holds, standing for a GPU wave of GPU_WAVE_SIZE slots, with ``passes``;
    its time is that of a frame's paths in a render of many samples per pixel, the megakernel's a 1-spp frame's,
    which is the same per path). Default: :data:`WAVEFRONTS`, pyclpt's code as written less the tail (the paper's
    structure) in both layouts."""
    gpu = gpu or Gpu()
    c = cost or CostModel()
    occ = {**gpu.occupancy(), **(occupancy or {})}
    target = trace.slots if target_slots is None else int(target_slots)
    scale = target / trace.slots
    times: dict[str, float] = {}
    kernels: dict[str, dict] = {}
    util: dict[str, dict] = {}
    per_bounce: dict[str, list] = {}
    lines: dict[str, dict] = {}

    mk, mk_bounces = megakernel_work(trace, c, width)
    t = kernel_time_us(mk, occ["megakernel"], gpu, c, scale)
    times["megakernel"] = t["time_us"] / 1e3
    kernels["megakernel"] = {"megakernel": {**t, "launches": 1}}
    util["megakernel"] = {"megakernel": mk.utilisation(mk.compute)}
    per_bounce["megakernel"] = [{"bounce": b, "alive": a, "warps": w, "utilisation": u} for b, (a, w, u) in
                                enumerate(zip(mk_bounces["alive"], mk_bounces["warps"], mk_bounces["utilisation"]))]

    counts = trace.alive_counts()
    for name, opts in (WAVEFRONTS if wavefronts is None else wavefronts).items():
        opts = dict(opts)
        tail = opts.pop("tail", None)
        regenerate = opts.pop("regenerate", None)
        # from the first bounce after 0 whose expected ray count is at most the tail's paths (Wavefront.render_frames)
        tail_from = None if not tail else next(
            (b for b in range(1, len(counts)) if 0 < _expected_rays(counts, b, opts.get("schedule", "readback"),
                                                                   trace.slots) <= tail * trace.slots), None)
        if regenerate:  # a pool of a GPU wave's slots, the traced pool standing for it (regenerating_work)
            pool = max(1, int(trace.slots * regenerate))
            wave_scale = GPU_WAVE_SIZE / pool
            launches, info = regenerating_work(trace, c, opts.pop("layout", "soa"), width, gpu.line_bytes, pool,
                                               scale=wave_scale, **opts)
        else:
            wave_scale = scale
            launches, info = wavefront_work(trace, c, opts.pop("layout", "soa"), width, gpu.line_bytes, scale,
                                            tail_from, **opts)
        total_us = 0.0
        ks: dict[str, dict] = {}
        us: dict[str, float] = {}
        ls: dict[str, float] = {}
        for stage, works in launches.items():
            if not works:
                continue
            agg = {"time_us": 0.0, "issue_us": 0.0, "memory_us": 0.0, "critical_us": 0.0, "launches": len(works)}
            compaction = stage.startswith("compact")
            for w in works:
                tt = kernel_time_us(w, occ[stage], gpu, c, wave_scale, scaled_compaction=compaction)
                for k in ("time_us", "issue_us", "memory_us", "critical_us"):
                    agg[k] += tt[k]
            ks[stage] = agg
            total_us += agg["time_us"]
            issue = sum(w.compute for w in works)
            us[stage] = float(sum(w.lane.sum() for w in works) / (width * issue)) if issue else 1.0
            ls[stage] = float(sum(w.lines for w in works)) * (1.0 if compaction else wave_scale)
            ls[stage + ":requests"] = float(sum(w.requests for w in works)) * (1.0 if compaction else wave_scale)
        if regenerate:  # the steady steps' time per path, for a frame's paths; a read of the ray count a step
            first, end = info["window"]
            per_frame = target / (info["paths"] * wave_scale)
            total_us = (total_us + (end - first) * c.readback_us) * per_frame
            for agg in ks.values():  # the kernels' times and lines per frame too
                for k in ("time_us", "issue_us", "memory_us", "critical_us"):
                    agg[k] *= per_frame
            ls = {k: v * per_frame for k, v in ls.items()}
        elif opts.get("schedule", "readback") == "readback":  # pipelined: the host reads behind the device
            total_us += len(info["bounces"]) * c.readback_us
        times[name] = total_us / 1e3
        kernels[name] = ks
        util[name] = us
        per_bounce[name] = info["bounces"] if "bounces" in info else info["steps"]
        lines[name] = ls
    return Prediction(trace.scene, trace.max_depth, width, trace.slots, target, times, kernels, util, per_bounce, lines)


def hand_utilisation(steps: np.ndarray, alive: np.ndarray, width: int = 32) -> float:
    """Lane utilisation of one loop over warps of consecutive lanes: the sum of the active lanes'
    ``steps`` over ``width`` times the sum of each warp's longest (the "max" term of :func:`warp_cost`)."""
    idx, valid = _pack(np.arange(steps.size), width)
    w, l_ = warp_cost([("max", alive[idx], steps[idx].astype(float))], valid)
    return float(l_.sum() / (width * w.sum()))
