"""Two-level BVH for instancing (Mitsuba ``shapegroup`` + ``instance``; docs/bvh.md "Instances").

Bottom level: one :class:`~pyclpt.accel.bvh.FlatBVH` per shapegroup (built once and cached like any
BVH, by :func:`~pyclpt.accel.bvh.build_bvh`) and one for the scene's plain meshes; :func:`merge_bvhs`
puts them into one node array and one triangle array (links relocated), so that every triangle has
one global leaf-order index and the kernels' per-triangle arrays work unchanged.

Top level: a BVH of the same width over the instances' world boxes (:func:`~pyclpt.accel.bvh.build_box_bvh`,
leaves of one instance), whose leaves index instance records (``INST_STRIDE`` float32 words, in the
top level's leaf order), mirrored by ``cl/scene/instances.h``::

    [0:12]  world-to-object, 3x4 row-major (rays go to object space: same t in both)
    [12:24] object-to-world, 3x4 row-major (hit points)
    [24:33] inverse transpose of the object-to-world 3x3, row-major (normals)
    [33]    node index of the instance's bottom-level root (int32 bits)
    [34:36] zero

The plain meshes are one more instance, with the identity transform (exact: x * 1 + y * 0 ... = x).
The node buffer of an instanced scene (:func:`instanced_node_buffer`) is a header node (node 0: the
top level's root, the records' first word and the packed hit id's triangle bits, as int32, so that one
program serves every instanced scene), the merged bottom levels (with their leaf packets for width 8),
zero padding to a node boundary, the top-level nodes (links relocated), then the records.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pyclpt.accel.bvh import (
    EMPTY_LINK,
    MAX_TRIANGLES,
    BuildSettings,
    FlatBVH,
    build_box_bvh,
    leaf_packet_buffer,
)

__all__ = ["HEADER_RECORDS", "HEADER_ROOT", "HEADER_TRI_BITS", "INST_STRIDE", "InstancedBVH", "build_instanced",
           "instanced_node_buffer", "merge_bvhs"]

#: Words of an instance record (cl/scene/instances.h INST_STRIDE).
INST_STRIDE = 36
INST_W2O, INST_O2W, INST_NORMAL, INST_ROOT = 0, 12, 24, 33


def _links(nodes: np.ndarray, width: int) -> np.ndarray:
    """A writable int32 view of the link words of (N, 8 * width) nodes."""
    if width == 2:
        return nodes.view(np.int32)[:, 12:14]
    return nodes.reshape(nodes.shape[0], 8, width).view(np.int32)[:, 6]


def _relocate(nodes: np.ndarray, width: int, node_off: int, tri_off: int) -> np.ndarray:
    out = nodes.copy()
    links = _links(out, width)
    internal = links >= 0
    leaf = (links < 0) & ((links & 31) > 0)
    links[internal] += node_off
    start = ((links[leaf] & 0x7FFFFFFF) >> 5).astype(np.int64) + tri_off
    links[leaf] = (np.int64(-(1 << 31)) | (start << 5) | (links[leaf] & 31)).astype(np.int32)
    return out


def _empty_nodes(n: int, width: int) -> np.ndarray:
    """n nodes of empty children only (inverted boxes, EMPTY_LINK links)."""
    nodes = np.zeros((n, 8 * width), np.float32)
    if width == 2:
        nodes[:, 0:6] = nodes[:, 6:12] = np.repeat([[np.inf] * 3 + [-np.inf] * 3], n, 0).astype(np.float32)
    else:
        f = nodes.reshape(n, 8, width)
        f[:, 0:6:2], f[:, 1:6:2] = np.inf, -np.inf
    _links(nodes, width)[:] = np.int64(EMPTY_LINK).astype(np.uint32).view(np.int32)
    return nodes


def merge_bvhs(bvhs: list[FlatBVH], reserve: int = 0) -> tuple[FlatBVH, np.ndarray, np.ndarray]:
    """The BVHs in one node array and one triangle array, after ``reserve`` empty nodes: (merged, root node
    of each, first leaf-order triangle of each). ``tri_order`` of the merged BVH maps to the concatenation of
    the inputs' triangles."""
    width = bvhs[0].width
    if any(b.width != width for b in bvhs):
        raise ValueError("merge_bvhs: every BVH must have the same width")
    nodes, tris, order = [_empty_nodes(reserve, width)], [], []
    roots = np.zeros(len(bvhs), np.int64)
    firsts = np.zeros(len(bvhs), np.int64)
    n_off, t_off = reserve, 0
    for k, b in enumerate(bvhs):
        roots[k], firsts[k] = n_off, t_off
        nodes.append(_relocate(b.nodes, width, n_off, t_off))
        tris.append(b.tris)
        order.append(b.tri_order.astype(np.int64) + t_off)
        n_off += b.node_count
        t_off += b.triangle_count
    if t_off >= MAX_TRIANGLES:
        raise ValueError(f"{t_off} triangles in all shapegroups and meshes: the BVH layout holds at most "
                         f"{MAX_TRIANGLES - 1}")
    merged = FlatBVH(nodes=np.concatenate(nodes), tris=np.concatenate(tris),
                     tri_order=np.concatenate(order).astype(np.int32),
                     build_seconds=sum(b.build_seconds for b in bvhs))
    return merged, roots, firsts


@dataclass(frozen=True)
class InstancedBVH:
    """Both levels: the merged bottom levels, the top level and the instance records."""

    blas: FlatBVH            # merged bottom levels (merge_bvhs)
    tlas_nodes: np.ndarray   # (N, 8 * width) float32; internal links relative to the top level's root (0)
    records: np.ndarray      # (I, INST_STRIDE) float32 in the top level's leaf order
    order: np.ndarray        # (I,) int32: record -> instance index (as given to build_instanced)
    bounds: np.ndarray       # (2, 3) world bounds of every instance
    tlas_seconds: float

    @property
    def width(self) -> int:
        return self.blas.width

    @property
    def tri_bits(self) -> int:
        """Bits of a hit's packed id that hold the triangle (the rest: the record; cl/scene/instances.h)."""
        return max(1, int(self.blas.triangle_count - 1).bit_length())


def _world_boxes(blas: FlatBVH, roots: np.ndarray, which: np.ndarray,
                 to_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World boxes of the instances: the corners of their bottom level's boxes two levels below the root
    (at most W² boxes, each holding its triangles as the intersector forms them) through to_world, padded
    by a relative 1e-5 against rounding. Conservative, and far cheaper than transforming every vertex."""
    lo_all, hi_all, links = blas.children()
    corners = {}
    for b in np.unique(which):
        node = int(roots[b])
        boxes = []
        for c in range(blas.width):
            link = int(links[node, c])
            if link >= 0:  # an internal child: its children's boxes
                keep = np.all(lo_all[link] <= hi_all[link], axis=1)
                boxes.extend(zip(lo_all[link][keep], hi_all[link][keep]))
            elif np.all(lo_all[node, c] <= hi_all[node, c]):
                boxes.append((lo_all[node, c], hi_all[node, c]))
        lo = np.array([x for x, _ in boxes], np.float64)
        hi = np.array([y for _, y in boxes], np.float64)
        sel = np.array([[(k >> a) & 1 for a in range(3)] for k in range(8)], bool)  # the 8 corners
        corners[int(b)] = np.where(sel[None], hi[:, None], lo[:, None]).reshape(-1, 3)
    lo = np.empty((len(which), 3))
    hi = np.empty((len(which), 3))
    for k, (b, m) in enumerate(zip(which, to_world)):
        w = corners[int(b)] @ m[:3, :3].T + m[:3, 3]
        lo[k], hi[k] = w.min(0), w.max(0)
    pad = 1e-5 * np.maximum(np.abs(lo), np.abs(hi)).max(1, keepdims=True) + 1e-30
    return lo - pad, hi + pad


def build_instanced(bvhs: list[FlatBVH], which: np.ndarray, to_world: np.ndarray,
                    settings: BuildSettings | None = None) -> InstancedBVH:
    """The two-level BVH of instances ``k`` of bottom level ``which[k]`` placed by ``to_world[k]`` (4x4,
    invertible). ``settings``: the top level's build (default: the bottom levels' width, leaves of 1)."""
    blas, roots, _ = merge_bvhs(bvhs, reserve=1)  # node 0: the header (instanced_node_buffer)
    W = blas.width
    which = np.asarray(which, np.int64)
    to_world = np.asarray(to_world, np.float64).reshape(-1, 4, 4)
    lo, hi = _world_boxes(blas, roots, which, to_world)
    settings = settings or BuildSettings(width=W, min_leaf=1, max_leaf=1, intersection_cost=1.0)
    tlas, order, seconds = build_box_bvh(lo, hi, settings)
    records = np.zeros((len(which), INST_STRIDE), np.float32)
    for r, k in enumerate(order):
        m = to_world[k]
        inv = np.linalg.inv(m)
        records[r, INST_W2O:INST_W2O + 12] = inv[:3, :4].ravel()
        records[r, INST_O2W:INST_O2W + 12] = m[:3, :4].ravel()
        records[r, INST_NORMAL:INST_NORMAL + 9] = inv[:3, :3].T.ravel()
        records.view(np.int32)[r, INST_ROOT] = roots[which[k]]
    bits = max(1, int(blas.triangle_count - 1).bit_length())
    if len(which) > 1 << (31 - bits):
        raise ValueError(f"{len(which)} instances of {blas.triangle_count} triangles: a hit's packed id "
                         f"(triangle in {bits} bits, instance in {31 - bits}) holds at most {1 << (31 - bits)} "
                         "instances")
    return InstancedBVH(blas=blas, tlas_nodes=tlas, records=records, order=order.astype(np.int32),
                        bounds=np.stack([lo.min(0), hi.max(0)]).astype(np.float32), tlas_seconds=seconds)


#: Words of the node buffer's header (node 0 of an instanced scene; cl/scene/instances.h INST_HEADER_*).
HEADER_ROOT, HEADER_RECORDS, HEADER_TRI_BITS = 0, 1, 2


def instanced_node_buffer(inst: InstancedBVH, packets: bool) -> tuple[np.ndarray, int, int]:
    """The node buffer of an instanced scene (module docstring): (buffer, the top level's root node
    index, the records' first word). Its first words (node 0, which no traversal visits) are the header
    the kernels read: the root, the records' first word and the packed id's triangle bits (int32)."""
    W = inst.width
    base = leaf_packet_buffer(inst.blas) if packets else inst.blas.nodes.ravel()
    node_words = 8 * W
    root = -(-base.size // node_words)
    tlas = _relocate(inst.tlas_nodes, W, root, 0)
    pad = np.zeros(root * node_words - base.size, np.float32)
    records_at = (root + tlas.shape[0]) * node_words
    buf = np.concatenate([base, pad, tlas.ravel(), inst.records.ravel()]).astype(np.float32)
    if buf.size >= 1 << 31:
        raise ValueError("the instanced node buffer exceeds 2^31 words")
    buf.view(np.int32)[[HEADER_ROOT, HEADER_RECORDS, HEADER_TRI_BITS]] = [root, records_at, inst.tri_bits]
    return buf, int(root), int(records_at)
