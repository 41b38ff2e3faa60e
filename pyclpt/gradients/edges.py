"""The boundary term of primary visibility, by edge sampling (Li, Aittala, Durand and Lehtinen 2018).

Moving a surface moves its silhouette over the image: a pixel integral whose integrand jumps across an
edge changes at the rate (Reynolds transport, screen space)::

    d/dtheta  integral w(x) L(x) dx  =  integral over the edges of  w(x) (L_-(x) - L_+(x)) (n . dx/dtheta) dl

with n the edge's unit normal in the film plane, L_+ the radiance on the side n points to, L_- on the
other, and dx/dtheta how the edge's point moves with the parameter. Holding paths fixed (path replay)
misses it entirely. This module computes it for the meshes' vertex positions (and the poses that move
them, :mod:`pyclpt.gradients.placement`):

1. :func:`silhouette_edges`: the edges that can bound what the camera sees, in film coordinates: a
   mesh's boundary edges (one triangle), and edges whose two triangles face the camera on different
   sides (silhouettes) or that have more than two, and on a flat-shaded mesh the creases between two
   triangles of different normals (its shading jumps there); clipped to the image. Then the same edges seen in
   each planar mirror (:func:`pyclpt.gradients.mirrors.mirror_planes`: point c, unit normal m, R = I - 2 m m^T):
   the silhouettes from the camera's origin reflected across the plane, the edges' points p reflected,
   p' = R (p - c) + c, and projected, clipped to the mirror's box on the film and to the part of the edge on the
   camera's side of the plane.
2. :func:`primary_boundary`: points sampled on those edges, stratified, with density proportional to
   their length in pixels; the radiance on both sides of each point from the ``edge_radiance`` kernel
   (``cl/gradients/edge_radiance.cl``: the full path estimator, both sides with the same random
   numbers; seen in a mirror, the rays reflect in it, and the jump has its reflectance); the difference weighted
   by the image gradient through the film's reconstruction filter and scattered to the edge's two vertices
   through the projection's Jacobian (a perspective camera's; an orthographic one's is constant, its silhouettes
   those of its parallel rays, no mirrors: :class:`Projection`; seen in a mirror, at p' and times R: the film
   position is film(p'); the camera's motion acts at p'). A mirror that moves moves every outline it shows, the
   reflected points still (:func:`reflection_velocity`): the plane through the point c where the camera's ray meets the
   mirror's triangle, of normal m (the triangle's, or on a smooth-shaded mirror its interpolated vertex normals,
   which the renderer reflects about), moves p' by -2 [((p - c) . dm - dc . m) m + ((p - c) . m) dm], scattered
   to the triangle's corners (and their vertex normals, chained through :mod:`pyclpt.gradients.normals`); a mirror
   moved by its ``to_world`` or ``vertex_positions`` has the edges of every other mesh seen in it sampled.

It is one term of the derivative: the interior term is the replay's (:mod:`pyclpt.gradients.differentiate`), the
boundary terms of shadows :mod:`pyclpt.gradients.shadows`'s. Outlines seen through curved mirrors or refracting
glass and after two or more mirror bounces are left out. Exact where the radiance on each side is constant across
a parameter change (tests/test_edges.py: a square emitter moving over a constant background, directly and in a
mirror, a mirror moving before it, a sphere's silhouette against its radius).
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass

import numpy as np

from pyclpt.buffers.rfilter import filter_eval
from pyclpt.device.context import Device
from pyclpt.gradients.mirrors import MirrorPlane, mirror_planes
from pyclpt.gradients.normals import normals_backward, normals_chain, normals_forward
from pyclpt.gradients.parameters import SceneParameters, flat_shaded, traverse
from pyclpt.gradients.session import replay_for
from pyclpt.scene.model import Mesh, ReconstructionFilter, Scene

#: Film-space offset (pixels) of the two rays on either side of an edge point.
SIDE_EPS = 1e-3


@dataclass
class ScreenEdges:
    """Silhouette edges in film coordinates (pixels from the image's top-left corner), clipped to it."""

    a: np.ndarray  # (E, 2) film position of the clipped start
    b: np.ndarray  # (E, 2) and end
    mesh: np.ndarray  # (E,) index in scene.meshes
    v0: np.ndarray  # (E,) the 3D edge's first vertex (index in its mesh)
    v1: np.ndarray  # (E,) and second
    s0: np.ndarray  # (E,) the clipped start and end as parameters of the whole projected edge
    s1: np.ndarray
    z0: np.ndarray  # (E,) depth along the view direction of v0 and v1 (of their reflections, seen in a mirror);
    # 1 under an orthographic camera (the film position is affine along the edge)
    z1: np.ndarray
    mirror: np.ndarray  # (E,) the index in ``planes`` of the mirror the edge is seen in, -1 seen directly
    planes: list[MirrorPlane] = dataclasses.field(default_factory=list)  # the scene's mirror planes

    @property
    def lengths(self) -> np.ndarray:
        return np.linalg.norm(self.b - self.a, axis=1)


@dataclass
class Projection:
    """A perspective or orthographic camera's map from world points to film coordinates and its Jacobian. An
    orthographic camera's rays go along forward from the film rectangle origin + sx right + sy up (camera_ray,
    cl/integrators/path.h): a point's film coordinates are affine in it, (sx, sy, t) = B^-1 (p - origin) with
    B = [right up forward], t its distance along the ray."""

    origin: np.ndarray
    forward: np.ndarray
    right: np.ndarray  # scaled: the image's half-extent at unit depth (as the kernels' CONST_CAM_RIGHT)
    up: np.ndarray
    width: int
    height: int
    orthographic: bool = False  # then right and up are the image's half-extent in world units

    @classmethod
    def of(cls, scene: Scene, width: int, height: int, to_world: np.ndarray | None = None,
           x_fov: float | None = None, orthographic: bool = False) -> Projection:
        """The projection of ``scene``'s camera (with ``to_world`` instead of its own, and a horizontal fov of
        ``x_fov`` degrees, when given); an orthographic camera's where ``orthographic`` allows it (the terms
        written for it: the silhouettes' and the shadows'), else refused by name as any other kind but
        perspective."""
        cam = scene.camera
        if cam.kind != "perspective" and not (orthographic and cam.kind == "orthographic"):
            what = "perspective and orthographic" if orthographic else "perspective"
            raise ValueError(f"this boundary term is implemented for {what} cameras; scene {scene.name!r} has a "
                             f"{cam.kind} camera")
        if to_world is not None:
            cam = dataclasses.replace(cam, to_world=np.asarray(to_world, np.float64))
        if x_fov is not None:
            cam = dataclasses.replace(cam, fov=x_fov, fov_axis="x")
        o, f, r, u = (np.asarray(v, np.float64) for v in cam.basis(width, height))
        return cls(o, f / np.linalg.norm(f), r, u, width, height, cam.kind == "orthographic")

    def _inverse(self) -> np.ndarray:
        """B^-1 (rows: d sx/dp, d sy/dp, d t/dp) of an orthographic camera."""
        return np.linalg.inv(np.stack([self.right, self.up, self.forward], axis=1))

    def depth(self, p: np.ndarray) -> np.ndarray:
        if self.orthographic:
            return (p - self.origin) @ self._inverse()[2]
        return (p - self.origin) @ self.forward

    def film(self, p: np.ndarray) -> np.ndarray:
        """(N, 2) film coordinates of points p (N, 3) in front of the camera."""
        d = p - self.origin
        if self.orthographic:
            inv = self._inverse()
            sx, sy = d @ inv[0], d @ inv[1]
        else:
            z = d @ self.forward
            sx = (d @ self.right) / (self.right @ self.right) / z
            sy = (d @ self.up) / (self.up @ self.up) / z
        return np.stack([(sx + 1) * 0.5 * self.width, (1 - sy) * 0.5 * self.height], axis=1)

    def rays_to(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The camera rays that reach points p (N, 3) in front of the camera: their origins (N, 3), unit directions
        (N, 3) and lengths (N,). A pinhole's start at its origin; an orthographic camera's go along forward from the
        film rectangle, p - t forward, t the point's depth (camera_ray, cl/integrators/path.h)."""
        if self.orthographic:
            t = self.depth(p)
            return p - t[:, None] * self.forward[None], np.tile(self.forward, (len(p), 1)), t
        d = p - self.origin
        dist = np.linalg.norm(d, axis=1)
        return np.tile(self.origin, (len(p), 1)), d / np.maximum(dist, 1e-300)[:, None], dist

    def normal_velocity(self, p: np.ndarray, n: np.ndarray) -> np.ndarray:
        """(N, 3): n . d(film position)/dp at points p (N, 3) for film-space directions n (N, 2)."""
        if self.orthographic:  # constant: the rows of B^-1
            inv = self._inverse()
            dsx, dsy = inv[0][None], inv[1][None]
        else:
            d = p - self.origin
            z = (d @ self.forward)[:, None]
            sx = ((d @ self.right) / (self.right @ self.right))[:, None] / z
            sy = ((d @ self.up) / (self.up @ self.up))[:, None] / z
            dsx = (self.right / (self.right @ self.right) - sx * self.forward) / z
            dsy = (self.up / (self.up @ self.up) - sy * self.forward) / z
        return n[:, :1] * (0.5 * self.width) * dsx - n[:, 1:] * (0.5 * self.height) * dsy


def _clip(a: np.ndarray, b: np.ndarray, lo: tuple[float, float], hi: tuple[float, float]
          ) -> tuple[np.ndarray, np.ndarray]:
    """Liang-Barsky: the parameters [s0, s1] of segments a -> b inside the box [lo, hi] (s0 > s1: outside)."""
    s0, s1 = np.zeros(len(a)), np.ones(len(a))
    d = b - a
    for k in (0, 1):
        for p, q in ((-d[:, k], a[:, k] - lo[k]), (d[:, k], hi[k] - a[:, k])):
            with np.errstate(divide="ignore", invalid="ignore"):
                r = q / p
            parallel = p == 0
            s1 = np.where(parallel & (q < 0), -1.0, s1)
            s0 = np.where(~parallel & (p < 0), np.maximum(s0, r), s0)
            s1 = np.where(~parallel & (p > 0), np.minimum(s1, r), s1)
    return s0, s1


def edge_copies(mesh: Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every triangle's three edges, ordered so that the copies of one edge (one per triangle it bounds) are
    adjacent, and which copy is its edge's first: ``pairs`` (3F, 2) the copy's vertex indices in its triangle's
    winding order, ``face`` (3F,) its triangle, ``new`` (3F,) True on an edge's first copy. The copies are found
    by position (the vertices welded), so that a mesh whose vertices are split where its normals or uvs jump (a
    box of 24 vertices) has its faces' common edges all the same: found by index, each face's edges were
    boundary edges, and a box's outlines and creases were each counted twice (once per face)."""
    f = mesh.indices.astype(np.int64)
    _, weld = np.unique(np.asarray(mesh.positions), axis=0, return_inverse=True)
    pairs = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    face = np.tile(np.arange(len(f)), 3)
    key = np.sort(weld.reshape(-1)[pairs], axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    key, face, pairs = key[order], face[order], pairs[order]
    new = np.ones(len(key), bool)
    new[1:] = np.any(key[1:] != key[:-1], axis=1)
    return pairs, face, new


def mesh_edges(mesh: Mesh, camera_origin: np.ndarray | None, creases: bool = False,
               direction: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The vertex pairs (K, 2) of ``mesh``'s edges that can bound what a camera at ``camera_origin``
    sees (or, with ``direction`` instead, a distant light's parallel rays travelling along it): boundary edges,
    silhouettes (their two triangles facing the camera on different sides) and edges of more than two triangles;
    with ``creases``, also the edges between two triangles of different normals (a flat-shaded mesh's shading
    jumps there); and how many triangles share each (K,)."""
    p = mesh.positions.astype(np.float64)
    f = mesh.indices.astype(np.int64)
    n = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    towards = (-np.asarray(direction, np.float64))[None] if direction is not None else camera_origin - p[f[:, 0]]
    facing = np.sign(np.einsum("ij,ij->i", n, np.broadcast_to(towards, n.shape)))
    pairs, face, new = edge_copies(mesh)
    group = np.cumsum(new) - 1
    count = np.bincount(group)
    lo = np.full(len(count), np.inf)
    hi = np.full(len(count), -np.inf)
    np.minimum.at(lo, group, facing[face])
    np.maximum.at(hi, group, facing[face])
    keep = (count != 2) | (lo != hi)
    first = np.flatnonzero(new)
    if creases:
        unit = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        two = count == 2
        a, b = face[first[two]], face[first[two] + 1]
        bent = np.zeros(len(count), bool)
        bent[two] = np.einsum("ij,ij->i", unit[a], unit[b]) < 1.0 - 1e-7
        keep |= bent
    return pairs[first][keep], count[keep]


def mirrors_need_a_pinhole(scene: Scene, planes: Sequence[MirrorPlane] | None = None) -> None:
    """ValueError, naming the scene, where the camera's outlines seen in planar mirrors (``planes``, by default the
    scene's :func:`pyclpt.gradients.mirrors.mirror_planes`) would be sampled under an orthographic camera: they
    are written for perspective cameras."""
    if scene.camera.kind == "orthographic" and (mirror_planes(scene) if planes is None else planes):
        raise ValueError(f"the outlines seen in planar mirrors are implemented for perspective cameras; scene "
                         f"{scene.name!r} has an orthographic camera and a planar mirror")


def silhouette_edges(scene: Scene, meshes: Sequence[int], width: int, height: int,
                     mirrors: Collection[int] = ()) -> ScreenEdges:
    """The silhouette edges of ``scene.meshes[i]`` for i in ``meshes`` seen by the scene's camera on a
    width x height image (see the module): first those seen directly, then, for each planar mirror
    (:func:`pyclpt.gradients.mirrors.mirror_planes`), those seen in it, but the mirror's own mesh's (see
    :func:`_view_edges`); in the mirrors of the meshes in ``mirrors`` (mirrors that move: they move every outline
    they show) those of every other mesh. Edges with an end at or behind the camera's plane are left out."""
    proj = Projection.of(scene, width, height, orthographic=True)
    parts = [_view_edges(scene, proj, i) for i in meshes]
    planes = mirror_planes(scene)
    mirrors_need_a_pinhole(scene, planes)
    for k, plane in enumerate(planes):
        box = _footprint(scene, proj, plane)
        shown = range(len(scene.meshes)) if plane.mesh in mirrors else meshes
        if box is not None:
            parts += [_view_edges(scene, proj, i, plane, k, box) for i in shown if i != plane.mesh]
    cols = {key: [part[key] for part in parts] for key in ("a", "b", "mesh", "v0", "v1", "s0", "s1", "z0", "z1",
                                                           "mirror")}
    if not parts:
        empty = np.zeros((0, 2))
        return ScreenEdges(empty, empty, *(np.zeros(0, int) for _ in range(3)), *(np.zeros(0) for _ in range(4)),
                           np.zeros(0, int), planes)
    return ScreenEdges(**{k: np.concatenate(v) for k, v in cols.items()}, planes=planes)


#: A box on the film: its lowest (x, y) and its highest.
Box = tuple[tuple[float, float], tuple[float, float]]


def _footprint(scene: Scene, proj: Projection, plane: MirrorPlane) -> Box | None:
    """The film box (lo, hi) that the mirror ``plane``'s triangles cover, within the image (the whole image when one
    of their corners is at or behind the camera's plane); None when it covers none of the image, or the camera is in
    the plane (it sees no reflection there)."""
    p = scene.meshes[plane.mesh].positions.astype(np.float64)
    corners = p[np.asarray(scene.meshes[plane.mesh].indices, np.int64)[plane.faces].reshape(-1)]
    scale = max(float(np.abs(corners - proj.origin).max()), 1e-30)
    if abs(float(plane.side(proj.origin))) <= 1e-6 * scale:
        return None
    full = (0.0, 0.0), (float(proj.width), float(proj.height))
    if np.any(proj.depth(corners) <= 1e-6 * scale):
        return full
    x = proj.film(corners)
    lo, hi = np.maximum(x.min(0), full[0]), np.minimum(x.max(0), full[1])
    if not np.all(hi > lo):
        return None
    return (float(lo[0]), float(lo[1])), (float(hi[0]), float(hi[1]))


def _view_edges(scene: Scene, proj: Projection, i: int, plane: MirrorPlane | None = None, k: int = -1,
                box: Box | None = None) -> dict[str, np.ndarray]:
    """The columns of :class:`ScreenEdges` for mesh i: seen directly (``plane`` None), clipped to the image; or
    seen in the mirror ``plane`` (index k): the silhouettes from the camera's origin reflected across it, the
    edges' points reflected (R (p - c) + c) and projected, clipped to the mirror's film box ``box`` and to the part
    on the camera's side of the plane (the mirror is between the camera and the reflected part only)."""
    mesh = scene.meshes[i]
    p = mesh.positions.astype(np.float64)
    eye, seen = (proj.origin, p) if plane is None else (plane.reflect(proj.origin), plane.reflect(p))
    # flat shading jumps at creases; an orthographic camera's silhouettes are those of its parallel rays
    pairs, _ = mesh_edges(mesh, eye, creases=flat_shaded(mesh), direction=proj.forward if proj.orthographic else None)
    z0, z1 = proj.depth(seen[pairs[:, 0]]), proj.depth(seen[pairs[:, 1]])
    scale = max(float(np.abs(seen - proj.origin).max()), 1e-30)
    front = (z0 > 1e-6 * scale) & (z1 > 1e-6 * scale)
    pairs, z0, z1 = pairs[front], z0[front], z1[front]
    if proj.orthographic:  # the film position is affine along the edge: its parameter t is s (z0 = z1)
        z0, z1 = np.ones_like(z0), np.ones_like(z1)
    a, b = proj.film(seen[pairs[:, 0]]), proj.film(seen[pairs[:, 1]])
    s0, s1 = _clip(a, b, *(box or ((0, 0), (proj.width, proj.height))))
    if plane is not None:  # the part in front of the mirror, as parameters t of the 3D edge, then s on the film
        toward = np.sign(plane.side(proj.origin))
        h0, h1 = toward * plane.side(p[pairs[:, 0]]), toward * plane.side(p[pairs[:, 1]])
        with np.errstate(divide="ignore", invalid="ignore"):
            cross = h0 / (h0 - h1)
        t0 = np.where(h0 > 0, 0.0, np.where(h1 > 0, cross, 1.0))
        t1 = np.where(h1 > 0, 1.0, np.where(h0 > 0, cross, 0.0))
        s0 = np.maximum(s0, t0 * z1 / ((1 - t0) * z0 + t0 * z1))  # s = t z1 / z(t) (1/z is linear on the film)
        s1 = np.minimum(s1, t1 * z1 / ((1 - t1) * z0 + t1 * z1))
    inside = (s1 > s0) & np.all(np.isfinite(a) & np.isfinite(b), axis=1)
    cols = {"a": a + s0[:, None] * (b - a), "b": a + s1[:, None] * (b - a), "mesh": np.full(len(a), i),
            "v0": pairs[:, 0], "v1": pairs[:, 1], "s0": s0, "s1": s1, "z0": z0, "z1": z1, "mirror": np.full(len(a), k)}
    return {key: v[inside] for key, v in cols.items()}


def _filter_weights(rfilter: ReconstructionFilter, x: np.ndarray, width: int, height: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For film positions x (N, 2): the pixels (N, K) (flat index, -1 outside) whose value the point
    contributes to and its normalised filter weights (N, K): w(x - c) / integral of w, per axis."""
    radius = {"box": 0.5, "tent": rfilter.radius, "gaussian": 4.0 * rfilter.stddev}[rfilter.kind]
    grid = np.linspace(-radius, radius, 40001)
    norm = float(np.trapezoid(filter_eval(rfilter, grid), grid)) if rfilter.kind != "box" else 1.0
    # the pixels whose centres j + 1/2 are within the radius, a < j < a + 2 radius with a = x - radius - 1/2:
    # at most ceil(2 radius) a row (1 for the box, 2 for a unit tent, 4 for Mitsuba's gaussian), from floor(a) + 1
    offs = np.arange(max(int(math.ceil(2.0 * radius)), 1))
    base = np.floor(x - radius - 0.5).astype(np.int64) + 1
    px = base[:, :1] + offs[None, :]  # (N, R) candidate columns
    py = base[:, 1:] + offs[None, :]
    wx = filter_eval(rfilter, x[:, :1] - (px + 0.5)) / norm
    wy = filter_eval(rfilter, x[:, 1:] - (py + 0.5)) / norm
    w = (wy[:, :, None] * wx[:, None, :]).reshape(len(x), -1)
    ok = ((px >= 0) & (px < width))[:, None, :] & ((py >= 0) & (py < height))[:, :, None]
    pix = (py[:, :, None] * width + px[:, None, :]).reshape(len(x), -1)
    ok = ok.reshape(len(x), -1) & (w != 0)
    return np.where(ok, pix, -1), np.where(ok, w, 0.0), ok


@dataclass
class EdgeSamples:
    """Points sampled on the silhouette edges and what each contributes (see the module)."""

    pixels: np.ndarray  # (N, K) flat pixel indices the point's filter reaches (-1: none)
    weights: np.ndarray  # (N, K) the filter's normalised weights there
    jump: np.ndarray  # (N, 3) (L- - L+) x total edge length / N: the estimator's weight of the point
    mesh: np.ndarray  # (N,) index in scene.meshes
    v0: np.ndarray  # (N,) the edge's vertices
    v1: np.ndarray
    t: np.ndarray  # (N,) the point's parameter on the 3D edge v0 -> v1
    velocity: np.ndarray  # (N, 3) n . d(film position)/dp at the 3D point: how the edge moves with it
    point: np.ndarray  # (N, 3) the 3D point
    normal: np.ndarray  # (N, 2) the edge's unit normal in the film plane (towards the "+" side)
    seen_at: np.ndarray  # (N, 3) where the camera sees the point: the point, or its reflection in a planar mirror
    mirror_mesh: np.ndarray  # (N,) the mesh of the planar mirror the point is seen in (index in scene.meshes), -1
    mirror_corners: np.ndarray  # (N, 3) the vertices (in that mesh) of the mirror's triangle it is seen through
    mirror_velocity: np.ndarray  # (N, 3, 3) n . d(film position)/d(each of those corners' positions)
    mirror_normal_velocity: np.ndarray  # (N, 3, 3) and /d(their vertex normals) (a smooth-shaded mirror's; else 0)


def sample_edges(scene: Scene, meshes: Sequence[int], width: int, height: int, *, samples: int, seed: int,
                 max_depth: int | None = None, device: Device | str | None = None,
                 stratified: bool = True, mirrors: Collection[int] = ()) -> EdgeSamples:
    """``samples`` points on the silhouette edges of ``scene.meshes[i]`` (i in ``meshes``; in the planar mirrors of
    the meshes in ``mirrors``, every mesh's: :func:`silhouette_edges`), stratified along their total length in pixels
    (independent with ``stratified`` False), with the radiance on both sides of each from the ``edge_radiance``
    kernel (random numbers keyed by ``seed``)."""
    edges = silhouette_edges(scene, meshes, width, height, mirrors)
    lengths = edges.lengths
    total = float(lengths.sum())
    n_pts = samples if total > 0 else 0
    if n_pts == 0:
        z = np.zeros(0)
        return EdgeSamples(np.zeros((0, 1), np.int64), np.zeros((0, 1)), np.zeros((0, 3)), z.astype(int),
                           z.astype(int), z.astype(int), z, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 2)),
                           np.zeros((0, 3)), z.astype(int), np.zeros((0, 3), np.int64), np.zeros((0, 3, 3)),
                           np.zeros((0, 3, 3)))
    rng = np.random.default_rng([seed, 0x6564676573])  # "edges"
    u = ((np.arange(n_pts) if stratified else 0) + rng.random(n_pts)) / (n_pts if stratified else 1) * total
    cdf = np.cumsum(lengths)
    e = np.minimum(np.searchsorted(cdf, u, side="right"), len(lengths) - 1)
    local = np.clip((u - (cdf[e] - lengths[e])) / np.maximum(lengths[e], 1e-300), 0.0, 1.0)
    d = edges.b[e] - edges.a[e]
    x = edges.a[e] + local[:, None] * d
    n = np.stack([-d[:, 1], d[:, 0]], axis=1) / np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
    replay = replay_for(scene, width=width, height=height, max_depth=max_depth, device=device)
    points = np.concatenate([x, n], axis=1).astype(np.float32)
    sides = replay.edge_radiance_started(points, seed, SIDE_EPS)  # (N, 2, 3): minus, plus; the rest meanwhile
    pix, w, _ = _filter_weights(scene.film.rfilter, x, width, height)
    # the 3D point of each sample (1/z is linear along the projected edge), the edge's normal velocity there
    s = edges.s0[e] + local * (edges.s1[e] - edges.s0[e])
    z0, z1 = edges.z0[e], edges.z1[e]
    t = s * z0 / ((1 - s) * z1 + s * z0)
    proj = Projection.of(scene, width, height, orthographic=True)
    point = np.zeros((n_pts, 3))
    for i in set(edges.mesh[e].tolist()):
        m = edges.mesh[e] == i
        p = scene.meshes[i].positions.astype(np.float64)
        tm = t[m][:, None]
        point[m] = (1 - tm) * p[edges.v0[e][m]] + tm * p[edges.v1[e][m]]
    # seen in a mirror, the point is seen at p' = R (p - c) + c: n . d film(p')/dp = (n . d film/dp') R
    seen = point.copy()
    mirrored = [(edges.mirror[e] == k, plane) for k, plane in enumerate(edges.planes)]
    for m, plane in mirrored:
        seen[m] = plane.reflect(point[m])
    velocity = proj.normal_velocity(seen, n)
    for m, plane in mirrored:
        velocity[m] = velocity[m] @ plane.matrix
    # and it moves with the mirror's triangle it is seen through, the point still
    mirror_mesh = np.full(n_pts, -1)
    corners = np.zeros((n_pts, 3), np.int64)
    by_position, by_normal = np.zeros((n_pts, 3, 3)), np.zeros((n_pts, 3, 3))
    for m, plane in mirrored:
        if m.any():
            mirror = scene.meshes[plane.mesh]
            mirror_mesh[m] = plane.mesh
            corners[m], bary = _faces_seen(scene, proj, plane, seen[m])
            shading = None if mirror.normals is None else mirror.normals.astype(np.float64)[corners[m]]
            by_position[m], by_normal[m] = reflection_velocity(
                proj, mirror.positions.astype(np.float64)[corners[m]], bary, point[m], n[m], shading)
    radiance = sides().astype(np.float64)
    return EdgeSamples(pix, w, (radiance[:, 0] - radiance[:, 1]) * total / n_pts, edges.mesh[e], edges.v0[e],
                       edges.v1[e], t, velocity, point, n, seen, mirror_mesh, corners, by_position, by_normal)


def _faces_seen(scene: Scene, proj: Projection, plane: MirrorPlane, seen: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The triangle of the mirror ``plane`` through which the camera sees the reflected points ``seen`` (N, 3), the
    one the ray from the camera's origin to the point crosses the plane in (outside the mirror, where it shows
    nothing and the jump is 0, the nearest): its corners (N, 3) (vertex indices in the mirror's mesh) and the
    crossing's barycentric coordinates there (N, 3)."""
    mesh = scene.meshes[plane.mesh]
    tri = np.asarray(mesh.indices, np.int64)[plane.faces]
    d = seen - proj.origin
    with np.errstate(divide="ignore", invalid="ignore"):
        x = proj.origin + ((plane.point - proj.origin) @ plane.normal / (d @ plane.normal))[:, None] * d
    best = np.full(len(seen), -np.inf)
    bary = np.zeros((len(seen), 3))
    face = np.zeros(len(seen), np.int64)
    for f, q in enumerate(mesh.positions.astype(np.float64)[tri]):
        n = np.cross(q[1] - q[0], q[2] - q[0])
        b = np.stack([np.cross(q[(j + 2) % 3] - q[(j + 1) % 3], x - q[(j + 1) % 3]) @ n for j in range(3)], axis=1)
        b /= n @ n
        inside = b.min(1)
        nearer = inside > best
        face, bary, best = np.where(nearer, f, face), np.where(nearer[:, None], b, bary), np.maximum(best, inside)
    return tri[face], bary


def reflection_velocity(proj: Projection, q: np.ndarray, bary: np.ndarray, point: np.ndarray, normal: np.ndarray,
                        shading: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """How points ``point`` (N, 3) seen in a planar mirror move on the film with the mirror, the points still, for
    film-space normals ``normal`` (N, 2): n . d(film position)/d(corner j's position) and /d(corner j's vertex
    normal), (N, 3, 3) each, for the mirror's triangle of corners q (N, 3, 3) they are seen through, at barycentrics
    ``bary`` (N, 3) (where the camera's ray meets it). There the mirror is the plane through c = sum b_j q_j, of
    unit normal m: the triangle's, (q1 - q0) x (q2 - q0) / |.|, on a flat-shaded mirror (``shading`` None), else
    the shading normal s / |s|, s = sum b_j n_j, of the corners' vertex normals n_j (``shading``, (N, 3, 3): the
    renderer reflects about it; on a planar mirror it is +-m). It shows p at p' = p - 2 ((p - c) . m) m, which moves
    by dp' = -2 [((p - c) . dm - dc . m) m + ((p - c) . m) dm], with dc = sum b_j dq_j and
    dm = (I - m m^T) ((q_{j+2} - q_{j+1}) x dq_j) / |(q1 - q0) x (q2 - q0)| (flat), or
    (I - m m^T) sum b_j dn_j / |s| (smooth; p' is the same for -m, its derivative in m then turns sign). Exact for
    any motion of a flat mirror's vertices; a smooth one's vertex normals are chained by the caller
    (:mod:`pyclpt.gradients.normals`)."""
    cross = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
    size = np.linalg.norm(cross, axis=1)[:, None]
    m = cross / size
    d = point - np.einsum("nj,njk->nk", bary, q)
    h = np.einsum("nk,nk->n", d, m)[:, None]
    v = proj.normal_velocity(point - 2.0 * h * m, normal)  # n . d film/dp' at p'
    vm = np.einsum("nk,nk->n", v, m)[:, None]
    by_point = 2.0 * vm * m  # n . d film/dc
    by_normal = -2.0 * (vm * d + h * v)  # n . d film/dm
    by_normal -= np.einsum("nk,nk->n", by_normal, m)[:, None] * m  # m stays a unit vector
    by_position = bary[:, :, None] * by_point[:, None, :]
    if shading is None:
        by_position += np.stack([np.cross(by_normal / size, q[:, (j + 2) % 3] - q[:, (j + 1) % 3]) for j in range(3)],
                                axis=1)
        return by_position, np.zeros_like(by_position)
    s = np.einsum("nj,njk->nk", bary, shading)
    by_normal *= (np.sign(np.einsum("nk,nk->n", s, m)) / np.linalg.norm(s, axis=1))[:, None]
    return by_position, bary[:, :, None] * by_normal[:, None, :]


def _meshes_of(scene: Scene, names: Sequence[str]) -> dict[int, list[str]]:
    """The meshes whose parameters ``names`` are, by index (the sensor's to_world is not a mesh's)."""
    by_name = {m.name: i for i, m in enumerate(scene.meshes)}
    sensor = f"{scene.ids.get('camera', 'sensor')}.to_world"
    wanted: dict[int, list[str]] = {}
    for name in names:
        if name in sensor_names(scene):
            continue
        shape, _, prop = name.rpartition(".")
        if prop not in ("vertex_positions", "to_world") or shape not in by_name:
            raise ValueError(f"{name}: the boundary term is computed for a shape's vertex_positions or to_world "
                             f"and for {sensor}; shapes: {', '.join(by_name)}")
        wanted.setdefault(by_name[shape], []).append(name)
    return wanted


#: Step of the central differences of the film position with respect to the camera's matrix (float64).
CAMERA_STEP = 1e-6


def sensor_names(scene: Scene) -> tuple[str, str]:
    """The names of where the sensor is: its to_world and its x_fov."""
    sensor = scene.ids.get("camera", "sensor")
    return f"{sensor}.to_world", f"{sensor}.x_fov"


#: Step of the central differences of the film position with respect to the horizontal fov (degrees).
FOV_STEP = 1e-5


def sensor_velocity(scene: Scene, width: int, height: int, point: np.ndarray, normal: np.ndarray, name: str
                    ) -> np.ndarray:
    """n . d(film position of each point)/d(sensor parameter ``name``): (N, 4, 4) for its to_world, (N, 1) for its
    x_fov (degrees; central differences of the projection in float64)."""
    if name.endswith(".to_world"):
        return camera_velocity(scene, width, height, point, normal)
    cam = scene.camera
    _, _, right, _ = cam.basis(width, height)
    fov = 2 * np.degrees(np.arctan(np.linalg.norm(right)))
    film = []
    for x in (fov + FOV_STEP, fov - FOV_STEP):
        film.append(Projection.of(scene, width, height, x_fov=x).film(point))
    return np.einsum("nk,nk->n", normal, (film[0] - film[1]) / (2 * FOV_STEP))[:, None]


def camera_velocity(scene: Scene, width: int, height: int, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(N, 4, 4): n . d(film position of each point)/d(the sensor's to_world), by central differences of
    the projection (a closed form in float64: exact to about 1e-9 relative); the last row zero."""
    m = np.asarray(scene.camera.to_world, np.float64)
    out = np.zeros((len(point), 4, 4))
    for r in range(3):
        for c in range(4):
            d = np.zeros((4, 4))
            d[r, c] = CAMERA_STEP
            up = Projection.of(scene, width, height, m + d, orthographic=True).film(point)
            down = Projection.of(scene, width, height, m - d, orthographic=True).film(point)
            out[:, r, c] = np.einsum("nk,nk->n", normal, (up - down) / (2 * CAMERA_STEP))
    return out


def _rest(params: SceneParameters, name: str, mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """A mesh pose M (4x4) and the positions it moves (positions = M rest)."""
    m4 = np.asarray(params[name], np.float64)
    p = mesh.positions.astype(np.float64)
    return m4, (p - m4[:3, 3]) @ np.linalg.inv(m4[:3, :3]).T


def sample_weights(pixels: np.ndarray, weights: np.ndarray, image_grad: np.ndarray, jump: np.ndarray) -> np.ndarray:
    """(N,) dLoss/dImage at each sample's pixels through its filter weights, dotted with its jump (N, 3): what
    a unit normal motion of the sample's point adds to the loss."""
    gflat = np.asarray(image_grad, np.float64).reshape(-1, 3)
    at = np.maximum(pixels, 0)  # a pixel outside the image has weight 0 (_filter_weights)
    w = np.where(pixels >= 0, weights, 0.0)
    return sum(np.einsum("nk,nk->n", w, gflat[:, c][at]) * jump[:, c] for c in range(3))


def add_at(out: np.ndarray, rows: np.ndarray, q: np.ndarray) -> None:
    """out (V, C) += q (N, C) at rows (N,), as np.add.at, in the same order, a column at a time with np.bincount
    (about ten times faster than np.add.at on rows of vectors)."""
    for c in range(out.shape[1]):
        out[:, c] += np.bincount(rows, weights=q[:, c], minlength=out.shape[0])


def add_on_edges(gv: np.ndarray, v0: np.ndarray, v1: np.ndarray, t: np.ndarray, q: np.ndarray) -> None:
    """gv (V, 3) += per-point vectors q (N, 3) at the points (1 - t) v0 + t v1, to the two vertices linearly."""
    add_at(gv, v0, (1 - t)[:, None] * q)
    add_at(gv, v1, t[:, None] * q)


def add_on_triangles(gv: np.ndarray, indices: np.ndarray, tri: np.ndarray, bary: np.ndarray, q: np.ndarray) -> None:
    """gv (V, 3) += per-point vectors q (N, 3) at barycentrics ``bary`` (N, 2) of triangles ``tri`` (N,) of a mesh
    with ``indices``, to the three vertices by their barycentrics."""
    corners = np.asarray(indices, np.int64)[tri]
    for k, bk in enumerate((1 - bary[:, 0] - bary[:, 1], bary[:, 0], bary[:, 1])):
        add_at(gv, corners[:, k], bk[:, None] * q)


def along(velocity: np.ndarray, tangent: np.ndarray) -> np.ndarray:
    """(N,): per-point velocities (N, *parameter shape) contracted with a tangent of the parameter's shape."""
    return velocity.reshape(velocity.shape[0], int(np.prod(velocity.shape[1:]))) @ np.asarray(tangent).reshape(-1)


def vertex_gradients(params: SceneParameters, scene: Scene, i: int, names: Sequence[str], gv: np.ndarray,
                     out: dict[str, np.ndarray]) -> None:
    """Mesh i's gradients for ``names`` (its ``vertex_positions``, ``to_world``) into ``out``, from the gradient of
    its vertices' world positions gv (V, 3)."""
    for name in names:
        if name.endswith(".vertex_positions"):
            out[name] = gv.reshape(-1).astype(np.float32)
        else:  # positions = M rest: dL/dM = sum over vertices of dL/dp (rest, 1)^T
            _, rest = _rest(params, name, scene.meshes[i])
            gm = np.zeros((4, 4))
            gm[:3, :3] = gv.T @ rest
            gm[:3, 3] = gv.sum(0)
            out[name] = gm.astype(np.float32)


def vertex_motion(params: SceneParameters, scene: Scene, name: str, tangent: np.ndarray) -> tuple[int, np.ndarray]:
    """(mesh index, (V, 3) vertex velocities) of a tangent of ``SHAPE.vertex_positions`` or ``SHAPE.to_world``."""
    (i, _), = _meshes_of(scene, [name]).items()
    mesh = scene.meshes[i]
    tan = np.asarray(tangent, np.float64)
    if name.endswith(".vertex_positions"):
        return i, tan.reshape(mesh.positions.shape)
    _, rest = _rest(params, name, mesh)
    tm = tan.reshape(4, 4)
    return i, rest @ tm[:3, :3].T + tm[:3, 3]


def edge_point_motion(velocity: np.ndarray, v0: np.ndarray, v1: np.ndarray, t: np.ndarray, dp: np.ndarray
                      ) -> np.ndarray:
    """(N,) the normal motion velocity . dp of the edge points (1 - t) v0 + t v1 for vertex velocities dp."""
    return (1 - t) * np.einsum("nc,nc->n", velocity, dp[v0]) + t * np.einsum("nc,nc->n", velocity, dp[v1])


def splat_image(pixels: np.ndarray, weights: np.ndarray, values: np.ndarray, width: int, height: int) -> np.ndarray:
    """(H, W, 3) image of per-sample values (N, 3) through their filter weights."""
    contrib = weights[..., None] * values[:, None, :]
    image = np.zeros((width * height, 3))
    ok = pixels >= 0
    np.add.at(image, pixels[ok], contrib[ok])
    return image.reshape(height, width, 3).astype(np.float32)


def primary_boundary(scene: Scene, image_grad: np.ndarray, names: Sequence[str], *, samples: int = 65536,
                     seed: int = 0, max_depth: int | None = None, parameters: SceneParameters | None = None,
                     device: Device | str | None = None, stratified: bool = True) -> dict[str, np.ndarray]:
    """Reverse mode: the boundary term of primary visibility (outlines seen directly and in planar mirrors, which
    move with the mirror too) of dLoss/dparameter for ``names`` (``SHAPE.vertex_positions``, ``SHAPE.to_world``,
    ``SENSOR.to_world``; :func:`pyclpt.traverse`), given dLoss/dImage ``image_grad`` (H, W, 3) of an image rendered
    at that size: ``samples`` edge points, the radiance on both sides of each traced with ``seed``
    (:func:`sample_edges`).
    ``parameters``: the SceneParameters whose poses the ``to_world`` gradients are for (default: a new traverse,
    where every pose is the identity)."""
    g = np.asarray(image_grad, np.float64)
    if g.ndim != 3 or g.shape[2] != 3:
        raise ValueError(f"image_grad must be (H, W, 3), got {g.shape}")
    height, width = g.shape[:2]
    params = parameters if parameters is not None else traverse(scene)
    wanted = _meshes_of(scene, names)
    cameras = [n for n in names if n in sensor_names(scene)]
    meshes = range(len(scene.meshes)) if cameras else sorted(wanted)  # the camera moves every edge
    es = sample_edges(scene, meshes, width, height, samples=samples, seed=seed, max_depth=max_depth,
                      device=device, stratified=stratified, mirrors=sorted(wanted))  # a mirror moves all it shows
    weight = sample_weights(es.pixels, es.weights, g, es.jump)
    out: dict[str, np.ndarray] = {}
    for name in cameras:
        velocity = sensor_velocity(scene, width, height, es.seen_at, es.normal, name)  # the mirrors are still
        out[name] = np.tensordot(weight, velocity, axes=1).astype(np.float32)
    for i, mesh_names in wanted.items():
        gv = np.zeros((scene.meshes[i].positions.shape[0], 3))
        m = es.mesh == i  # its outlines
        add_on_edges(gv, es.v0[m], es.v1[m], es.t[m], es.velocity[m] * weight[m][:, None])
        m = es.mirror_mesh == i  # the outlines seen in it, a mirror
        gn = np.zeros_like(gv)  # and through its vertex normals, smooth-shaded
        if m.any():
            for j in range(3):
                add_at(gv, es.mirror_corners[m, j], es.mirror_velocity[m, j] * weight[m][:, None])
                add_at(gn, es.mirror_corners[m, j], es.mirror_normal_velocity[m, j] * weight[m][:, None])
        vertex_gradients(params, scene, i, mesh_names, gv, out)
        if gn.any():
            for name in mesh_names:
                out[name] = out[name] + _normals_chain(params, scene, i, name, gn, normals_backward).reshape(
                    out[name].shape).astype(np.float32)
    return out


def _normals_chain(params: SceneParameters, scene: Scene, i: int, name: str, value: np.ndarray,
                   chain: Callable[..., np.ndarray]) -> np.ndarray:
    """:func:`pyclpt.gradients.normals.normals_chain` for mesh i's parameter ``name``."""
    mesh = scene.meshes[i]
    return normals_chain(name, mesh.positions, mesh.indices, mesh.normals, value, params[name], chain)


def primary_boundary_forward(scene: Scene, name: str, tangent: np.ndarray, *, width: int | None = None,
                             height: int | None = None, samples: int = 65536, seed: int = 0,
                             max_depth: int | None = None, parameters: SceneParameters | None = None,
                             device: Device | str | None = None) -> np.ndarray:
    """Forward mode: the boundary term of primary visibility of d image (H, W, 3) along ``tangent`` (shaped as
    parameter ``name``'s value: (3 V,) for ``SHAPE.vertex_positions``, (4, 4) for ``SHAPE.to_world`` and
    ``SENSOR.to_world``). The
    same edge points as :func:`primary_boundary` for the same seed and size, so that
    ``sum(forward * image_grad) == sum(backward[name] * tangent)`` up to rounding."""
    width = width or scene.film.width
    height = height or scene.film.height
    params = parameters if parameters is not None else traverse(scene)
    tan = np.asarray(tangent, np.float64)
    if name in sensor_names(scene):  # every edge moves in the film
        es = sample_edges(scene, range(len(scene.meshes)), width, height, samples=samples, seed=seed,
                          max_depth=max_depth, device=device)
        velocity = sensor_velocity(scene, width, height, es.seen_at, es.normal, name)
        dx = along(velocity, tan)
    else:
        i, dp = vertex_motion(params, scene, name, tan)
        es = sample_edges(scene, [i], width, height, samples=samples, seed=seed, max_depth=max_depth,
                          device=device, mirrors=[i])
        own = es.mesh == i  # its outlines, then those seen in it, a mirror
        dx = np.zeros(len(own))
        dx[own] = edge_point_motion(es.velocity[own], es.v0[own], es.v1[own], es.t[own], dp)
        m = es.mirror_mesh == i
        if m.any():
            corners = es.mirror_corners[m]
            dx[m] += np.einsum("njc,njc->n", es.mirror_velocity[m], dp[corners])
            if scene.meshes[i].normals is not None:  # a smooth-shaded mirror turns with its vertex normals
                dn = _normals_chain(params, scene, i, name, tan, normals_forward).reshape(-1, 3)
                dx[m] += np.einsum("njc,njc->n", es.mirror_normal_velocity[m], dn[corners])
    return splat_image(es.pixels, es.weights, es.jump * dx[:, None], width, height)
