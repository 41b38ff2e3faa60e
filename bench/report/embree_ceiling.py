"""Embree's own ray throughput on a scene, on the host: the ceiling for this machine.

Embree (through ``embreex``, one ``rtcIntersect1``/``rtcOccluded1`` call per ray, the rays
split over host threads) traces three kinds of rays through the scene's triangles:

- ``primary``: the scene camera's rays at the report's resolution, jittered in the pixel as
  pyclpt's camera does, one per pixel or, for small images, several per pixel so that at
  least ``min_rays`` are traced (closest hit);
- ``secondary``: from each primary hit point, a cosine-distributed direction about the
  surface normal on the side the ray came from (closest hit), the incoherent rays that
  bounces trace;
- ``shadow``: from each primary hit point to a random point on a random emitting triangle
  (area-weighted), or in a random direction when no triangle emits (any hit).

Throughput is the best of ``repeats`` runs (a ceiling); the time to build Embree's BVH is
recorded apart. The device kernels trace the same kinds of rays with pyclpt's own BVH, so
the ratio of their rays/s to these is how close the device gets to what the host's best
ray tracer does on the same CPU.
"""
from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np


def scene_triangles(scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All meshes as (positions (V, 3) float32, indices (T, 3) int32, emissive (T,) bool)."""
    pos, idx, emit = [], [], []
    offset = 0
    for mesh in scene.meshes:
        pos.append(np.asarray(mesh.positions, np.float32))
        idx.append(np.asarray(mesh.indices, np.int64) + offset)
        offset += pos[-1].shape[0]
        em = getattr(mesh, "emission", None)
        try:
            emissive = em is not None and float(np.max(np.asarray(em, np.float64))) > 0
        except (TypeError, ValueError):  # an emitter that is not a plain colour: count it as emitting
            emissive = em is not None
        emit.append(np.full(mesh.triangle_count, emissive))
    return (np.concatenate(pos), np.concatenate(idx).astype(np.int32), np.concatenate(emit))


def camera_rays(scene, width: int, height: int, rng: np.random.Generator,
                count: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``count`` (default: one per pixel) jittered camera rays, pixel after pixel, as
    ``camera_path`` in cl/integrators/path.h makes them."""
    origin, forward, right, up = (np.asarray(v, np.float64) for v in scene.camera.basis(width, height))
    n = count or width * height
    py, px = np.divmod(np.arange(n) % (width * height), width)
    j = rng.random((n, 2))
    sx = 2.0 * ((px + j[:, 0]) / width) - 1.0
    sy = 1.0 - 2.0 * ((py + j[:, 1]) / height)
    d = forward[None, :] + sx[:, None] * right[None, :] + sy[:, None] * up[None, :]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(origin, d.shape)
    return np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)


def _cosine_directions(n: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Cosine-distributed unit directions about unit normals n (N, 3)."""
    u1, u2 = rng.random(len(n)), rng.random(len(n))
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1 - u1))], axis=1)
    a = np.where(np.abs(n[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    t = np.cross(n, a)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(n, t)
    return local[:, :1] * t + local[:, 1:2] * b + local[:, 2:] * n


class EmbreeTracer:
    """An Embree scene of the given triangles, traced from ``threads`` host threads."""

    def __init__(self, positions: np.ndarray, indices: np.ndarray, threads: int | None = None) -> None:
        from embreex import mesh_construction, rtcore_scene

        self.threads = max(1, int(threads or os.cpu_count() or 1))
        t0 = time.perf_counter()
        self.scene = rtcore_scene.EmbreeScene()
        mesh_construction.TriangleMesh(self.scene, np.ascontiguousarray(positions, np.float32),
                                       np.ascontiguousarray(indices, np.int32))
        # Embree commits (builds its BVH) on the first query.
        self.scene.run(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32))
        self.build_seconds = time.perf_counter() - t0
        self.pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None

    def close(self) -> None:
        if self.pool:
            self.pool.shutdown()

    def run(self, org: np.ndarray, dirs: np.ndarray, dists: np.ndarray | None = None,
            query: str = "INTERSECT", output: bool = False):
        """Trace rays; returns embreex's result (prim ids / occlusion, or a dict with ``output``)."""
        def one(sl: slice):
            d = None if dists is None else np.ascontiguousarray(dists[sl], np.float32)
            return self.scene.run(np.ascontiguousarray(org[sl], np.float32),
                                  np.ascontiguousarray(dirs[sl], np.float32), dists=d, query=query,
                                  output=1 if output else None)

        n = len(org)
        if self.pool is None or n < 1024:
            return one(slice(0, n))
        edges = np.linspace(0, n, 4 * self.threads + 1).astype(int)
        parts = list(self.pool.map(one, [slice(a, b) for a, b in zip(edges[:-1], edges[1:])]))
        if output:
            return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        return np.concatenate(parts)

    def throughput(self, org, dirs, dists=None, query="INTERSECT", repeats: int = 3) -> dict:
        best = float("inf")
        times = []
        for _ in range(repeats):
            t = time.perf_counter()
            self.run(org, dirs, dists, query)
            times.append(time.perf_counter() - t)
            best = min(best, times[-1])
        return {"rays": int(len(org)), "best_s": best, "median_s": float(np.median(times)),
                "mrays_per_s": len(org) / best / 1e6}


def bounce_and_shadow_rays(p: np.ndarray, n: np.ndarray, dirs: np.ndarray, pos: np.ndarray, idx: np.ndarray,
                           emissive: np.ndarray, rng: np.random.Generator):
    """Rays leaving hit points ``p`` (float64) with geometric normals ``n`` of rays ``dirs``: the normals
    turned to face the incoming rays, the points offset along them by 1e-4 of the scene's extent, a
    cosine-distributed bounce direction each, and a shadow ray each towards a point on the emitters
    (chosen by area; cosine-distributed directions of the scene's extent without emitters). Returns
    (origins, bounce directions, shadow directions, shadow lengths), float64."""
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    n *= -np.sign(np.sum(n * dirs, axis=1, keepdims=True) + 1e-30)  # face the incoming ray
    extent = float(np.linalg.norm(pos.max(0) - pos.min(0))) or 1.0
    p = p + 1e-4 * extent * n
    bounce = _cosine_directions(n, rng)
    if not emissive.any():
        return p, bounce, _cosine_directions(n, rng), np.full(len(p), extent)
    tri = np.flatnonzero(emissive)
    v = pos[idx[tri]].astype(np.float64)
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    pick = rng.choice(len(tri), size=len(p), p=area / area.sum()) if area.sum() > 0 else \
        rng.integers(0, len(tri), len(p))
    u1, u2 = np.sqrt(rng.random(len(p))), rng.random(len(p))
    target = (1 - u1)[:, None] * v[pick, 0] + (u1 * (1 - u2))[:, None] * v[pick, 1] + \
        (u1 * u2)[:, None] * v[pick, 2]
    to = target - p
    dist = np.linalg.norm(to, axis=1)
    return p, bounce, to / np.maximum(dist[:, None], 1e-30), 0.999 * dist


def measure(scene, width: int, height: int, *, threads: int | None = None, repeats: int = 3,
            seed: int = 0, min_rays: int = 1 << 18) -> dict:
    """Embree's primary, secondary and shadow ray throughput on ``scene`` (see the module docstring)."""
    rng = np.random.default_rng(seed)
    pos, idx, emissive = scene_triangles(scene)
    tracer = EmbreeTracer(pos, idx, threads)
    try:
        org, dirs = camera_rays(scene, width, height, rng, max(width * height, min_rays))
        out = {"triangles": int(len(idx)), "threads": tracer.threads, "build_s": tracer.build_seconds,
               "repeats": repeats}
        primary = tracer.throughput(org, dirs, repeats=repeats)
        hit = tracer.run(org, dirs, output=True)
        mask = hit["primID"] >= 0
        primary["hit_fraction"] = float(mask.mean())
        out["primary"] = primary
        if not mask.any():
            return out
        p = org[mask].astype(np.float64) + hit["tfar"][mask, None].astype(np.float64) * dirs[mask]
        p, sdirs, to, dists = bounce_and_shadow_rays(p, hit["Ng"][mask].astype(np.float64), dirs[mask], pos, idx,
                                                     emissive, rng)
        out["secondary"] = tracer.throughput(p.astype(np.float32), sdirs.astype(np.float32), repeats=repeats)
        out["shadow"] = tracer.throughput(p.astype(np.float32), to.astype(np.float32),
                                          dists.astype(np.float32), query="OCCLUDED", repeats=repeats)
        return out
    finally:
        tracer.close()
