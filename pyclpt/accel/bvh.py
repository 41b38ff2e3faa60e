"""Triangle BVH: built by Embree's ``rtcBuildBVH``, flattened for ``cl/scene/bvh.h``.

Layout
------
A BVH of width W = 2, 4 or 8 (``BuildSettings.width``; 8 by default, see docs/bvh.md) whose
child bounds live in the parent. A binary node (W = 2) is 16 32-bit words (64 bytes, one
cache line)::

    [0:3]   left child min xyz      [3:6]   left child max xyz
    [6:9]   right child min xyz     [9:12]  right child max xyz
    [12]    left child link         [13]    right child link     (int32 bits)
    [14:16] zero

A wide node (W = 4 or 8) is 8·W words, eight rows of W, the children's boxes as structure of
arrays so that one work-item tests them together in ``floatW`` arithmetic::

    lo_x[W] hi_x[W] lo_y[W] hi_y[W] lo_z[W] hi_z[W] link[W] zero[W]

A link ``>= 0`` is the index of an internal node. A link with the high bit set
is a leaf: ``start = (link & 0x7fffffff) >> 5``, ``count = link & 31``,
triangles ``tris[start:start + count]``; ``count == 0`` is an empty child
(link ``0x80000000``) whose bounds are ``min=+inf, max=-inf``, never entered.
Node 0 is the root (a single-leaf tree is a root with the leaf as its first child and
empty others). Nodes are in depth-first order, the first child right
after its parent. ``tris`` rows are ``v0, v1-v0, v2-v0`` (9 float32) in leaf
order, in which every subtree's triangles are contiguous; ``tri_order`` maps a
leaf-order slot back to the caller's triangle index.

For width 8 the renderer uploads :func:`leaf_packet_buffer` instead of ``nodes``: the nodes with
their leaf links pointing at packet records of 8 triangles (structure of arrays) appended to them,
which ``cl/scene/bvh.h`` tests 8 at a time (``-DBVH_LEAF_PACKETS=1``, docs/bvh.md "Leaf packets").

Building
--------
Embree's builder calls back for every node and leaf, and Python callbacks cost
about a microsecond each, so they do almost nothing: ``createNode`` returns
the next id of a counter (cast to a pointer, never 0); ``setNodeChildren``
stores the child "pointers" (2 to W) into preallocated lists; ``setNodeBounds`` is a
native no-op (see ``_set_bounds_callback``) because bounds are refitted in
numpy afterwards from the triangles, exactly the unions Embree would pass; and
``createLeaf`` stores nothing: Embree's SAH builder (``RTC_BUILD_QUALITY_MEDIUM``)
partitions the primitive array it is given in place and passes each leaf a
pointer into it, so a leaf is its offset and count, and after the build the
array's ``primID`` column is the leaf order. (Leaves whose pointer lies outside
the array - the Morton builder of ``RTC_BUILD_QUALITY_LOW`` - get their
primitives copied.) The result is checked (a tree reaching every node once,
leaves partitioning the triangles) and flattened with vectorised numpy over the
tree's levels. Building the 871k-triangle dragon takes about 2 CPU-seconds:
1.6 in Embree and its ~650k callbacks, 0.4 in flattening.

Python callbacks serialise on the GIL, so more builder threads only add
contention: pyclpt's Embree device is made with ``threads=1``
(``$PYCLPT_EMBREE_CONFIG`` overrides). TBB's thread limit is process-wide,
though (the largest any live Embree device asked for, e.g. an ``embreex``
scene's); a TBB worker thread that calls back is given a persistent Python
thread state on its first callback, so later callbacks do not create and
destroy one each (without that, builds were about 5x slower on 2 cores; with it,
as fast as single-threaded ones). Builds are deterministic either way.

Build settings (measured)
-------------------------
``bench/timing/bvh_build.py --compare`` on 2 cores of an AMD EPYC VM shared with
other jobs, Embree 4.4 from the embreex wheel, PoCL 3.0 CPU device, 400k
random rays (half from a sphere around the mesh aimed into its box, half from
inside the box in random directions; 52% hit). Build CPU-seconds (the build
is single-threaded) and closest-/any-hit throughput in million rays per
CPU-second of the PoCL threads (wall-clock rates, 1-2.7 Mrays/s on the two
cores, swung with the other jobs); repeat runs differ by about 10%.
"1-16 1/0.35" = leaf sizes 1..16, traversal cost 1, intersection cost 0.35:

===============  =====  ======  =====  =======  ====  =====  ======  =======  ====
setting          bunny, 69k triangles               dragon res2, 202k triangles
---------------  ---------------------------------  --------------------------------
quality, leaves  build  nodes   leaf   closest  any   build  nodes   closest  any
===============  =====  ======  =====  =======  ====  =====  ======  =======  ====
MED 1-2  1/1     0.25   38.1k   1.8    1.33     1.16  0.87   122k    0.99     0.94
MED 1-4  1/1     0.31   37.6k   1.9    1.39     1.23  0.75   107k    0.99     0.92
MED 1-8  1/1     0.25   37.6k   1.9    1.42     1.40  0.75   107k    0.97     0.94
MED 4-8  1/1     0.16   21.3k   3.3    1.39     1.38  0.52    67k    1.11     1.07
MED 1-16 1/0.5   0.18   24.6k   2.8    1.29     1.18  0.52    67k    1.10     1.09
MED 1-16 1/0.35  0.19   16.9k   4.1    1.41     1.34  0.41    49k    1.17     1.15
MED 1-16 1/0.25  0.16   12.4k   5.6    1.43     1.41  0.34    36k    1.15     1.15
MED 1-31 1/0.1   0.07    4.9k  14.2    1.23     1.37  0.22    14k    1.00     1.12
LOW 1-8  1/1     0.52   69.5k   1.0    1.15     1.04  1.60   203k    0.77     0.69
===============  =====  ======  =====  =======  ====  =====  ======  =======  ====

Traversal speed is flat (within the noise) over the SAH settings with average
leaves of 2-6 triangles, lower with 14-triangle leaves and clearly lower with
the Morton builder (LOW, which also builds slowest here: one leaf per
triangle means twice the callbacks). Build time follows the node count. The
default, MEDIUM with leaves of 1..16 and costs 1/0.35, is on the traversal
plateau on both meshes (best on the larger one), builds about 2x faster than
costs 1/1, and keeps leaves at ~4 triangles, a sensible size for GPUs too,
where wide leaves cost SIMT divergence (not measured: no GPU here). The full
dragon (871k triangles, ``--full-dragon``) builds in 2.0 s into 215k nodes.
For scale, the same traversal compiled natively with ``gcc -O2`` ran the bunny
rays at 1.2 Mrays/s on one core: random rays are bound by memory latency and
branch misses rather than arithmetic.
"""
from __future__ import annotations

import ctypes
import itertools
import logging
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from pyclpt.accel import embree
from pyclpt.common import env
from pyclpt.common.cache import cache_path, content_key, save_npz

log = logging.getLogger("pyclpt.accel.bvh")

__all__ = ["FlatBVH", "BuildSettings", "DEFAULT_SETTINGS", "GPU_SETTINGS", "DEVICE_CLASSES", "STACK_DISTANCES",
           "layout_settings", "build_bvh", "build_box_bvh", "leaf_packet_buffer", "LAYOUT_VERSION", "refit_bvh",
           "box_area_ratio", "REBUILD_GROWTH"]

#: Bumped whenever the flattened layout or the build changes meaning.
LAYOUT_VERSION = "bvh-layout-1"

#: Node widths the traversal (cl/scene/bvh.h, ``-DBVH_WIDTH``) implements.
WIDTHS = (2, 4, 8)
#: The width scenes are built with (and cl/scene/bvh.h's default ``BVH_WIDTH``).
DEFAULT_WIDTH = 8
#: Traversal stack entries per width (cl/scene/bvh.h's BVH_STACK_SIZE) and the deepest tree it allows:
#: a node pushes at most width - 1 entries.
STACK_SIZE = {2: 64, 4: 128, 8: 192}

LEAF_BIT = 0x80000000
MAX_LEAF = 31                 # 5-bit count field
MAX_TRIANGLES = 1 << 26       # 26-bit start field
EMPTY_LINK = LEAF_BIT         # start 0, count 0
#: Default (min_leaf, intersection_cost) per width. Width 8 is traversed with leaf packets
#: (8 triangles tested at once, cl/scene/bvh.h BVH_LEAF_PACKETS), which make a triangle test
#: cheaper relative to a node: larger leaves (docs/bvh.md, "Leaf packets").
LEAF_DEFAULTS = {2: (1, 0.35), 4: (1, 0.35), 8: (2, 0.1)}


@dataclass(frozen=True)
class BuildSettings:
    """Embree builder parameters (part of the cache key)."""

    quality: int = embree.RTC_BUILD_QUALITY_MEDIUM
    min_leaf: int = 0         # 0: the width's default (LEAF_DEFAULTS)
    max_leaf: int = 16
    traversal_cost: float = 1.0
    intersection_cost: float = 0.0  # 0: the width's default (LEAF_DEFAULTS)
    max_depth: int = 0        # 0: the deepest the traversal stack allows (60 for width 2)
    width: int = DEFAULT_WIDTH  # children per node: 2, 4 or 8 (module docstring)

    def __post_init__(self) -> None:
        if self.width not in WIDTHS:
            raise ValueError(f"width must be one of {WIDTHS}")
        if self.max_depth == 0:
            object.__setattr__(self, "max_depth", {2: 60, 4: 40, 8: 24}[self.width])
        if self.min_leaf == 0:
            object.__setattr__(self, "min_leaf", LEAF_DEFAULTS[self.width][0])
        if self.intersection_cost == 0.0:
            object.__setattr__(self, "intersection_cost", LEAF_DEFAULTS[self.width][1])
        if not 1 <= self.min_leaf <= self.max_leaf <= MAX_LEAF:
            raise ValueError(f"need 1 <= min_leaf <= max_leaf <= {MAX_LEAF}")
        if self.quality not in (embree.RTC_BUILD_QUALITY_LOW, embree.RTC_BUILD_QUALITY_MEDIUM):
            raise ValueError("quality must be RTC_BUILD_QUALITY_LOW or _MEDIUM")
        deepest = min(60, (STACK_SIZE[self.width] - 2) // (self.width - 1))
        if not 8 <= self.max_depth <= deepest:
            raise ValueError(f"max_depth must be in 8..{deepest} for width {self.width} "
                             f"(the traversal stack holds {STACK_SIZE[self.width]} entries)")


DEFAULT_SETTINGS = BuildSettings()

# The BVH layout per device class (pyclpt.device.context.Device.device_class; docs/bvh.md, "Layouts per
# device class"). CPUs: DEFAULT_SETTINGS (8 wide), leaf packets, a stack of (node, entry distance) pairs.
# GPUs: a binary BVH whose traversal stack holds node indices only (64 ints, 256 bytes a work-item;
# cl/scene/bvh.h -DBVH_STACK_DISTANCES=0), no leaf packets: 46 registers and 256 bytes of stack for the
# intersect stage on sm_90 where the CPU layout takes 125 and 1536 (measured: docs/bvh.md). The settings
# are part of the cache key (repr), so a CPU and a GPU BVH of one mesh are different cache entries.
DEVICE_CLASSES = ("cpu", "gpu")
#: The GPU layout's build settings (binary; leaves of 1..16, as any binary build).
GPU_SETTINGS = BuildSettings(width=2)
#: Whether the traversal stack holds entry distances (cl/scene/bvh.h BVH_STACK_DISTANCES), per device class.
STACK_DISTANCES = {"cpu": True, "gpu": False}


def layout_settings(device_class: str = "cpu") -> BuildSettings:
    """The build settings of ``device_class``'s BVH layout: :data:`DEFAULT_SETTINGS` for ``"cpu"`` (read at
    call time, so that benchmarks may swap it), :data:`GPU_SETTINGS` for ``"gpu"``."""
    if device_class == "cpu":
        return DEFAULT_SETTINGS
    if device_class == "gpu":
        return GPU_SETTINGS
    raise ValueError(f"device_class must be one of {', '.join(DEVICE_CLASSES)}, got {device_class!r}")


@dataclass(frozen=True)
class FlatBVH:
    nodes: np.ndarray      # (N, 8 * width) float32 — layout in the module docstring
    tris: np.ndarray       # (T, 9) float32 in leaf order: v0, v1-v0, v2-v0
    tri_order: np.ndarray  # (T,) int32: leaf-order slot -> original triangle index
    build_seconds: float   # 0 when loaded from cache

    @property
    def node_count(self) -> int:
        return int(self.nodes.shape[0])

    @property
    def triangle_count(self) -> int:
        return int(self.tris.shape[0])

    @property
    def width(self) -> int:
        """Children per node (2, 4 or 8), from the record size: 8 * width floats."""
        return int(self.nodes.shape[1]) // 8

    def children(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every node's child boxes and links, whatever the layout: lo, hi (N, W, 3) float32, links (N, W) int32."""
        N, W = self.node_count, self.width
        if W == 2:
            lo = self.nodes[:, [0, 1, 2, 6, 7, 8]].reshape(N, 2, 3)
            hi = self.nodes[:, [3, 4, 5, 9, 10, 11]].reshape(N, 2, 3)
            links = self.nodes.view(np.int32)[:, 12:14]
        else:
            f = self.nodes.reshape(N, 8, W)
            lo = f[:, [0, 2, 4]].transpose(0, 2, 1)
            hi = f[:, [1, 3, 5]].transpose(0, 2, 1)
            links = f.view(np.int32)[:, 6]
        return lo, hi, links


#: Rows (of ``width`` words) of one leaf packet record (cl/scene/bvh.h, ``BVH_PACKET_ROWS``).
PACKET_ROWS = 10


def leaf_packet_buffer(bvh: FlatBVH) -> np.ndarray:
    """The node buffer of ``-DBVH_LEAF_PACKETS=1`` (wide BVHs only): a flat float32 array.

    The nodes, their leaf links rewritten to ``LEAF_BIT | q << 5 | count`` where ``q`` is the
    leaf's first packet record in units of ``PACKET_ROWS`` rows of ``width`` words from the buffer
    start, then (after zero padding to a record boundary) the packets: per leaf, ``ceil(count /
    width)`` records of ``idx[W] v0x[W] v0y[W] v0z[W] e1x[W] e1y[W] e1z[W] e2x[W] e2y[W] e2z[W]``
    holding the leaf's triangles in leaf order (``idx``: the leaf-order index, int32 bits), the
    last one padded with ``idx = -1`` and all-zero rows (zero edges: det = 0, never hit).
    """
    W, N = bvh.width, bvh.node_count
    if W == 2:
        raise ValueError("leaf packets need a wide BVH (width 4 or 8)")
    nodes = bvh.nodes.reshape(N, 8, W).copy()
    links = nodes.view(np.int32)[:, 6]
    leaf = (links < 0) & ((links & 31) > 0)
    start = (links[leaf] & 0x7FFFFFFF) >> 5
    count = links[leaf] & 31
    npk = (count + W - 1) // W
    first = np.concatenate([[0], np.cumsum(npk)[:-1]]).astype(np.int64)
    base = -(-8 * N // PACKET_ROWS)  # first record after the nodes
    q = base + first
    if q.size and int(q.max()) + int(npk.max()) >= 1 << 26:
        raise ValueError("too many leaf packets for the 26-bit link field")
    links[leaf] = (np.int64(-(1 << 31)) | (q << 5) | count).astype(np.int32)
    P = int(npk.sum())
    packets = np.zeros((P, PACKET_ROWS, W), np.float32)
    pi = packets[:, 0].view(np.int32)
    pi[:] = -1
    # Every leaf triangle: its packet and lane.
    tot = int(count.sum())
    lstart = np.repeat(start, count)
    k = np.arange(tot) - np.repeat(np.concatenate([[0], np.cumsum(count)[:-1]]), count)
    pk = np.repeat(first, count) + k // W
    lane = k % W
    tri = lstart + k
    pi[pk, lane] = tri
    packets[pk, 1:, lane] = bvh.tris[tri]
    pad = np.zeros(base * PACKET_ROWS * W - 8 * N * W, np.float32)
    return np.concatenate([nodes.ravel(), pad, packets.ravel()])


# --------------------------------------------------------------------------
# Input checking


def _prepare(positions: np.ndarray, indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pos = np.asarray(positions)
    idx = np.asarray(indices)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise ValueError(f"positions must have shape (V, 3), got {pos.shape}")
    if idx.size == 0:
        raise ValueError("cannot build a BVH over zero triangles")
    if idx.ndim != 2 or idx.shape[1] != 3:
        raise ValueError(f"indices must have shape (T, 3), got {idx.shape}")
    if not np.issubdtype(idx.dtype, np.integer):
        raise ValueError(f"indices must be integers, got {idx.dtype}")
    if not (np.issubdtype(pos.dtype, np.floating) or np.issubdtype(pos.dtype, np.integer)):
        raise ValueError(f"positions must be numeric, got {pos.dtype}")
    if idx.shape[0] >= MAX_TRIANGLES:
        raise ValueError(f"{idx.shape[0]} triangles: the BVH layout holds at most {MAX_TRIANGLES - 1}")
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    lo, hi = int(idx.min()), int(idx.max())
    if lo < 0 or hi >= pos.shape[0]:
        bad = int(np.flatnonzero(((idx < 0) | (idx >= pos.shape[0])).any(axis=1))[0])
        raise ValueError(
            f"triangle {bad} has vertex index {idx[bad].tolist()} outside 0..{pos.shape[0] - 1}"
        )
    with np.errstate(over="ignore", invalid="ignore"):
        pos32 = np.ascontiguousarray(pos, dtype=np.float32)
    finite_v = np.isfinite(pos32).all(axis=1)
    if not finite_v.all():
        bad_tris = np.flatnonzero(~finite_v[idx].all(axis=1))
        if bad_tris.size:
            t = int(bad_tris[0])
            raise ValueError(
                f"triangle {t} (vertices {idx[t].tolist()}) has a NaN/inf or float32-overflowing "
                f"position; {bad_tris.size} triangle(s) affected"
            )
    return pos32, idx


# --------------------------------------------------------------------------
# Embree build

# OS thread ids that own a persistent Python thread state (see module docstring).
_tstate_threads: set[int] = set()
_tstate_lock = threading.Lock()
try:  # a private function object, so ctypes.pythonapi's own is left as it is
    _PyGILState_Ensure = ctypes.PYFUNCTYPE(ctypes.c_int)(("PyGILState_Ensure", ctypes.pythonapi))
except (AttributeError, OSError):  # not CPython
    _PyGILState_Ensure = None

_FREE_THREADED = not getattr(sys, "_is_gil_enabled", lambda: True)()
_LEAF_TAG = 1 << 62          # marks a leaf "pointer": TAG | byte_offset << 5 | count
_COPY_TAG = 1 << 61          # leaf whose primitives were copied: TAG | copy_id << 5 | count


def _py_set_bounds(node, bounds, n, user):
    pass


def _set_bounds_callback():
    """The setNodeBounds callback: Embree requires one, pyclpt needs none.

    Bounds are refitted in numpy afterwards, so this callback only has to be
    harmless. Rather than paying a Python call per node (about 10% of a
    build), it is a native function that takes no arguments and has no side
    effects, ``int Py_IsInitialized(void)``: on the 64-bit ABIs Embree 4
    supports (x86-64 System V and Windows, AArch64) extra register arguments
    and an unused return value are harmless. ``PYCLPT_BVH_PY_BOUNDS=1`` uses
    a Python no-op instead.
    """
    native = None
    if ctypes.sizeof(ctypes.c_void_p) == 8 and not env.flag("PYCLPT_BVH_PY_BOUNDS"):
        try:
            native = ctypes.cast(ctypes.pythonapi.Py_IsInitialized, ctypes.c_void_p).value
        except (AttributeError, OSError):
            native = None
    if native:
        return ctypes.cast(native, embree.SetNodeBoundsFunc)
    return embree.SetNodeBoundsFunc(_py_set_bounds)


def _embree_build(prims: np.ndarray, settings: BuildSettings):
    """Run rtcBuildBVH over ``prims`` ((T, 8) float32 RTCBuildPrimitive rows, reordered in place).

    Returns (root, n_nodes, kids, copies) where root and kids hold the callback
    "pointers" (internal node id >= 1 or a tagged leaf; node ``i``'s children
    are ``kids[W * i:W * i + W]``, 0 where it has fewer) and copies the
    primitive bytes of copied leaves.
    """
    T = prims.shape[0]
    L = embree.lib()
    dev = embree.device()
    base = prims.ctypes.data
    nbytes = 32 * T
    W = settings.width
    cap = 2 * T + 2
    kids = [0] * (cap * W)   # W child "pointers" per node id (0: no child)
    copies: list[bytes] = []
    counter = itertools.count(1)
    if _FREE_THREADED:
        lock = threading.Lock()
        _next = counter.__next__

        def next_id() -> int:
            with lock:
                return _next()
    else:
        next_id = counter.__next__  # atomic under the GIL

    get_ident = threading.get_ident
    known = _tstate_threads
    caller = get_ident()
    ensure = _PyGILState_Ensure

    def adopt_thread() -> None:
        # First callback on a foreign (TBB) thread: keep its Python thread state alive.
        t = get_ident()
        with _tstate_lock:
            if t in known:
                return
            known.add(t)
        if ensure is not None and t != caller:
            ensure()

    errors: list[BaseException] = []

    # The callbacks run once per node or leaf (about T/2 times each), so they
    # do as little as possible: no allocation, no ctypes calls on the hot path.
    def create_node(alloc, n, user, _next=next_id, _w=W):
        if not 2 <= n <= _w:
            errors.append(RuntimeError(f"Embree created a node with {n} children"))
        return _next()

    if W == 2:
        def set_children(node, ch, n, user, _k=kids):
            _k[2 * node] = ch[0]
            _k[2 * node + 1] = ch[1]
    else:
        def set_children(node, ch, n, user, _k=kids, _w=W):
            _k[_w * node:_w * node + n] = ch[:n]

    # Leaf primitives are copied only when the pointer is not into our array
    # (the Morton builder of RTC_BUILD_QUALITY_LOW passes a local copy, and
    # older Embree versions pointed into the unsorted input); rare, so locked.
    in_place = settings.quality == embree.RTC_BUILD_QUALITY_MEDIUM
    copy_lock = threading.Lock()

    def create_leaf(alloc, p, n, user, _known=known, _gi=get_ident, _base=base, _nb=nbytes,
                    _in_place=in_place):
        # Every builder thread creates leaves, so this is where a foreign
        # thread is first seen (a few createNode calls before it are merely slower).
        if _gi() not in _known:
            adopt_thread()
        if n > MAX_LEAF:
            errors.append(RuntimeError(f"Embree created a leaf of {n} primitives"))
        off = (p or 0) - _base
        if _in_place and 0 <= off < _nb:
            return _LEAF_TAG | off << 5 | n
        with copy_lock:
            copies.append(ctypes.string_at(p, 32 * n))
            cid = len(copies) - 1
        return _COPY_TAG | cid << 5 | n

    callbacks = (
        embree.CreateNodeFunc(create_node),
        embree.SetNodeChildrenFunc(set_children),
        _set_bounds_callback(),
        embree.CreateLeafFunc(create_leaf),
    )
    args = embree.default_build_arguments()
    args.buildQuality = settings.quality
    args.maxBranchingFactor = W
    args.maxDepth = settings.max_depth
    args.sahBlockSize = 1
    args.minLeafSize = settings.min_leaf
    args.maxLeafSize = settings.max_leaf
    args.traversalCost = settings.traversal_cost
    args.intersectionCost = settings.intersection_cost
    args.primitives = base
    args.primitiveCount = T
    args.primitiveArrayCapacity = T
    args.createNode, args.setNodeChildren, args.setNodeBounds, args.createLeaf = callbacks

    bvh = L.rtcNewBVH(dev)
    if not bvh:
        embree.check_error(dev, "rtcNewBVH")
        raise embree.EmbreeError("rtcNewBVH returned NULL")
    try:
        args.bvh = bvh
        root = L.rtcBuildBVH(ctypes.byref(args))
        embree.check_error(dev, "rtcBuildBVH")
        if not root:
            raise embree.EmbreeError("rtcBuildBVH returned NULL")
    finally:
        L.rtcReleaseBVH(bvh)
        del callbacks  # kept alive until here
    if errors:
        raise embree.EmbreeError(str(errors[0]))
    n_nodes = next_id() - 1
    return int(root), n_nodes, kids, copies


# --------------------------------------------------------------------------
# Flattening


def _flatten(root: int, n_nodes: int, kids: list, W: int, copies: list[bytes],
             prims: np.ndarray, tri9: np.ndarray, prim_lo: np.ndarray,
             prim_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    T = prims.shape[0]
    if root & (_LEAF_TAG | _COPY_TAG):
        # Root is a single leaf: one node holding it, its other children empty.
        child = np.zeros((1, W), dtype=np.uint64)
        child[0, 0] = root
        n_int = 1
        root_idx = 0
    else:
        n_int = n_nodes
        child = np.array(kids[W:W * (n_int + 1)], dtype=np.uint64).reshape(n_int, W)
        root_idx = root - 1
    # Child references: internal -> node index (>= 0); leaf -> ~leaf index (< 0).
    # Missing children (0: a node with fewer than W) become empty leaves (count 0).
    tags = child >> np.uint64(61)
    is_leaf = (tags != 0) | (child == 0)
    leaf_raw = child[is_leaf]
    n_leaf = leaf_raw.size
    ref = np.empty((n_int, W), dtype=np.int64)
    ref[~is_leaf] = child[~is_leaf].astype(np.int64) - 1
    ref[is_leaf] = ~np.arange(n_leaf, dtype=np.int64)
    if np.any(ref[~is_leaf] >= n_int) or np.any(ref[~is_leaf] < 0) or not 0 <= root_idx < n_int:
        raise embree.EmbreeError("Embree returned an inconsistent tree")

    leaf_count = (leaf_raw & np.uint64(31)).astype(np.int64)
    leaf_is_copy = (leaf_raw >> np.uint64(61)) == 1
    leaf_payload = ((leaf_raw & np.uint64((1 << 61) - 1)) >> np.uint64(5)).astype(np.int64)

    # Levels, top-down from the root.
    levels = []
    frontier = np.array([root_idx], dtype=np.int64)
    seen = 0
    while frontier.size:
        levels.append(frontier)
        seen += frontier.size
        if seen > n_int or len(levels) > 64:
            raise embree.EmbreeError("Embree returned a tree with a cycle or too deep")
        c = ref[frontier].ravel()
        frontier = c[c >= 0]
    if seen != n_int:
        raise embree.EmbreeError(f"tree reaches {seen} of {n_int} nodes")

    # Subtree sizes counting leaves as nodes (bottom-up) -> depth-first preorder.
    size = np.zeros(n_int, dtype=np.int64)
    for lev in reversed(levels):
        r = ref[lev]
        s = np.where(r >= 0, size[np.maximum(r, 0)], 1)
        size[lev] = 1 + s.sum(axis=1)
    pre = np.zeros(n_int, dtype=np.int64)
    leaf_pre = np.zeros(n_leaf, dtype=np.int64)
    for lev in levels:
        r = ref[lev]
        s = np.where(r >= 0, size[np.maximum(r, 0)], 1)
        pos = pre[lev][:, None] + 1 + np.cumsum(s, axis=1) - s   # children in order after the parent
        internal = r >= 0
        pre[r[internal]] = pos[internal]
        leaf_pre[~r[~internal]] = pos[~internal]
    node_order = np.argsort(pre, kind="stable")      # new index -> old index
    node_rank = np.empty(n_int, dtype=np.int64)
    node_rank[node_order] = np.arange(n_int)

    if int(leaf_count.sum()) != T:
        raise embree.EmbreeError(f"leaves hold {int(leaf_count.sum())} primitives, expected {T}")
    nonempty = leaf_count > 0
    if not leaf_is_copy[nonempty].any():
        # In-place build: the leaves are slices of Embree's reordered primitive
        # array (each subtree contiguous), which becomes the leaf order as is.
        leaf_start = np.where(nonempty, leaf_payload >> 5, 0)
        order = np.argsort(leaf_start[nonempty], kind="stable")
        st = leaf_start[nonempty][order]
        en = st + leaf_count[nonempty][order]
        if st[0] != 0 or en[-1] != T or not np.array_equal(st[1:], en[:-1]):
            raise embree.EmbreeError("Embree's leaves do not partition the primitive array")
        src_slot = prims.view(np.uint32)[:, 7].astype(np.int64)
        lo_sorted = prims[:, 0:3]
        hi_sorted = prims[:, 4:7]
    else:
        # Copied leaves: lay them out in depth-first order.
        leaf_order = np.argsort(leaf_pre, kind="stable")
        counts = leaf_count[leaf_order]
        starts_dfs = np.zeros(n_leaf, dtype=np.int64)
        np.cumsum(counts[:-1], out=starts_dfs[1:])
        leaf_start = np.empty(n_leaf, dtype=np.int64)
        leaf_start[leaf_order] = starts_dfs
        # Source of each leaf's primitive ids: the reordered array (in place)
        # or the concatenated copies, appended after it.
        final_ids = prims.view(np.uint32)[:, 7]
        copied = np.frombuffer(b"".join(copies), dtype=np.uint32).reshape(-1, 8)[:, 7]
        copy_off = np.zeros(len(copies) + 1, dtype=np.int64)
        np.cumsum([len(c) // 32 for c in copies], out=copy_off[1:])
        source = np.concatenate([final_ids, copied]).astype(np.int64)
        src_base = np.where(leaf_is_copy, T + copy_off[np.where(leaf_is_copy, leaf_payload, 0)],
                            leaf_payload >> 5)
        ne = np.flatnonzero(nonempty)
        cnt = leaf_count[ne]
        within = np.arange(T, dtype=np.int64) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        src_slot = np.empty(T, dtype=np.int64)
        src_slot[np.repeat(leaf_start[ne], cnt) + within] = source[np.repeat(src_base[ne], cnt) + within]
        lo_sorted = prim_lo[src_slot]
        hi_sorted = prim_hi[src_slot]
    if not np.array_equal(np.bincount(src_slot, minlength=T), np.ones(T, dtype=np.int64)):
        raise embree.EmbreeError("Embree's leaves do not cover every triangle exactly once")

    # Leaf bounds from the (leaf-order) triangle bounds; empty leaves stay inverted.
    leaf_lo = np.full((n_leaf, 3), np.inf, dtype=np.float32)
    leaf_hi = np.full((n_leaf, 3), -np.inf, dtype=np.float32)
    ne = np.flatnonzero(nonempty)
    by_start = ne[np.argsort(leaf_start[ne], kind="stable")]
    leaf_lo[by_start] = np.minimum.reduceat(lo_sorted, leaf_start[by_start], axis=0)
    leaf_hi[by_start] = np.maximum.reduceat(hi_sorted, leaf_start[by_start], axis=0)
    leaf_link = np.where(leaf_count > 0, LEAF_BIT | (leaf_start << 5) | leaf_count,
                         EMPTY_LINK).astype(np.uint32)

    # Internal bounds, bottom-up.
    node_lo = np.empty((n_int, 3), dtype=np.float32)
    node_hi = np.empty((n_int, 3), dtype=np.float32)
    for lev in reversed(levels):
        r = ref[lev]
        clo = np.where((r >= 0)[..., None], node_lo[np.maximum(r, 0)], leaf_lo[np.maximum(~r, 0)])
        chi = np.where((r >= 0)[..., None], node_hi[np.maximum(r, 0)], leaf_hi[np.maximum(~r, 0)])
        node_lo[lev] = clo.min(axis=1)
        node_hi[lev] = chi.max(axis=1)

    # Records in DFS order.
    r = ref[node_order]
    internal = r >= 0
    safe_int = np.maximum(r, 0)
    safe_leaf = np.maximum(~r, 0)
    clo = np.where(internal[..., None], node_lo[safe_int], leaf_lo[safe_leaf])
    chi = np.where(internal[..., None], node_hi[safe_int], leaf_hi[safe_leaf])
    links = np.where(internal, node_rank[safe_int].astype(np.uint32), leaf_link[safe_leaf])
    nodes = np.zeros((n_int, 8 * W), dtype=np.float32)
    if W == 2:
        nodes[:, 0:3] = clo[:, 0]
        nodes[:, 3:6] = chi[:, 0]
        nodes[:, 6:9] = clo[:, 1]
        nodes[:, 9:12] = chi[:, 1]
        nodes.view(np.uint32)[:, 12:14] = links
    else:  # SoA: lo_x[W] hi_x[W] lo_y[W] hi_y[W] lo_z[W] hi_z[W] link[W] zero[W]
        f = nodes.reshape(n_int, 8, W)
        f[:, 0:6:2] = clo.transpose(0, 2, 1)
        f[:, 1:6:2] = chi.transpose(0, 2, 1)
        f.view(np.uint32)[:, 6] = links

    tris = np.take(tri9, src_slot, axis=0)
    return nodes, tris, src_slot.astype(np.int32)


def _build(pos32: np.ndarray, idx: np.ndarray, settings: BuildSettings) -> FlatBVH:
    start = time.perf_counter()
    tri9, prim_lo, prim_hi = _triangles(pos32, idx)  # in input order
    prims = _build_prims(prim_lo, prim_hi)
    root, n_nodes, kids, copies = _embree_build(prims, settings)
    nodes, tris, tri_order = _flatten(root, n_nodes, kids, settings.width, copies, prims, tri9,
                                      prim_lo, prim_hi)
    return FlatBVH(nodes=nodes, tris=tris, tri_order=tri_order,
                   build_seconds=time.perf_counter() - start)


def _build_prims(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Embree's build primitives (RTCBuildPrimitive: lower xyz, geomID, upper xyz, primID) of boxes lo, hi."""
    prims = np.zeros((lo.shape[0], 8), dtype=np.float32)
    prims[:, 0:3] = lo
    prims[:, 4:7] = hi
    prims.view(np.uint32)[:, 7] = np.arange(lo.shape[0], dtype=np.uint32)
    return prims


def _cache_entry_problem(nodes: np.ndarray, tris: np.ndarray, order: np.ndarray, pos32: np.ndarray,
                         idx: np.ndarray, width: int) -> str | None:
    """None when a loaded cache entry is a BVH of this mesh the renderer can use, else what is wrong:
    shapes and dtypes, ``tri_order`` a permutation of the triangles, ``tris`` the mesh's triangles
    in that order, node boxes free of NaN (infinite only for empty children), links in range (an
    internal link after its parent: no cycles, leaves within ``tris``)."""
    T = idx.shape[0]
    if not (nodes.dtype == np.float32 and nodes.ndim == 2 and nodes.shape[0] >= 1 and nodes.shape[1] == 8 * width):
        return f"nodes: expected (N >= 1, {8 * width}) float32, got {nodes.shape} {nodes.dtype}"
    if not (tris.dtype == np.float32 and tris.shape == (T, 9)):
        return f"tris: expected ({T}, 9) float32, got {tris.shape} {tris.dtype}"
    if not (order.dtype == np.int32 and order.shape == (T,)):
        return f"tri_order: expected ({T},) int32, got {order.shape} {order.dtype}"
    if order.min() < 0 or order.max() >= T or np.any(np.bincount(order, minlength=T) != 1):
        return f"tri_order is not a permutation of the {T} triangles (values {int(order.min())}..{int(order.max())})"
    i = idx[order]
    v0 = pos32[i[:, 0]]
    with np.errstate(over="ignore", invalid="ignore"):
        expected = np.concatenate([v0, pos32[i[:, 1]] - v0, pos32[i[:, 2]] - v0], axis=1)
    if not np.array_equal(tris, expected):
        return "tris do not match the mesh's triangles in tri_order"
    bvh = FlatBVH(nodes=nodes, tris=tris, tri_order=order, build_seconds=0.0)
    lo, hi, links = bvh.children()
    if np.isnan(lo).any() or np.isnan(hi).any():
        bad = np.isnan(lo).any(axis=(1, 2)) | np.isnan(hi).any(axis=(1, 2))
        return f"node {int(np.flatnonzero(bad)[0])} has NaN bounds"
    N = bvh.node_count
    links64 = links.astype(np.int64)
    leaf = links64 < 0
    empty = links64 == np.iinfo(np.int32).min
    full = ~empty
    if not (np.isfinite(lo[full]).all() and np.isfinite(hi[full]).all()):
        return "a non-empty child has infinite bounds"
    parent = np.broadcast_to(np.arange(N)[:, None], links64.shape)
    inner = ~leaf
    if np.any(links64[inner] <= parent[inner]) or np.any(links64[inner] >= N):
        return f"an internal link is outside nodes 1..{N - 1} or not after its parent"
    bits = links64[leaf & full] & 0x7FFFFFFF
    if np.any((bits >> 5) + (bits & 31) > T):
        return f"a leaf reaches past the {T} triangles"
    return None


def build_bvh(positions: np.ndarray, indices: np.ndarray, *, use_cache: bool = True,
              settings: BuildSettings | None = None) -> FlatBVH:
    """Build (or load from the disk cache) the flattened BVH of a triangle mesh.

    ``positions`` (V, 3) and ``indices`` (T, 3). Raises ValueError for zero
    triangles, out-of-range indices, or NaN/inf positions (naming a triangle);
    degenerate triangles are fine. ``settings`` overrides the Embree build
    parameters (default :data:`DEFAULT_SETTINGS`).
    """
    settings = settings or DEFAULT_SETTINGS
    pos32, idx = _prepare(positions, indices)
    if not use_cache:
        return _build(pos32, idx, settings)
    key = content_key(pos32, idx, repr(settings), LAYOUT_VERSION)
    path = cache_path("bvh", key)
    if path is None:  # the cache folder cannot be used (warned once): build uncached
        return _build(pos32, idx, settings)
    if path.is_file():
        try:
            with np.load(path, allow_pickle=False) as z:
                nodes, tris, order = z["nodes"], z["tris"], z["tri_order"]
            problem = _cache_entry_problem(nodes, tris, order, pos32, idx, settings.width)
            if problem is None:
                return FlatBVH(nodes=nodes, tris=tris, tri_order=order, build_seconds=0.0)
            log.warning("ignoring malformed BVH cache entry %s (%s); rebuilding", path, problem)
        except Exception as exc:  # corrupt or truncated file: rebuild
            log.warning("ignoring unreadable BVH cache entry %s (%s)", path, exc)
    bvh = _build(pos32, idx, settings)
    try:
        save_npz(path, nodes=bvh.nodes, tris=bvh.tris, tri_order=bvh.tri_order)
    except OSError as exc:
        log.warning("could not write BVH cache entry %s (%s)", path, exc)
    return bvh


def _triangles(pos32: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``tri9`` (v0, v1 - v0, v2 - v0) and the boxes of triangles ``idx``: over the vertices and over
    v0 + e1, v0 + e2 as the traversal forms them, so that a box contains exactly what the intersector can
    hit. ValueError naming the first triangle (its row in ``idx``) whose edge vectors overflow float32."""
    T = idx.shape[0]
    tri9 = np.empty((T, 9), dtype=np.float32)
    v0, e1, e2 = tri9[:, 0:3], tri9[:, 3:6], tri9[:, 6:9]
    np.take(pos32, idx[:, 0], axis=0, out=v0)
    v1 = np.take(pos32, idx[:, 1], axis=0)
    v2 = np.take(pos32, idx[:, 2], axis=0)
    np.subtract(v1, v0, out=e1)
    np.subtract(v2, v0, out=e2)
    with np.errstate(over="ignore", invalid="ignore"):
        a1 = v0 + e1
        a2 = v0 + e2
    prim_lo = np.minimum(np.minimum(np.minimum(v0, v1), np.minimum(v2, a1)), a2)
    prim_hi = np.maximum(np.maximum(np.maximum(v0, v1), np.maximum(v2, a1)), a2)
    if not (np.isfinite(prim_lo).all() and np.isfinite(prim_hi).all()):
        bad = int(np.flatnonzero(~(np.isfinite(prim_lo) & np.isfinite(prim_hi)).all(axis=1))[0])
        raise ValueError(f"triangle {bad}: edge vectors overflow float32")
    return tri9, prim_lo, prim_hi


def _levels(links: np.ndarray) -> list[np.ndarray]:
    """The nodes of a flattened tree by depth, from the root (node 0) down."""
    levels, frontier = [], np.zeros(1, dtype=np.int64)
    while frontier.size:
        levels.append(frontier)
        c = links[frontier].ravel().astype(np.int64)
        frontier = c[c >= 0]
    return levels


def refit_bvh(bvh: FlatBVH, positions: np.ndarray, indices: np.ndarray) -> FlatBVH:
    """``bvh``'s tree over the same triangles at new ``positions``: the same nodes, leaves and leaf order,
    every box recomputed bottom-up from the triangles (what a build would have put in it for that tree).
    With unchanged positions the result is ``bvh`` bit for bit. The tree was chosen for the old positions:
    after large moves it is slower to traverse than a new build (:func:`box_area_ratio` measures it).
    About 0.2 s for the 871k-triangle dragon against 1.2 s for a build (docs/bvh.md, "Refitting")."""
    start = time.perf_counter()
    pos32, idx = _prepare(positions, indices)
    if idx.shape[0] != bvh.triangle_count:
        raise ValueError(f"refit: the BVH holds {bvh.triangle_count} triangles, the mesh {idx.shape[0]}")
    order = bvh.tri_order.astype(np.int64)
    try:
        tri9, lo_sorted, hi_sorted = _triangles(pos32, idx[order])
    except ValueError as exc:  # name the caller's triangle, not the leaf-order slot
        slot = int(str(exc).split(":")[0].split()[1])
        raise ValueError(f"triangle {int(order[slot])}: edge vectors overflow float32") from None
    N, W = bvh.node_count, bvh.width
    _, _, links = bvh.children()
    links = links.astype(np.int64)
    leaf = links < 0
    count = np.where(leaf, links & 31, 0)
    first = np.where(leaf, (links & 0x7FFFFFFF) >> 5, 0)
    lo = np.full((N, W, 3), np.inf, dtype=np.float32)
    hi = np.full((N, W, 3), -np.inf, dtype=np.float32)
    full = count > 0
    by_start = np.argsort(first[full], kind="stable")
    starts = first[full][by_start]
    leaf_lo = np.empty((starts.size, 3), np.float32)
    leaf_hi = np.empty((starts.size, 3), np.float32)
    leaf_lo[by_start] = np.minimum.reduceat(lo_sorted, starts, axis=0)
    leaf_hi[by_start] = np.maximum.reduceat(hi_sorted, starts, axis=0)
    lo[full], hi[full] = leaf_lo, leaf_hi
    for lev in reversed(_levels(links)):  # a node's box: the union of its children's, children first
        r = links[lev]
        inner = r >= 0
        rows, cols = np.nonzero(inner)
        lo[lev[rows], cols] = lo[r[inner]].min(axis=1)
        hi[lev[rows], cols] = hi[r[inner]].max(axis=1)
    nodes = bvh.nodes.copy()
    if W == 2:
        nodes[:, 0:3], nodes[:, 3:6] = lo[:, 0], hi[:, 0]
        nodes[:, 6:9], nodes[:, 9:12] = lo[:, 1], hi[:, 1]
    else:
        f = nodes.reshape(N, 8, W)
        f[:, 0:6:2] = lo.transpose(0, 2, 1)
        f[:, 1:6:2] = hi.transpose(0, 2, 1)
    return FlatBVH(nodes=nodes, tris=tri9, tri_order=bvh.tri_order, build_seconds=time.perf_counter() - start)


def box_area_ratio(bvh: FlatBVH) -> float:
    """The surface areas of every non-empty child box summed, over the root's: the SAH's traversal cost
    of the tree up to its constants, independent of the scene's scale. Refitting a tree after its
    triangles moved far from where it was built makes it grow (boxes overlap); pyclpt builds again when it
    has grown by :data:`REBUILD_GROWTH` (pyclpt.buffers.scene.SceneBuffers.refresh_geometry)."""
    lo, hi, links = bvh.children()
    full = (links >= 0) | ((links & 31) > 0)
    ext = np.where(full[..., None], hi.astype(np.float64) - lo, 0.0)
    area = 2 * (ext[..., 0] * ext[..., 1] + ext[..., 1] * ext[..., 2] + ext[..., 2] * ext[..., 0])
    rlo = np.where(full[0, :, None], lo[0], np.inf).min(0).astype(np.float64)
    rhi = np.where(full[0, :, None], hi[0], -np.inf).max(0).astype(np.float64)
    e = rhi - rlo
    root = 2 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0])
    return float(area.sum() / root) if root > 0 else 1.0


#: How much a refitted tree's :func:`box_area_ratio` may grow over the built one's before a new build.
REBUILD_GROWTH = 1.5


def build_box_bvh(lo: np.ndarray, hi: np.ndarray, settings: BuildSettings) -> tuple[np.ndarray, np.ndarray, float]:
    """A BVH over boxes (the top level of instancing, :mod:`pyclpt.accel.instances`): ``lo``, ``hi`` (N, 3)
    finite boxes. Returns the nodes (the layout of :class:`FlatBVH`, leaves' starts index the boxes in leaf
    order), the leaf order (leaf-order slot -> box index) and the build seconds. Not cached (a few
    hundred boxes build in milliseconds)."""
    start = time.perf_counter()
    lo = np.ascontiguousarray(lo, np.float32).reshape(-1, 3)
    hi = np.ascontiguousarray(hi, np.float32).reshape(-1, 3)
    N = lo.shape[0]
    if N == 0 or not (np.isfinite(lo).all() and np.isfinite(hi).all() and (lo <= hi).all()):
        raise ValueError("build_box_bvh needs one or more finite boxes with lo <= hi")
    if N >= MAX_TRIANGLES:
        raise ValueError(f"{N} boxes: the BVH layout holds at most {MAX_TRIANGLES - 1}")
    prims = _build_prims(lo, hi)
    root, n_nodes, kids, copies = _embree_build(prims, settings)
    nodes, _, order = _flatten(root, n_nodes, kids, settings.width, copies, prims,
                               np.zeros((N, 9), np.float32), lo, hi)
    return nodes, order, time.perf_counter() - start
