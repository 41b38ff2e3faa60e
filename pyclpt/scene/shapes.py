"""Analytic shapes as triangle meshes, in their Mitsuba object spaces.

``rectangle``: [-1, 1]^2 at z = 0, facing +z. ``cube``: [-1, 1]^3, faces outward.
``disk``: unit disk at z = 0, facing +z. ``sphere``: unit sphere at the origin
(a UV sphere with smooth shading normals, a documented approximation of
Mitsuba's analytic sphere). ``cylinder``: radius 1 around the z axis from z = 0 to 1, open, facing
out, u = phi / 2pi and v = z as Mitsuba's (a prism of 128 sides with smooth normals).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np


class ShapeMesh(NamedTuple):
    positions: np.ndarray
    indices: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray


def rectangle() -> ShapeMesh:
    p = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    n = np.tile(np.array([0, 0, 1], np.float32), (4, 1))
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    return ShapeMesh(p, np.array([[0, 1, 2], [2, 3, 0]], np.int32), n, uv)


# Mitsuba 3's cube, as mi.traverse gives it (vertex_positions, vertex_texcoords, faces): 4 vertices a face,
# texture coordinates as Mitsuba's (the loader flips v into pyclpt's convention, as for every analytic shape).
_CUBE_POSITIONS = [
    [1, -1, -1], [1, -1, 1], [-1, -1, 1], [-1, -1, -1],  # -y
    [1, 1, -1], [-1, 1, -1], [-1, 1, 1], [1, 1, 1],  # +y
    [1, -1, -1], [1, 1, -1], [1, 1, 1], [1, -1, 1],  # +x
    [1, -1, 1], [1, 1, 1], [-1, 1, 1], [-1, -1, 1],  # +z
    [-1, -1, 1], [-1, 1, 1], [-1, 1, -1], [-1, -1, -1],  # -x
    [1, 1, -1], [1, -1, -1], [-1, -1, -1], [-1, 1, -1],  # -z
]
_CUBE_FACE_UVS = [[0, 1], [1, 1], [1, 0], [0, 0]]


def cube() -> ShapeMesh:
    p = np.array(_CUBE_POSITIONS, np.float32)
    n = np.repeat(np.array([[0, -1, 0], [0, 1, 0], [1, 0, 0], [0, 0, 1], [-1, 0, 0], [0, 0, -1]], np.float32), 4, 0)
    uv = np.tile(np.array(_CUBE_FACE_UVS, np.float32), (6, 1))
    base = 4 * np.arange(6)[:, None]
    idx = np.concatenate([base + [0, 1, 2], base + [3, 0, 2]], 1).reshape(-1, 3)
    return ShapeMesh(p, idx.astype(np.int32), n, uv)


def disk(segments: int = 128, rings: int = 8) -> ShapeMesh:
    """Rings of vertices at radii k / rings with uv (r, phi / 2pi) as Mitsuba's disk has; the centre is
    a ring of its own (one vertex per angle, all at the origin: its triangles with two of them have no
    area), so that v follows the angle everywhere, and the seam's vertices come twice (v = 0 and 1)."""
    phi = np.linspace(0, 2 * np.pi, segments + 1)
    r = np.linspace(0, 1, rings + 1)
    rr, ff = np.meshgrid(r, phi, indexing="ij")
    p = np.stack([rr * np.cos(ff), rr * np.sin(ff), np.zeros_like(rr)], -1).reshape(-1, 3)
    uv = np.stack([rr, ff / (2 * np.pi)], -1).reshape(-1, 2)
    w = segments + 1
    idx = []
    for k in range(rings):
        for j in range(segments):
            a, b, c, d = k * w + j, k * w + j + 1, (k + 1) * w + j, (k + 1) * w + j + 1
            if k > 0:  # counter-clockwise seen from +z
                idx.append([a, d, b])
            idx.append([a, c, d])
    n = np.tile(np.array([0, 0, 1], np.float32), (len(p), 1))
    return ShapeMesh(p.astype(np.float32), np.array(idx, np.int32), n, uv.astype(np.float32))


def sphere(rings: int = 48, segments: int = 96) -> ShapeMesh:
    theta = np.linspace(0, np.pi, rings + 1)
    phi = np.linspace(0, 2 * np.pi, segments + 1)
    t, f = np.meshgrid(theta, phi, indexing="ij")
    p = np.stack([np.sin(t) * np.cos(f), np.sin(t) * np.sin(f), np.cos(t)], -1).reshape(-1, 3)
    uv = np.stack([f / (2 * np.pi), t / np.pi], -1).reshape(-1, 2)
    idx = []
    w = segments + 1
    for r in range(rings):
        for s in range(segments):
            a, b, c, d = r * w + s, r * w + s + 1, (r + 1) * w + s, (r + 1) * w + s + 1
            if r != 0:
                idx.append([a, c, b])
            if r != rings - 1:
                idx.append([b, c, d])
    p = p.astype(np.float32)
    return ShapeMesh(p, np.array(idx, np.int32), p.copy(), uv.astype(np.float32))


def cylinder(segments: int = 128) -> ShapeMesh:
    phi = np.linspace(0, 2 * np.pi, segments + 1)  # the seam's vertices twice: u = 0 and u = 1
    ring = np.stack([np.cos(phi), np.sin(phi)], 1)
    zero, one = np.zeros(segments + 1), np.ones(segments + 1)
    p = np.concatenate([np.column_stack([ring, zero]), np.column_stack([ring, one])])
    n = np.concatenate([np.column_stack([ring, zero])] * 2)
    u = phi / (2 * np.pi)
    uv = np.concatenate([np.column_stack([u, zero]), np.column_stack([u, one])])
    i = np.arange(segments)
    top = i + segments + 1
    idx = np.concatenate([np.stack([i, i + 1, top + 1], 1), np.stack([top + 1, top, i], 1)])  # ccw from outside
    return ShapeMesh(p.astype(np.float32), idx.astype(np.int32), n.astype(np.float32), uv.astype(np.float32))


SHAPES = {"rectangle": rectangle, "cube": cube, "disk": disk, "sphere": sphere, "cylinder": cylinder}
