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


def cube() -> ShapeMesh:
    positions, normals, uvs, indices = [], [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u_axis, v_axis = [a for a in range(3) if a != axis]
            corners = []
            for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                c = np.zeros(3)
                c[axis], c[u_axis], c[v_axis] = sign, du, dv
                corners.append(c)
            # keep counter-clockwise winding seen from outside
            if np.dot(np.cross(corners[1] - corners[0], corners[2] - corners[0]), n) < 0:
                corners = corners[::-1]
            base = len(positions)
            positions += corners
            normals += [n] * 4
            uvs += [[0, 0], [1, 0], [1, 1], [0, 1]]
            indices += [[base, base + 1, base + 2], [base + 2, base + 3, base]]
    return ShapeMesh(np.array(positions, np.float32), np.array(indices, np.int32),
                     np.array(normals, np.float32), np.array(uvs, np.float32))


def disk(segments: int = 64) -> ShapeMesh:
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], 1)
    p = np.vstack([[0, 0, 0], ring]).astype(np.float32)
    n = np.tile(np.array([0, 0, 1], np.float32), (len(p), 1))
    uv = np.vstack([[0, 0], np.stack([np.ones_like(phi), phi / (2 * np.pi)], 1)]).astype(np.float32)
    i = np.arange(segments)
    idx = np.stack([np.zeros(segments, int), 1 + i, 1 + (i + 1) % segments], 1).astype(np.int32)
    return ShapeMesh(p, idx, n, uv)


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
