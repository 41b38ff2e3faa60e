"""Expected values computed independently of the renderer, in numpy: the point-to-polygon form
factor, and what the camera sees directly (ray casting against the scene's triangles)."""
from __future__ import annotations

import numpy as np

import pyclpt


def form_factor(points: np.ndarray, normal: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Form factor from a differential area at each point (unit normal ``normal``) to a convex
    polygon (vertices in order around it): F = 1/(2 pi) sum_i angle_i n . unit(R_i x R_i+1), R_i the
    unit vectors to the vertices (Lambert 1760; e.g. Cohen & Wallace, Radiosity and Realistic Image
    Synthesis, ch. 4), the polygon first clipped to the half-space in front of the point."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    normal = np.asarray(normal, np.float64)
    polygon = np.asarray(polygon, np.float64)
    above = (polygon[None, :, :] - points[:, None, :]) @ normal > 1e-12
    out = np.zeros(len(points))
    whole = above.all(1)
    out[whole] = _contour(points[whole], normal, polygon)
    for i in np.flatnonzero(~whole & above.any(1)):
        out[i] = _contour(points[i:i + 1], normal, _clip(polygon, points[i], normal))[0]
    return out


def _contour(points: np.ndarray, normal: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    r = polygon[None, :, :] - points[:, None, :]
    r /= np.linalg.norm(r, axis=-1, keepdims=True)
    rn = np.roll(r, -1, axis=1)
    c = np.cross(r, rn)
    angle = np.arctan2(np.linalg.norm(c, axis=-1), (r * rn).sum(-1))
    g = c / np.maximum(np.linalg.norm(c, axis=-1, keepdims=True), 1e-300)
    return np.abs((angle * (g @ normal)).sum(1)) / (2.0 * np.pi)


def _clip(polygon: np.ndarray, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman: the part of a convex polygon with normal . (y - point) >= 0."""
    out = []
    h = (polygon - point) @ normal
    for k in range(len(polygon)):
        j = (k + 1) % len(polygon)
        if h[k] >= 0:
            out.append(polygon[k])
        if (h[k] >= 0) != (h[j] >= 0):
            out.append(polygon[k] + (polygon[j] - polygon[k]) * (h[k] / (h[k] - h[j])))
    return np.array(out)


def camera_rays(scene: pyclpt.Scene, width: int, height: int, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Origin (3,) and unit directions (height, width, len(offsets)^2, 3) of rays through the points
    ``offsets`` x ``offsets`` (in [0, 1]) of every pixel, as the camera jitters: pixel (px, py) spans
    screen x in [px, px + 1) / width, screen y downwards."""
    origin, forward, right, up = scene.camera.basis(width, height)
    py, px, jy, jx = np.meshgrid(np.arange(height), np.arange(width), offsets, offsets, indexing="ij")
    sx = 2.0 * (px + jx) / width - 1.0
    sy = 1.0 - 2.0 * (py + jy) / height
    d = forward + sx[..., None] * right + sy[..., None] * up
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return origin, d.reshape(height, width, len(offsets) ** 2, 3)


def directly_seen_emission(scene: pyclpt.Scene, origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Radiance of the emitter each ray sees first (front faces only: area lights are one-sided),
    zero where it sees a surface that does not emit or nothing (no environment allowed).
    Brute-force closest hit against every triangle of the scene, in float64."""
    assert scene.environment is None, "directly_seen_emission ignores the environment"
    shape = dirs.shape[:-1]
    d = dirs.reshape(-1, 3).astype(np.float64)
    best = np.full(len(d), np.inf)
    out = np.zeros((len(d), 3))
    for mesh in scene.meshes:
        tri = mesh.positions.astype(np.float64)[mesh.indices]  # (T, 3, 3)
        v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        ng = np.cross(e1, e2)
        for k in range(len(tri)):
            p = np.cross(d, e2[k])
            det = p @ e1[k]
            with np.errstate(divide="ignore", invalid="ignore"):
                inv = 1.0 / det
                s = origin - v0[k]
                u = (p @ s) * inv
                q = np.cross(s, e1[k])
                v = (d @ q) * inv
                t = (q @ e2[k]) * inv
                hit = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9) & (t < best)
            best = np.where(hit, t, best)
            front = (d @ ng[k]) < 0
            le = np.asarray(mesh.emission if mesh.emission is not None else (0.0, 0.0, 0.0), np.float64)
            out = np.where(hit[:, None], np.where(front[:, None], le[None, :], 0.0), out)
    return out.reshape(*shape, 3)


def emitter_pixels(scene: pyclpt.Scene, width: int, height: int, sub: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """What each pixel sees directly: (radiance (H, W, 3), certain (H, W) bool). A pixel is certain
    when rays through a sub x sub grid spanning it edge to edge all see the same radiance; its value is
    then the exact depth-1 image of the pixel (for emitters larger than a sub-pixel cell)."""
    origin, dirs = camera_rays(scene, width, height, np.linspace(0.0, 1.0, sub))
    seen = directly_seen_emission(scene, origin, dirs)
    certain = np.all(seen == seen[:, :, :1], axis=(2, 3))
    return seen[:, :, sub * sub // 2], certain
