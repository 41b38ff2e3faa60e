"""The boundary term of hard shadows, by edge sampling from the lights (Li, Aittala, Durand and Lehtinen 2018).

A point, spot or directional light's shadow has a sharp outline on the surfaces it falls on: the receiver points whose
segment to the light grazes a silhouette edge of an occluder as the light sees it. Moving the occluder (or
the light) moves that outline over the receiver, and moving the camera moves it over the image: a jump of
the image's integrand along a curve, whose derivative is the same Reynolds term as the silhouettes'
(:mod:`pyclpt.gradients.edges`)::

    d/dtheta  integral w(x) L(x) dx  =  integral over the shadow outline's image of  w(x) (L_- - L_+) (n . dx/dtheta) dl

Points are sampled on the occluders' edges that the light sees as silhouettes (:func:`mesh_edges` from the
light's position), stratified along their total length; each is projected from the light onto the first
surface behind it (a ray cast with Embree on the host, through ``embreex``), kept where that point is lit
through the edge and seen by the camera (along its ray to the point: a pinhole's from its origin, an orthographic
camera's parallel one from its film rectangle, :meth:`Projection.rays_to`), and mapped to the image (a pinhole's
or an orthographic camera's affine projection). There the outline's normal and speed come from the chain light ->
edge point -> receiver plane -> film, and the radiance on its two sides from the ``edge_radiance`` kernel, as for
silhouettes.

Parameters: ``SHAPE.vertex_positions`` and ``SHAPE.to_world`` of the occluders and of the receivers (the outline
slides along the light's rays with the receiver's plane), ``SENSOR.to_world`` and ``SENSOR.x_fov`` (the outline is
fixed in the world and moves in the image), ``LIGHT.position`` of point lights. Left out (zero): shadows seen
through specular bounces, instanced shapes (refused).

Soft shadows (area lights, the environment, any incident light an occluder's silhouette cuts at the first
bounce) are :func:`soft_shadow_boundary`'s: an outline per shading point, on the sphere of directions, sampled
from each pixel's shading points with the ``vertex_radiance`` kernel.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable, Generator, Iterator, Sequence
from dataclasses import dataclass
from functools import partial
from typing import TypeVar

import numpy as np

from pyclpt.buffers.rfilter import sample_offsets
from pyclpt.device.context import Device
from pyclpt.gradients.edges import (
    CAMERA_STEP,
    FOV_STEP,
    SIDE_EPS,
    Projection,
    _filter_weights,
    _meshes_of,
    add_on_edges,
    add_on_triangles,
    along,
    edge_copies,
    edge_point_motion,
    mesh_edges,
    sample_weights,
    sensor_names,
    sensor_velocity,
    splat_image,
    vertex_gradients,
    vertex_motion,
)
from pyclpt.gradients.parameters import SceneParameters, traverse
from pyclpt.gradients.replay import SIDE_OCCLUDER, PathReplay
from pyclpt.gradients.session import replay_for
from pyclpt.scene.model import Camera, DirectionalLight, PointLight, Scene, SpotLight

T = TypeVar("T")

#: Relative offsets of the host's shadow-outline rays: the lit test stops this far short of the edge point, the
#: receiver ray starts this far beyond it, and the camera's view of the receiver point may end this far short.
RAY_EPS = 1e-4


@dataclass
class ShadowSamples:
    """Points of the shadow outlines in the image and what each contributes (see the module)."""

    pixels: np.ndarray  # (N, K) flat pixel indices the point's filter reaches (-1: none)
    weights: np.ndarray  # (N, K) the filter's normalised weights there
    jump: np.ndarray  # (N, 3) (L- - L+) x the outline's image length per sample
    mesh: np.ndarray  # (N,) index in scene.meshes of the occluder
    v0: np.ndarray  # (N,) the occluder edge's vertices
    v1: np.ndarray
    t: np.ndarray  # (N,) the edge point's parameter on v0 -> v1
    light: np.ndarray  # (N,) index in scene.lights
    velocity: np.ndarray  # (N, 3) n . d(film position)/d(edge point)
    light_velocity: np.ndarray  # (N, 3) n . d(film position)/d(light position)
    point: np.ndarray  # (N, 3) the receiver point (on the outline)
    normal: np.ndarray  # (N, 2) the outline's unit normal in the film plane (towards the "+" side)
    receiver: np.ndarray  # (N,) the receiver's mesh, its triangle (index in the mesh), barycentrics (N, 2) there
    rtri: np.ndarray
    rbary: np.ndarray
    receiver_velocity: np.ndarray  # (N, 3) n . d(film position)/d(the receiver's material point under the outline)


@dataclass
class HardLight:
    """A light whose shadows have sharp outlines: a point or spot light (``position``) or a directional one
    (``direction``, the way its parallel rays travel)."""

    index: int  # in scene.lights
    position: np.ndarray | None
    direction: np.ndarray | None

    def silhouettes(self, mesh) -> np.ndarray:
        """The vertex pairs (K, 2) of ``mesh``'s edges that this light sees as silhouettes."""
        pairs, _ = mesh_edges(mesh, self.position, direction=self.direction)
        return pairs

    def origins(self, q: np.ndarray, sphere: tuple[np.ndarray, float]) -> np.ndarray:
        """(N, 3) where the light's rays to the points q (N, 3) start: its position; for a directional light a
        point behind each q along its rays, outside the scene's bounding ``sphere`` (centre, radius)."""
        if self.position is not None:
            return np.broadcast_to(self.position, q.shape)
        c, r = sphere
        back = 2.0 * (np.linalg.norm(q - c, axis=1) + r) + 1.0
        return q - back[:, None] * self.direction[None]


def hard_lights(scene: Scene) -> list[HardLight]:
    """The scene's point, spot and directional lights."""
    out = []
    for k, light in enumerate(scene.lights):
        if isinstance(light, (PointLight, SpotLight)):
            out.append(HardLight(k, np.asarray(light.position, np.float64), None))
        elif isinstance(light, DirectionalLight):
            out.append(HardLight(k, None, np.asarray(light.direction, np.float64)))
    return out


def scene_sphere(scene: Scene) -> tuple[np.ndarray, float]:
    """The centre and radius of a sphere around every mesh's vertices."""
    p = np.concatenate([m.positions for m in scene.meshes]).astype(np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    return 0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo))


class _HostTracer:
    """Closest hits of the scene's triangles (world space) on the host, with Embree through embreex."""

    def __init__(self, scene: Scene) -> None:
        from embreex import mesh_construction, rtcore_scene

        if scene.instances:
            raise ValueError(f"scene {scene.name!r}: the shadow boundary term does not handle instanced shapes "
                             f"({len(scene.instances)} instances)")
        positions, indices = [], []
        offset = 0
        for mesh in scene.meshes:
            positions.append(mesh.positions.astype(np.float32))
            indices.append(mesh.indices.astype(np.int32) + offset)
            offset += len(mesh.positions)
        self.first_triangle = np.cumsum([0] + [len(m.indices) for m in scene.meshes[:-1]])
        self.scene = rtcore_scene.EmbreeScene()
        mesh_construction.TriangleMesh(self.scene, np.ascontiguousarray(np.concatenate(positions)),
                                       np.ascontiguousarray(np.concatenate(indices)))

    def hit(self, org: np.ndarray, dirs: np.ndarray, tmax: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
        """Distance (inf: no hit) and geometric normal (N, 3) of the first hit of each ray (unit dirs)."""
        t, ng, _ = self.hit_mesh(org, dirs, tmax)
        return t, ng

    def hit_mesh(self, org: np.ndarray, dirs: np.ndarray, tmax: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`hit`, and the index in scene.meshes of the mesh hit (-1: none)."""
        t, ng, mesh, _, _ = self.hit_triangle(org, dirs, tmax)
        return t, ng, mesh

    def hit_triangle(self, org: np.ndarray, dirs: np.ndarray, tmax: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`hit_mesh`, the triangle hit (its index in its mesh) and the barycentrics (N, 2) there."""
        if not len(org):
            return (np.zeros(0), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2)))
        dists = None if tmax is None else np.ascontiguousarray(tmax, np.float32)
        out = self.scene.run(np.ascontiguousarray(org, np.float32), np.ascontiguousarray(dirs, np.float32),
                             dists, output=1)
        hit = out["primID"] >= 0
        mesh = np.where(hit, np.searchsorted(self.first_triangle, out["primID"], side="right") - 1, -1)
        tri = np.where(hit, out["primID"] - self.first_triangle[np.maximum(mesh, 0)], -1)
        bary = np.stack([out["u"], out["v"]], axis=1).astype(np.float64)
        return np.where(hit, out["tfar"].astype(np.float64), np.inf), out["Ng"].astype(np.float64), mesh, tri, bary


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = np.sqrt(np.einsum("...c,...c->...", v, v))
    return v / np.maximum(n, 1e-300)[..., None], n


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, 3): the cross products of rows (np.cross without its axis shuffling, a third of its time)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def receiver_motion(p: np.ndarray, q: np.ndarray, light: np.ndarray, n_r: np.ndarray,
                    parallel: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """How the receiver point p = l + sigma (q - l) (on a plane of normal n_r) moves with the edge point q and the
    light l: dp = P ((1 - sigma) dl + sigma dq), P = I - d n_r^T / (d . n_r) projecting along the ray d onto the
    plane; where ``parallel`` (N,) (a directional light's rays, from a point l behind q along them) sigma is 1.
    Returns sigma (N,) and P (N, 3, 3)."""
    d, dist = _unit(q - light)
    sigma = np.linalg.norm(p - light, axis=1) / np.maximum(dist, 1e-300)
    if parallel is not None:
        sigma = np.where(parallel, 1.0, sigma)
    dn = np.einsum("nc,nc->n", d, n_r)
    return sigma, np.eye(3)[None] - d[:, :, None] * n_r[:, None, :] / dn[:, None, None]


def sample_shadow_edges(scene: Scene, meshes: Sequence[int], width: int, height: int, *, samples: int, seed: int,
                        max_depth: int | None = None, device: Device | str | None = None,
                        stratified: bool = True, receivers: Sequence[int] | None = None) -> ShadowSamples:
    """``samples`` points on the edges of ``scene.meshes[i]`` (i in ``meshes``) that the scene's point, spot and
    directional lights see as silhouettes, stratified along their total length in the world, mapped to the shadow
    outline they cast in the image (the points that cast none are dropped, and with ``receivers`` those whose outline
    falls on another mesh), with the radiance on both sides there."""
    cols: dict[str, list[np.ndarray]] = {k: [] for k in ("light", "mesh", "v0", "v1")}
    lights = {h.index: h for h in hard_lights(scene)}
    for k, light in lights.items():
        for i in meshes:
            pairs = light.silhouettes(scene.meshes[i])
            for key, v in (("light", np.full(len(pairs), k)), ("mesh", np.full(len(pairs), i)),
                           ("v0", pairs[:, 0]), ("v1", pairs[:, 1])):
                cols[key].append(v)
    edges = {k: np.concatenate(v) if v else np.zeros(0, np.int64) for k, v in cols.items()}
    a = np.zeros((len(edges["v0"]), 3))
    b = np.zeros_like(a)
    for i in set(edges["mesh"].tolist()):
        m = edges["mesh"] == i
        p = scene.meshes[i].positions.astype(np.float64)
        a[m], b[m] = p[edges["v0"][m]], p[edges["v1"][m]]
    lengths = np.linalg.norm(b - a, axis=1)
    total = float(lengths.sum())
    empty = ShadowSamples(np.zeros((0, 1), np.int64), np.zeros((0, 1)), np.zeros((0, 3)),
                          *(np.zeros(0, np.int64) for _ in range(3)), np.zeros(0), np.zeros(0, np.int64),
                          np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 2)),
                          np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 3)))
    if samples <= 0 or total <= 0:
        return empty
    rng = np.random.default_rng([seed, 0x736861646F77])  # "shadow"
    u = ((np.arange(samples) if stratified else 0) + rng.random(samples)) / (samples if stratified else 1) * total
    cdf = np.cumsum(lengths)
    e = np.minimum(np.searchsorted(cdf, u, side="right"), len(lengths) - 1)
    t = np.clip((u - (cdf[e] - lengths[e])) / np.maximum(lengths[e], 1e-300), 0.0, 1.0)
    point_on_edge = a[e] + t[:, None] * (b[e] - a[e])
    sphere = scene_sphere(scene)
    light_pos = np.zeros((len(e), 3))
    for k, light in lights.items():
        m = edges["light"][e] == k
        light_pos[m] = light.origins(point_on_edge[m], sphere)
    parallel = np.array([lights[k].direction is not None for k in edges["light"][e]], bool)
    d, dist = _unit(point_on_edge - light_pos)
    tracer = _HostTracer(scene)
    # lit through the edge: nothing between the light and the edge point
    before, _ = tracer.hit(light_pos, d, dist * (1 - RAY_EPS))
    # the receiver: the first surface behind the edge point, along the light's ray
    start = point_on_edge + (RAY_EPS * dist)[:, None] * d
    beyond, ng, r_mesh, r_tri, r_bary = tracer.hit_triangle(start, d)
    keep = np.isinf(before) & np.isfinite(beyond) & (dist > 0)
    if receivers is not None:
        keep &= np.isin(r_mesh, np.asarray(list(receivers), np.int64))
    receiver = start + np.where(np.isfinite(beyond), beyond, 0.0)[:, None] * d
    # seen by the camera
    proj = Projection.of(scene, width, height, orthographic=True)
    eye, view, view_dist = proj.rays_to(receiver)  # an orthographic camera's: parallel, from its film rectangle
    seen, _ = tracer.hit(eye, view)
    keep &= (proj.depth(receiver) > 0) & (seen >= view_dist * (1 - 1e-3))
    x = proj.film(receiver)
    keep &= np.all(np.isfinite(x), axis=1) & (x[:, 0] >= 0) & (x[:, 0] <= width) & (x[:, 1] >= 0) & (x[:, 1] <= height)
    n_r, _ = _unit(ng)
    dn = np.einsum("nc,nc->n", d, n_r)
    keep &= np.abs(dn) > 1e-6
    idx = np.flatnonzero(keep)
    if not len(idx):
        return empty
    e, t, d, dn, n_r, x = e[idx], t[idx], d[idx], dn[idx], n_r[idx], x[idx]
    r_mesh, r_tri, r_bary = r_mesh[idx], r_tri[idx], r_bary[idx]
    p, q, lp = receiver[idx], point_on_edge[idx], light_pos[idx]
    sigma, proj_along = receiver_motion(p, q, lp, n_r, parallel[idx])
    jac = np.stack([proj.normal_velocity(p, np.tile([1.0, 0.0], (len(p), 1))),
                    proj.normal_velocity(p, np.tile([0.0, 1.0], (len(p), 1)))], axis=1)  # (N, 2, 3) d film / dp
    edge_vec = b[e] - a[e]
    tangent = np.einsum("nij,njk,nk->ni", jac, proj_along, edge_vec) * sigma[:, None]  # d film / dt
    normal, speed = _unit(np.stack([-tangent[:, 1], tangent[:, 0]], axis=1))
    ok = speed > 1e-12
    through = np.einsum("ni,nij,njk->nk", normal, jac, proj_along)  # n . d film / d(receiver point, pre-P)
    replay = replay_for(scene, width=width, height=height, max_depth=max_depth, device=device)
    points = np.concatenate([x, normal], axis=1).astype(np.float32)
    radiance = replay.edge_radiance(points, seed, SIDE_EPS).astype(np.float64)  # (N, 2, 3): minus, plus
    # the outline's image length per sample: |d film/dt| / (density of t: the edge's share of the total length)
    measure = np.where(ok, speed * total / (lengths[e] * samples), 0.0)
    pix, w, _ = _filter_weights(scene.film.rfilter, x, width, height)
    # the receiver moving with its plane: the outline point slides along the light's ray d to the moved plane,
    # dp = d (n_r . dx_r) / (n_r . d)
    along = np.einsum("ni,nij,nj->n", normal, jac, d) / dn
    return ShadowSamples(pix, w, (radiance[:, 0] - radiance[:, 1]) * measure[:, None], edges["mesh"][e],
                         edges["v0"][e], edges["v1"][e], t, edges["light"][e], through * sigma[:, None],
                         through * (1 - sigma)[:, None], p, normal, r_mesh, r_tri, r_bary, along[:, None] * n_r)


def moving_light_names(scene: Scene) -> dict[str, int]:
    """{parameter name: index in scene.lights} of the lights whose position moves hard shadows: point lights'
    ``position``, spot lights' ``to_world`` (its translation)."""
    out = {}
    for k, light in enumerate(scene.lights):
        name = scene.ids.get(f"light:{k}", f"light_{k}")
        if isinstance(light, PointLight):
            out[f"{name}.position"] = k
        elif isinstance(light, SpotLight):
            out[f"{name}.to_world"] = k
    return out


def shadow_boundary(scene: Scene, image_grad: np.ndarray, names: Sequence[str], *, samples: int = 65536,
                    seed: int = 0, max_depth: int | None = None, parameters: SceneParameters | None = None,
                    device: Device | str | None = None, stratified: bool = True) -> dict[str, np.ndarray]:
    """Reverse mode: the boundary term of hard shadows of dLoss/dparameter for ``names`` (``SHAPE.vertex_positions``
    and ``SHAPE.to_world`` of occluders, ``SENSOR.to_world``, ``LIGHT.position`` of point lights), given dLoss/dImage
    ``image_grad`` (H, W, 3); add it to :func:`pyclpt.gradients.edges.primary_boundary`'s for the same names.
    ``parameters``: the SceneParameters whose poses the ``to_world`` gradients are for (default: a new traverse)."""
    g = np.asarray(image_grad, np.float64)
    if g.ndim != 3 or g.shape[2] != 3:
        raise ValueError(f"image_grad must be (H, W, 3), got {g.shape}")
    height, width = g.shape[:2]
    params = parameters if parameters is not None else traverse(scene)
    cameras = [n for n in names if n in sensor_names(scene)]
    light_names = moving_light_names(scene)
    wanted = _meshes_of(scene, [n for n in names if n not in light_names])
    moving_all = bool(cameras) or any(n in light_names for n in names)
    meshes = range(len(scene.meshes)) if moving_all else sorted(wanted)
    ss = sample_shadow_edges(scene, meshes, width, height, samples=samples, seed=seed, max_depth=max_depth,
                             device=device, stratified=stratified)
    weight = sample_weights(ss.pixels, ss.weights, g, ss.jump)
    out: dict[str, np.ndarray] = {}
    for name in cameras:
        velocity = sensor_velocity(scene, width, height, ss.point, ss.normal, name)
        out[name] = np.tensordot(weight, velocity, axes=1).astype(np.float32)
    for name, k in light_names.items():
        if name in names:
            m = ss.light == k
            gl = (weight[m, None] * ss.light_velocity[m]).sum(0)  # not g: the receivers' weights below read it
            if name.endswith(".to_world"):  # a spot light's pose: its translation moves the outlines
                pose = np.zeros((4, 4))
                pose[:3, 3] = gl
                gl = pose
            out[name] = gl.astype(np.float32)
    if wanted:  # as receivers: the outlines every occluder casts on them move with them
        rs = sample_shadow_edges(scene, range(len(scene.meshes)), width, height, samples=samples, seed=seed,
                                 max_depth=max_depth, device=device, stratified=stratified, receivers=sorted(wanted))
        r_weight = sample_weights(rs.pixels, rs.weights, g, rs.jump)
    for i, mesh_names in wanted.items():
        gv = np.zeros((scene.meshes[i].positions.shape[0], 3))
        m = ss.mesh == i
        add_on_edges(gv, ss.v0[m], ss.v1[m], ss.t[m], ss.velocity[m] * weight[m][:, None])
        r = rs.receiver == i
        add_on_triangles(gv, scene.meshes[i].indices, rs.rtri[r], rs.rbary[r],
                         rs.receiver_velocity[r] * r_weight[r][:, None])
        vertex_gradients(params, scene, i, mesh_names, gv, out)
    return out


#: Angular offset (radians) of the two directions either side of a soft-shadow edge point.
SOFT_SIDE_EPS = 1e-4
# camera shading points a band of pixels of the soft-shadow term (soft_sample_chunks)
SOFT_CHUNK = 1 << 16
#: Floats of an edge record of the silhouette search (EDGE_STRIDE of cl/gradients/edge_pick.h).
EDGE_STRIDE = 16


@dataclass
class MeshEdges:
    """Every edge of a mesh once, with the one or two triangles it bounds (for silhouettes seen from points)."""

    v0: np.ndarray  # (E,) vertex indices
    v1: np.ndarray
    face_a: np.ndarray  # (E,) a triangle of the edge
    face_b: np.ndarray  # (E,) the other (-1: a boundary edge; an edge of more than two counts as a boundary)

    @classmethod
    def of(cls, mesh) -> MeshEdges:
        """``mesh``'s edges, welded by position (:func:`pyclpt.gradients.edges.edge_copies`); ``v0``, ``v1``: the
        vertex indices of ``face_a``'s copy."""
        pairs, face, new = edge_copies(mesh)
        first = np.flatnonzero(new)
        count = np.diff(np.append(first, len(pairs)))
        face_b = np.where(count == 2, face[np.minimum(first + 1, len(pairs) - 1)], -1)
        return cls(pairs[first, 0], pairs[first, 1], face[first], face_b)

    def records(self, positions: np.ndarray, indices: np.ndarray, face_normals: np.ndarray, mesh: int = 0
                ) -> np.ndarray:
        """(E, EDGE_STRIDE) float32: the edges as the silhouette search reads them (cl/gradients/edge_pick.h):
        end points, the unit normal n of each face and n . p for a vertex p of it (a boundary edge's second face
        repeats its first), 1 for a boundary edge, and the index ``mesh`` of their mesh."""
        length = np.linalg.norm(face_normals, axis=1, keepdims=True)
        unit = np.divide(face_normals, length, out=np.zeros_like(face_normals), where=length > 0)
        fb = np.where(self.face_b >= 0, self.face_b, self.face_a)
        rec = np.zeros((len(self.v0), EDGE_STRIDE), np.float32)
        rec[:, 0:3], rec[:, 3:6] = positions[self.v0], positions[self.v1]
        for at, face in ((6, self.face_a), (10, fb)):
            rec[:, at:at + 3] = unit[face]
            rec[:, at + 3] = np.einsum("ec,ec->e", unit[face], positions[indices[face, 0]])
        rec[:, 14] = self.face_b < 0
        rec[:, 15] = mesh
        return rec


def _camera_rays(scene: Scene, film: np.ndarray, width: int, height: int, camera: Camera | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions of the camera's rays (``camera``'s, else the scene's) through film positions
    (N, 2), as the kernels' camera_ray makes them: a pinhole's from its origin through the film plane at unit depth;
    an orthographic camera's parallel, along forward from the film rectangle (origin + sx right + sy up)."""
    cam = scene.camera if camera is None else camera
    o, f, r, u = (np.asarray(v, np.float64) for v in cam.basis(width, height))
    sx = 2.0 * film[:, 0] / width - 1.0
    sy = 1.0 - 2.0 * film[:, 1] / height
    if cam.kind == "orthographic":
        d, _ = _unit(np.tile(f, (len(film), 1)))
        return o[None] + sx[:, None] * r[None] + sy[:, None] * u[None], d
    d, _ = _unit(f[None] + sx[:, None] * r[None] + sy[:, None] * u[None])
    return np.broadcast_to(o, d.shape).copy(), d


@dataclass
class SoftSamples:
    """Points on the occluders' silhouettes seen from the shading points, and what each contributes."""

    pixels: np.ndarray  # (N, 1) the flat index of the pixel the shading point stands for
    weights: np.ndarray  # (N, 1) 1 (its film position was drawn from the pixel's filter)
    jump: np.ndarray  # (N, 3) f |cos| (L_i- - L_i+) x the curve's measure per sample
    mesh: np.ndarray  # (N,) index in scene.meshes of the occluder
    v0: np.ndarray  # (N,) the edge's vertices
    v1: np.ndarray
    t: np.ndarray  # (N,) the edge point's parameter on v0 -> v1
    velocity: np.ndarray  # (N, 3) n . d(direction)/d(edge point) = n / |e - x|
    # the shading point: its mesh and triangle (index in the mesh), barycentrics (N, 2) there, its film position
    # (N, 2) and the camera ray's direction (N, 3) it lies on, the triangle's unit normal (N, 3)
    receiver: np.ndarray
    tri: np.ndarray
    bary: np.ndarray
    film: np.ndarray
    ray: np.ndarray
    receiver_normal: np.ndarray
    point: np.ndarray  # (N, 3) the shading point
    # (N,): False for a camera hit (it slides on its camera ray), True for a later vertex of a camera path (attached
    # to its surface: path_vertices)
    attached: np.ndarray
    # what the occluder hides there (the first hit of the side that passes it): its mesh (-1: none, the
    # environment), triangle (index in its mesh), barycentrics (N, 2), distance (inf: none); the edge point's
    background: np.ndarray
    back_tri: np.ndarray
    back_bary: np.ndarray
    back_dist: np.ndarray
    edge_dist: np.ndarray

    @property
    def relative(self) -> np.ndarray:
        """(N,): 1 - |e - x| / |b - x|: the outline's direction moves with the shading point x as 1 / |e - x|, the
        (attached) background point b behind it as 1 / |b - x|; the boundary term is their difference."""
        return 1.0 - self.edge_dist / self.back_dist

    def receiver_velocity(self) -> np.ndarray:
        """(N, 3): n . d(outline's direction relative to the background)/d(the shading point's triangle's material
        point under it): the shading point slides along its camera ray, x = o + d (n_r . (p - o)) / (n_r . d), so
        n . (dw_e - dw_b) = -(n . d) (n_r . dp) (1 / |e - x| - 1 / |b - x|) / (n_r . d), n the outline's normal
        (velocity = n / |e - x|)."""
        nd = np.einsum("nc,nc->n", self.receiver_normal, self.ray)
        k = -np.einsum("nc,nc->n", self.velocity, self.ray) / np.where(nd != 0, nd, np.inf) * self.relative
        # a later vertex is attached to its surface, x = p: -n . dp (1 / |e - x| - 1 / |b - x|)
        return np.where(self.attached[:, None], -self.velocity * self.relative[:, None],
                        k[:, None] * self.receiver_normal)

    def background_velocity(self) -> np.ndarray:
        """(N, 3): n . d(outline's direction relative to the background)/d(the background's material point):
        -n / |b - x|."""
        return -self.velocity * (self.edge_dist / self.back_dist)[:, None]


def _at_bary(corners: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """(N, 3): the points at barycentrics ``bary`` (N, 2) of triangles with ``corners`` (N, 3, 3)."""
    return ((1.0 - bary[:, 0] - bary[:, 1])[:, None] * corners[:, 0] + bary[:, :1] * corners[:, 1]
            + bary[:, 1:] * corners[:, 2])


def _bands(pixels: int, spp: int, band: Callable[[int, int], Generator[None, None, T]]) -> Iterator[T]:
    """The pixels in runs of SOFT_CHUNK // spp (the soft and later hard-shadow terms), each run's samples from
    ``band(p0, p1)``: a generator that yields twice, each time after enqueuing kernels whose results it reads next
    (its shading points', then its sides'), and returns the run's samples. Pipelined so that the device always
    has a kernel queued while the host works: run k's host work (its shading points back, its samples' tables,
    then its sides back and their arrays) goes while the kernels of runs k + 1 and k + 2 run, and run k's samples
    are yielded (the caller's sums) while they still do. In order; the same samples as one run at a time."""
    step = max(1, SOFT_CHUNK // spp)
    runs = [band(p0, min(p0 + step, pixels)) for p0 in range(0, pixels, step)]
    done: dict[int, T] = {}

    def advance(k: int) -> None:
        if 0 <= k < len(runs) and k not in done:
            try:
                next(runs[k])
            except StopIteration as stop:
                done[k] = stop.value

    # the queue's order: shading points 0, 1, sides 0, shading points 2, sides 1, shading points 3, sides 2, ...
    for k in range(-3, len(runs)):
        advance(k + 1)  # its shading points back: its sides' kernel enqueued
        advance(k + 3)  # its shading points' kernel enqueued
        if k >= 0:
            advance(k)  # its sides back: its samples
            yield done.pop(k)


def shading_points_started(replay, rfilter, width: int, p0: int, p1: int, spp: int, rng: np.random.Generator,
                           later: bool) -> Callable[[], tuple[np.ndarray, ...]]:
    """The shading points of pixels p0 .. p1 - 1 (flat indices, rows of ``width``), ``spp`` film positions each
    drawn from the pixel's filter: the camera rays' first hits, and (with ``later``, where the depth allows a
    bounce after them) the later vertices of camera paths through the same film positions (path_vertices: one a
    path, attached to its surface, weighted by the throughput that reached it). Returns their film positions
    (N, 2), pixels (N,), leaf-order triangles (N,) (-1: none), bounces (N,), tables (N, 8) (barycentrics, the
    direction back along the path, for the camera's hits their film positions and 0, the vertex_radiance.cl
    convention, and the throughput that reached them) and whether each is attached (a later vertex) (N,), from
    the call returned: the path_vertices kernel is enqueued, and that call waits for it."""
    pix = np.repeat(np.arange(p0, p1), spp)
    cell, u = np.stack([pix % width, pix // width], axis=1), rng.random((len(pix), 2))
    film = cell + u if rfilter.kind == "box" else cell + 0.5 + sample_offsets(rfilter, u)
    vertices = replay.path_vertices_started(film, int(rng.integers(2**32)))
    return partial(_shading_points, replay, film, pix, later, vertices)


def _shading_points(replay, film: np.ndarray, pix: np.ndarray, later: bool, vertices: Callable[[], tuple]
                    ) -> tuple[np.ndarray, ...]:
    """:func:`shading_points_started`'s results, once the path_vertices kernel (``vertices``) is done."""
    vprim, vert, vdepth, prim, hit = vertices()
    n_first = len(film)
    table = np.zeros((n_first, 8), np.float32)
    table[:, :2], table[:, 2:4], table[:, 5:] = hit[:, 1:], film, 1.0
    attached = np.zeros(n_first, bool)
    depth = np.zeros(n_first, np.int32)
    if later and (replay.max_depth < 0 or replay.max_depth > 2):  # a bounce after the camera's hit's
        keep = np.flatnonzero(vprim >= 0)
        film, pix = np.concatenate([film, film[keep]]), np.concatenate([pix, pix[keep]])
        prim, depth = np.concatenate([prim, vprim[keep]]), np.concatenate([depth, vdepth[keep]])
        table = np.concatenate([table, vert[keep]])
        attached = np.concatenate([attached, np.ones(len(keep), bool)])
    return film, pix, prim, depth, table, attached


def _triangle_tables(scene: Scene, replay: PathReplay) -> tuple[np.ndarray, np.ndarray]:
    """Where each mesh's triangles start in the scene's triangle list (M + 1,), and the BVH's leaf order of them
    (the kernels' primitive ids are leaf-order positions)."""
    return np.cumsum([0] + [m.triangle_count for m in scene.meshes]), replay.scene.arrays.bvh.tri_order


def _mesh_of(first: np.ndarray, order: np.ndarray, prims: np.ndarray) -> np.ndarray:
    """The mesh (index in scene.meshes) of leaf-order triangles ``prims`` (-1: none) (:func:`_triangle_tables`)."""
    return np.where(prims >= 0, np.searchsorted(first, order[np.maximum(prims, 0)], side="right") - 1, -1)


def soft_sample_chunks(scene: Scene, meshes: Sequence[int], width: int, height: int, *, spp: int, seed: int,
                       max_depth: int | None = None, device: Device | str | None = None,
                       receivers: Sequence[int] = (), camera: bool = False, later: bool = True
                       ) -> Iterator[SoftSamples]:
    """``spp`` shading points a pixel (the camera rays' first hits, from the path_vertices kernel), each with one
    point on an edge of the meshes ``scene.meshes[i]`` (i in ``meshes``, the point's own too) that is a silhouette
    from it, chosen in proportion to the angle the edges subtend, and the radiance either side, both from the
    vertex_radiance kernel (see :func:`soft_shadow_boundary`). With ``receivers`` (mesh indices) the shading points
    on those meshes choose among the edges of every other mesh (their own motion moves the outlines they see);
    with ``camera``, every shading point does. With ``later``,
    also one later vertex of a camera path through each of the same film positions (the path_vertices kernel: a
    vertex after the first bounce, weighted by the throughput that reached it), whose incident light's outlines
    move as its surface (attached), the occluders and what they hide move, not with the camera.
    A shading point stands for its own pixel alone (``pixels`` (N, 1), ``weights`` 1): its film position is drawn
    from the pixel's filter (filter importance sampling, :func:`pyclpt.buffers.rfilter.sample_offsets`; the box:
    uniform in the pixel), rather than spread over the 16 pixels Mitsuba's gaussian reaches (its (N, 16) tables
    took a third of the term's time).
    The pixels go in bands of SOFT_CHUNK // spp (each band's random numbers keyed by (seed, its first pixel)), one
    SoftSamples a band: every host array of a band stays a few MB, so the allocator reuses the last band's
    memory instead of mapping fresh pages (on a VM that maps them slowly, a third of the term's time)."""
    Projection.of(scene, width, height, orthographic=True)  # pinhole and orthographic cameras (a thin lens: refused)
    rfilter = scene.film.rfilter
    replay = replay_for(scene, width=width, height=height, max_depth=max_depth, device=device)
    first, order = _triangle_tables(scene, replay)

    def prim_mesh(prims: np.ndarray) -> np.ndarray:
        return _mesh_of(first, order, prims)

    # One sample a shading point: an edge that is a silhouette from it, picked in proportion to the angle it
    # subtends, its own mesh's included (a mesh's outlines on itself; not the edges of its own triangle): for a
    # point that moves, among every mesh's; for a still one, among the moving meshes' (SOFT_MOVING_SHARE of them)
    # or the still meshes' near a moving one, whose outline over a moving background moves relative to it
    # (cl/gradients/edge_pick.h). The edge records in one array, a block a mesh, the occluders' first.
    occluders = sorted(set(meshes))
    others = sorted(set(range(len(scene.meshes))) - set(occluders))
    moving_meshes = set(occluders) | set(receivers)
    records, v0s, v1s, blocks, spheres = [], [], [], [], []
    for i in occluders + others:
        mesh = scene.meshes[i]
        p = mesh.positions.astype(np.float64)
        tri = mesh.indices.astype(np.int64)
        edges = MeshEdges.of(mesh)
        rec = edges.records(p, tri, np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]]), i)
        # an edge between two faces of one plane (a quad's diagonal) is never a silhouette: left out
        flat = np.all(rec[:, 6:10] == rec[:, 10:14], axis=1) & (rec[:, 14] == 0)
        records.append(rec[~flat])
        v0s.append(edges.v0[~flat])
        v1s.append(edges.v1[~flat])
        # a block a mesh (edge_pick.h): its first edge, count, whether it moves, its bounding sphere
        blocks.append([sum(len(r) for r in records[:-1]), len(records[-1]), i in moving_meshes])
        lo, hi = p.min(axis=0), p.max(axis=0)
        spheres.append([*(0.5 * (lo + hi)), 0.5 * np.linalg.norm(hi - lo) * (1 + 1e-4) + 1e-6])
    n_edges = sum(len(r) for r in records)
    if not n_edges:
        return
    edge_records, edge_v0, edge_v1 = np.concatenate(records), np.concatenate(v0s), np.concatenate(v1s)
    block_table, sphere_table = np.asarray(blocks, np.int32), np.asarray(spheres, np.float32)
    mesh_vertices = np.cumsum([0] + [m.positions.shape[0] for m in scene.meshes]).astype(np.int32)
    mesh_moving = np.isin(np.arange(len(scene.meshes)), sorted(moving_meshes)).astype(np.int32)
    positions = np.concatenate([m.positions for m in scene.meshes]).astype(np.float64)

    def band(p0: int, p1: int) -> Generator[None, None, SoftSamples]:
        """The samples of pixels p0 .. p1 - 1 (:func:`_bands`: yields when a kernel is enqueued)."""
        rng = np.random.default_rng([seed, 0x736F6674, p0])  # "soft"
        points = shading_points_started(replay, rfilter, width, p0, p1, spp, rng, later)
        yield
        film, pix, prim, depth, table, attached = points()
        valid = prim >= 0
        mesh_hit = prim_mesh(prim)
        tri_hit = np.where(valid, order[np.maximum(prim, 0)] - first[np.maximum(mesh_hit, 0)], -1)

        # shading points that move: on a moving mesh, or (the camera's hits, sliding on its rays) with the camera
        moving = np.isin(mesh_hit, np.asarray(list(receivers), np.int64)) | (camera & ~attached)
        sel = np.flatnonzero(valid)
        if not len(sel):
            return _no_soft_samples()
        samples = np.empty((len(sel), 8), np.float32)
        samples[:, :5] = table[sel, :5]
        # the edge's pick, its point t, the pick's strategy (edge_pick.h)
        samples[:, 5:] = u = rng.random((len(sel), 3)).astype(np.float32)
        sides = replay.vertex_radiance_started(
            prim[sel], samples, depth[sel], moving[sel], edge_records, block_table, sphere_table, mesh_vertices,
            mesh_moving, int(rng.integers(2**32)), SOFT_SIDE_EPS)
        yield
        radiance, prims, hits, pick, outline = sides()
        # the curve integral per shading point: jump x |d w/dt| / p(edge), a shading point per 1/spp pixel (the side
        # whose ray meets the occluder first is 0: the material form, cl/gradients/incident.h); a sample with no jump
        # (no silhouette, both sides meet the occluder or pass it, the same light) contributes nothing: left out
        r = radiance.reshape(-1, 6)
        nz = np.flatnonzero(((r[:, 0] != r[:, 3]) | (r[:, 1] != r[:, 4]) | (r[:, 2] != r[:, 5])) & (outline[:, 0] > 0))
        edge = pick[nz]
        mesh = edge_records[edge, 15].astype(np.int64)
        sel, prims, hits, outline = sel[nz], prims[nz], hits[nz], outline[nz].astype(np.float64)
        jump = (radiance[nz, 0] - radiance[nz, 1]).astype(np.float64) * (outline[:, 0] / spp)[:, None] * table[sel, 5:]
        # The material form (the interior term's: points on the surfaces move with them): the occluder's own radiance
        # has no jump at its outline, what it hides behind does: the outline moves relative to that background, the
        # first hit of the side that passes the occluder at the edge (the other side's is SIDE_OCCLUDER), which may
        # be the occluder itself further on (a concave mesh, a mesh shadowing itself).
        rows = np.arange(len(sel))
        side = np.where(prims[:, 0] == SIDE_OCCLUDER, 1, 0)
        back_prim = prims[rows, side]
        back = prim_mesh(back_prim)
        back_prim = np.maximum(back_prim, 0)
        dist = outline[:, 1]
        # the shading points (their barycentric points), their triangles' unit normals, the rays that reach them
        bary = table[sel, :2].astype(np.float64)
        corners = positions[replay.scene.arrays.tri_vidx[prim[sel]]]  # (n, 3, 3), leaf order
        x = _at_bary(corners, bary)
        ng, _ = _unit(_cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]))
        ray = -table[sel, 2:5].astype(np.float64)
        at_camera = np.flatnonzero(~attached[sel])
        ray[at_camera] = _camera_rays(scene, film[sel[at_camera]], width, height)[1]
        return SoftSamples(
            pix[sel][:, None], np.ones((len(sel), 1)), jump, mesh, edge_v0[edge], edge_v1[edge],
            u[nz, 1].astype(np.float64), outline[:, 2:5] / dist[:, None],  # n is normal to w: n / |e - x|
            mesh_hit[sel], tri_hit[sel], bary, film[sel], ray, ng, x, attached[sel], back,
            np.where(back >= 0, order[back_prim] - first[np.maximum(back, 0)], -1),
            hits[rows, side, 1:].astype(np.float64),
            np.where(back >= 0, hits[rows, side, 0].astype(np.float64), np.inf), dist)

    yield from _bands(width * height, spp, band)


def sample_soft_edges(scene: Scene, meshes: Sequence[int], width: int, height: int, *, spp: int, seed: int,
                      max_depth: int | None = None, device: Device | str | None = None,
                      receivers: Sequence[int] = (), camera: bool = False, later: bool = True) -> SoftSamples:
    """All of :func:`soft_sample_chunks` in one SoftSamples."""
    bands = list(soft_sample_chunks(scene, meshes, width, height, spp=spp, seed=seed, max_depth=max_depth,
                                    device=device, receivers=receivers, camera=camera, later=later))
    if not bands:
        return _no_soft_samples()
    return SoftSamples(*(np.concatenate([getattr(b, f.name) for b in bands])
                         for f in dataclasses.fields(SoftSamples)))


def _no_soft_samples() -> SoftSamples:
    z, z3, zi = np.zeros(0), np.zeros((0, 3)), np.zeros(0, np.int64)
    return SoftSamples(np.zeros((0, 1), np.int64), np.zeros((0, 1)), z3, zi, zi, zi, z, z3, zi, zi, np.zeros((0, 2)),
                       np.zeros((0, 2)), z3, z3, z3, np.zeros(0, bool), zi, zi, np.zeros((0, 2)), z, z)


def soft_shadow_boundary(scene: Scene, image_grad: np.ndarray, names: Sequence[str], *, spp: int = 4,
                         seed: int = 0, max_depth: int | None = None, parameters: SceneParameters | None = None,
                         device: Device | str | None = None) -> dict[str, np.ndarray]:
    """Reverse mode: the boundary term of what the surfaces the camera sees receive, at their first bounce, for
    ``names`` (``SHAPE.vertex_positions`` and ``SHAPE.to_world``, ``SENSOR.to_world`` and ``SENSOR.x_fov``),
    given dLoss/dImage ``image_grad`` (H, W, 3): soft shadows of area lights and the environment, and every
    occluder's outline in the incident light (secondary visibility, Li et al. 2018), as occluders move and as
    the shading points move with the surface they lie on or with the camera (they slide along its rays).
    ``spp`` shading points per pixel and one later vertex of a camera path through each (:func:`sample_soft_edges`),
    each with one point on the edges that are silhouettes from it, chosen in proportion to the angle they subtend;
    the radiance either side of it from the ``vertex_radiance`` kernel; a mesh's outlines on itself included. Not
    included: outlines seen through delta (mirror, glass) bounces, delta lights (:func:`shadow_boundary`)."""
    g = np.asarray(image_grad, np.float64)
    if g.ndim != 3 or g.shape[2] != 3:
        raise ValueError(f"image_grad must be (H, W, 3), got {g.shape}")
    height, width = g.shape[:2]
    params = parameters if parameters is not None else traverse(scene)
    wanted = _meshes_of(scene, names)
    cameras = [n for n in names if n in sensor_names(scene)]
    out = {name: np.zeros_like(np.asarray(params[name], np.float32)) for ns in wanted.values() for name in ns}
    sums = {i: np.zeros((scene.meshes[i].positions.shape[0], 3)) for i in wanted}
    camera_sums = {name: np.zeros(np.shape(params[name])) for name in cameras}
    for ss in soft_sample_chunks(scene, sorted(wanted), width, height, spp=spp, seed=seed, max_depth=max_depth,
                                 device=device, receivers=sorted(wanted), camera=bool(cameras)):
        weight = sample_weights(ss.pixels, ss.weights, g, ss.jump)
        for i in wanted:
            sums[i] += _vertex_sums(scene, i, ss, weight)
        for name in cameras:
            camera_sums[name] += np.tensordot(weight, _shading_camera_velocity(scene, width, height, ss, name),
                                              axes=1).reshape(camera_sums[name].shape)
    for i, mesh_names in wanted.items():
        vertex_gradients(params, scene, i, mesh_names, sums[i], out)
    for name in cameras:
        out[name] = camera_sums[name].astype(np.float32)
    return out


def _vertex_sums(scene: Scene, i: int, ss: SoftSamples, weight: np.ndarray) -> np.ndarray:
    """(V, 3): sum over the samples of weight x d(outline's normal motion)/d(mesh i's vertex): as the occluder
    (its edge's two vertices) and as the receiver (the shading point's triangle's three, by its barycentrics)."""
    mesh = scene.meshes[i]
    gv = np.zeros((mesh.positions.shape[0], 3))
    m = ss.mesh == i
    add_on_edges(gv, ss.v0[m], ss.v1[m], ss.t[m], ss.velocity[m] * weight[m][:, None])
    for owner, tri, bary, velocity in ((ss.receiver, ss.tri, ss.bary, ss.receiver_velocity()),
                                       (ss.background, ss.back_tri, ss.back_bary, ss.background_velocity())):
        r = owner == i
        add_on_triangles(gv, mesh.indices, tri[r], bary[r], velocity[r] * weight[r][:, None])
    return gv


def _point_motion(scene: Scene, i: int, tri: np.ndarray, bary: np.ndarray, dp: np.ndarray) -> np.ndarray:
    """(N, 3): the motion of the points at barycentrics ``bary`` of mesh i's triangles ``tri``, for vertex
    velocities dp (V, 3)."""
    corners = scene.meshes[i].indices.astype(np.int64)[tri]
    return _at_bary(dp[corners], bary)


def _shading_camera_velocity(scene: Scene, width: int, height: int, ss: SoftSamples, name: str) -> np.ndarray:
    """(N, *value shape): n . d(direction of the edge point from the shading point)/d(sensor parameter ``name``):
    the shading point slides on its triangle's plane along its camera ray as the camera moves (central
    differences of that intersection in float64)."""
    cam = scene.camera
    if name.endswith(".to_world"):
        base, step = np.asarray(cam.to_world, np.float64).reshape(-1), CAMERA_STEP

        def moved(v: np.ndarray) -> Camera:
            return dataclasses.replace(cam, to_world=v.reshape(4, 4))
    else:
        _, _, right, _ = cam.basis(width, height)
        base, step = np.array([2 * np.degrees(np.arctan(np.linalg.norm(right)))]), FOV_STEP

        def moved(v: np.ndarray) -> Camera:
            return dataclasses.replace(cam, fov=float(v[0]), fov_axis="x")
    out = np.zeros((len(ss.point), base.size))
    for k in range(base.size):
        d = np.zeros(base.size)
        d[k] = step
        ends = []
        for v in (base + d, base - d):
            o, dirs = _camera_rays(scene, ss.film, width, height, moved(v))
            t = np.einsum("nc,nc->n", ss.receiver_normal, ss.point - o) / np.einsum("nc,nc->n", ss.receiver_normal,
                                                                                   dirs)
            ends.append(o + t[:, None] * dirs)
        out[:, k] = -np.einsum("nc,nc->n", ss.velocity, (ends[0] - ends[1]) / (2 * step)) * ss.relative
        out[ss.attached, k] = 0.0  # a later vertex stays on its surface when the camera moves
    return out.reshape(len(ss.point), *((4, 4) if name.endswith(".to_world") else (1,)))


def _forward_start(scene: Scene, tangent: np.ndarray, width: int | None, height: int | None,
                   parameters: SceneParameters | None) -> tuple[int, int, SceneParameters, np.ndarray, np.ndarray]:
    """A forward-mode term's size (the film's by default), parameters (a new traverse by default), tangent in
    float64 and a zero image (H, W, 3) to add its chunks into."""
    width, height = width or scene.film.width, height or scene.film.height
    params = parameters if parameters is not None else traverse(scene)
    return width, height, params, np.asarray(tangent, np.float64), np.zeros((height, width, 3))


def soft_shadow_boundary_forward(scene: Scene, name: str, tangent: np.ndarray, *, width: int | None = None,
                                 height: int | None = None, spp: int = 4, seed: int = 0,
                                 max_depth: int | None = None, parameters: SceneParameters | None = None,
                                 device: Device | str | None = None) -> np.ndarray:
    """Forward mode of :func:`soft_shadow_boundary`: d image (H, W, 3) along ``tangent`` (shaped as ``name``'s
    value), from the same samples for the same seed and size."""
    width, height, params, tan, image = _forward_start(scene, tangent, width, height, parameters)
    if name in sensor_names(scene):
        for ss in soft_sample_chunks(scene, [], width, height, spp=spp, seed=seed, max_depth=max_depth,
                                     device=device, camera=True):
            dx = along(_shading_camera_velocity(scene, width, height, ss, name), tan)
            image += splat_image(ss.pixels, ss.weights, ss.jump * dx[:, None], width, height)
        return image.astype(np.float32)
    i, dp = vertex_motion(params, scene, name, tan)
    for ss in soft_sample_chunks(scene, [i], width, height, spp=spp, seed=seed, max_depth=max_depth, device=device,
                                 receivers=[i]):
        dx = np.where(ss.mesh == i, edge_point_motion(ss.velocity, ss.v0, ss.v1, ss.t, dp), 0.0)
        for owner, tri, bary, velocity in ((ss.receiver, ss.tri, ss.bary, ss.receiver_velocity()),
                                           (ss.background, ss.back_tri, ss.back_bary, ss.background_velocity())):
            r = owner == i
            if np.any(r):
                dx[r] += np.einsum("nc,nc->n", velocity[r], _point_motion(scene, i, tri[r], bary[r], dp))
        image += splat_image(ss.pixels, ss.weights, ss.jump * dx[:, None], width, height)
    return image.astype(np.float32)


def shadow_boundary_forward(scene: Scene, name: str, tangent: np.ndarray, *, width: int | None = None,
                            height: int | None = None, samples: int = 65536, seed: int = 0,
                            max_depth: int | None = None, parameters: SceneParameters | None = None,
                            device: Device | str | None = None) -> np.ndarray:
    """Forward mode of :func:`shadow_boundary`: d image (H, W, 3) along ``tangent`` (shaped as ``name``'s value:
    (3 V,) or (4, 4) for a shape, (4, 4) for the sensor's to_world, (3,) for a point light's position), from the
    same edge points for the same seed and size."""
    width, height = width or scene.film.width, height or scene.film.height
    params = parameters if parameters is not None else traverse(scene)
    tan = np.asarray(tangent, np.float64)
    light_names = moving_light_names(scene)
    camera = name in sensor_names(scene)
    if camera or name in light_names:
        ss = sample_shadow_edges(scene, range(len(scene.meshes)), width, height, samples=samples, seed=seed,
                                 max_depth=max_depth, device=device)
        if camera:
            velocity = sensor_velocity(scene, width, height, ss.point, ss.normal, name)
            dx = along(velocity, tan)
        else:
            move = tan.reshape(4, 4)[:3, 3] if name.endswith(".to_world") else tan.reshape(3)
            dx = np.where(ss.light == light_names[name], ss.light_velocity @ move, 0.0)
    else:
        i, dp = vertex_motion(params, scene, name, tan)
        ss = sample_shadow_edges(scene, [i], width, height, samples=samples, seed=seed, max_depth=max_depth,
                                 device=device)
        dx = edge_point_motion(ss.velocity, ss.v0, ss.v1, ss.t, dp)
        rs = sample_shadow_edges(scene, range(len(scene.meshes)), width, height, samples=samples, seed=seed,
                                 max_depth=max_depth, device=device, receivers=[i])
        dr = np.einsum("nc,nc->n", rs.receiver_velocity, _point_motion(scene, i, rs.rtri, rs.rbary, dp))
        receiving = splat_image(rs.pixels, rs.weights, rs.jump * dr[:, None], width, height)
        return splat_image(ss.pixels, ss.weights, ss.jump * dx[:, None], width, height) + receiving
    return splat_image(ss.pixels, ss.weights, ss.jump * dx[:, None], width, height)


#: Floats a candidate edge of the later hard shadows (cl/gradients/delta_sides.h): its end points, the record
#: index of the light that sees it as a silhouette (int bits), and for a directional light how far behind the
#: edge point its ray may start (0: a point or spot light).
DELTA_EDGE_STRIDE = 8


@dataclass
class DeltaSamples:
    """Points of point, spot and directional lights' shadow outlines seen from the vertices of camera paths (after
    the first bounce), and what each contributes (:func:`delta_sample_chunks`)."""

    pixels: np.ndarray  # (N, 1) the pixel the vertex's camera path goes through
    weights: np.ndarray  # (N, 1) 1
    jump: np.ndarray  # (N, 3) f |cos| (L- - L+) x the curve's measure per sample x the path's throughput
    light: np.ndarray  # (N,) index in scene.lights
    mesh: np.ndarray  # (N,) index in scene.meshes of the occluder, its edge's vertices, the point's parameter
    v0: np.ndarray
    v1: np.ndarray
    t: np.ndarray
    sigma: np.ndarray  # (N,) |r - l| / |q - l|
    velocity: np.ndarray  # (N, 3) n^T P / |r - y|: the outline's normal motion per motion of its point r
    receiver: np.ndarray  # (N,) the receiver's mesh, its triangle (index in the mesh), barycentrics (N, 2)
    rtri: np.ndarray
    rbary: np.ndarray


def _delta_edge_table(scene: Scene, replay) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The candidate edges of the later hard shadows: every mesh's edges that a point, spot or directional light
    sees as silhouettes (:meth:`HardLight.silhouettes`), as (E, DELTA_EDGE_STRIDE) records, with their scene light
    (E,), mesh (E,) and vertex pairs (E, 2). A directional light's records hold how far behind an edge point its
    rays may start, outside the scene (its light has no position)."""
    packed = replay.scene.arrays.lights
    types = packed.lights[:, 7].astype(np.int64)  # LIGHT_TYPE
    prims = packed.lights[:, 0].view(np.int32)  # LIGHT_PRIM: the offset of its position (direction) in light_data
    c, radius = scene_sphere(scene)
    rows, lights, meshes, pairs = [], [], [], []
    for light in hard_lights(scene):
        kind = (4 if light.direction is not None else 5 if isinstance(scene.lights[light.index], SpotLight)
                else 1)  # LIGHT_DIRECTIONAL, LIGHT_SPOT, LIGHT_POINT
        where = light.position if light.direction is None else light.direction
        record = [r for r in np.flatnonzero(types == kind)
                  if np.allclose(packed.light_data[prims[r]:prims[r] + 3], where, rtol=1e-6, atol=1e-6)]
        if not record:  # no power: no record, no shadow
            continue
        for i, mesh in enumerate(scene.meshes):
            vp = light.silhouettes(mesh)
            if not len(vp):
                continue
            p = mesh.positions.astype(np.float64)
            rec = np.zeros((len(vp), DELTA_EDGE_STRIDE), np.float32)
            rec[:, 0:3], rec[:, 3:6] = p[vp[:, 0]], p[vp[:, 1]]
            rec[:, 6] = np.int32(record[0]).view(np.float32)
            if light.direction is not None:
                rec[:, 7] = 2.0 * (np.linalg.norm(np.maximum(np.abs(p[vp[:, 0]] - c), np.abs(p[vp[:, 1]] - c)),
                                                  axis=1) + radius) + 1.0
            rows.append(rec)
            lights.append(np.full(len(vp), light.index))
            meshes.append(np.full(len(vp), i))
            pairs.append(vp)
    if not rows:
        return (np.zeros((0, DELTA_EDGE_STRIDE), np.float32), np.zeros(0, np.int64), np.zeros(0, np.int64),
                np.zeros((0, 2), np.int64))
    return np.concatenate(rows), np.concatenate(lights), np.concatenate(meshes), np.concatenate(pairs)


def delta_sample_chunks(scene: Scene, width: int, height: int, *, spp: int, seed: int, max_depth: int | None = None,
                        device: Device | str | None = None) -> Iterator[DeltaSamples]:
    """Point, spot and directional lights' hard shadows seen after the first bounce: at ``spp`` shading points a
    pixel and one later vertex of a camera path through each (:func:`shading_points_started`, as the soft term's),
    one point on an edge that a delta light sees as a silhouette (every mesh's, chosen in proportion to its length), the
    outline it casts on the first surface behind it, and, where the vertex sees that point, the vertex's BSDF and cosine
    times the light's direct contribution either side of the outline (the delta_shadow_sides kernel,
    cl/gradients/delta_sides.h). The outline lies on the receiver's surface, at the next vertex of a path through
    the shading point, which the interior term holds attached to its surface (the material form): it moves
    relative to the receiver's material point r by P (sigma dq + (1 - sigma) dl - dr), P projecting along the
    light's ray onto the receiver's plane, and on the shading point's sphere of directions by that over |r - y|
    (the shading point's own motion moves both alike). In bands of pixels as :func:`soft_sample_chunks`."""
    Projection.of(scene, width, height, orthographic=True)  # pinhole and orthographic cameras (a thin lens: refused)
    rfilter = scene.film.rfilter
    replay = replay_for(scene, width=width, height=height, max_depth=max_depth, device=device)
    if not (replay.max_depth < 0 or replay.max_depth > 2):  # a light sample after a bounce
        return
    table_e, light_e, mesh_e, pairs_e = _delta_edge_table(scene, replay)
    lengths = np.linalg.norm(table_e[:, 3:6].astype(np.float64) - table_e[:, 0:3], axis=1)
    total = float(lengths.sum())
    if not total > 0:
        return
    cdf = np.cumsum(lengths) / total
    first, order = _triangle_tables(scene, replay)
    positions = np.concatenate([m.positions for m in scene.meshes]).astype(np.float64)
    by_index = {h.index: h for h in hard_lights(scene)}

    def band(p0: int, p1: int) -> Generator[None, None, DeltaSamples]:
        """The samples of pixels p0 .. p1 - 1 (:func:`_bands`: yields when a kernel is enqueued)."""
        rng = np.random.default_rng([seed, 0x64656C7461, p0])  # "delta"
        points = shading_points_started(replay, rfilter, width, p0, p1, spp, rng, True)
        yield
        film, pix, prim, depth, table, _ = points()
        sel = np.flatnonzero(prim >= 0)
        u = rng.random((len(sel), 2))
        e = np.minimum(np.searchsorted(cdf, u[:, 0], side="right"), len(cdf) - 1)
        samples = np.empty((len(sel), 6), np.float32)
        samples[:, :5], samples[:, 5] = table[sel, :5], u[:, 1]
        sides = replay.delta_shadow_sides_started(prim[sel], samples, depth[sel], e, table_e,
                                                  int(rng.integers(2**32)), SOFT_SIDE_EPS)
        yield
        out = sides()
        nz = np.flatnonzero(np.any(out.radiance[:, 0] != out.radiance[:, 1], axis=1) & (out.receiver_prim >= 0))
        sel, e, t = sel[nz], e[nz], u[nz, 1]
        # in float64: the shading point y, the edge point q, the light l, the receiver point r and its normal
        corners = positions[replay.scene.arrays.tri_vidx[prim[sel]]]
        bary = table[sel, :2].astype(np.float64)
        y = _at_bary(corners, bary)
        a, b = table_e[e, 0:3].astype(np.float64), table_e[e, 3:6].astype(np.float64)
        q = a + t[:, None] * (b - a)
        # where the light's rays start (a directional light's: behind q, table_e's distance), parallel or not
        lp = np.zeros_like(q)
        parallel = np.zeros(len(e), bool)
        for k, light in by_index.items():
            m = light_e[e] == k
            if light.position is not None:
                lp[m] = light.position
            else:
                lp[m] = q[m] - table_e[e[m], 7, None].astype(np.float64) * light.direction[None]
                parallel[m] = True
        _, qdist = _unit(q - lp)
        rprim = out.receiver_prim[nz]
        rc = positions[replay.scene.arrays.tri_vidx[rprim]]
        rb = out.receiver_hit[nz, 1:].astype(np.float64)
        r = _at_bary(rc, rb)
        n_r, _ = _unit(np.cross(rc[:, 1] - rc[:, 0], rc[:, 2] - rc[:, 0]))
        sigma, proj = receiver_motion(r, q, lp, n_r, parallel)
        w, dist = _unit(r - y)
        dr_dt = np.einsum("nij,nj->ni", proj, b - a) * sigma[:, None]
        dw_dt = (dr_dt - w * np.einsum("nc,nc->n", w, dr_dt)[:, None]) / dist[:, None]
        normal, speed = _unit(np.cross(w, dw_dt))
        # the kernel's sides are either side of its (float32) normal: the same one
        ok = (speed > 0) & (np.einsum("nc,nc->n", normal, out.outline[nz, 2:5]) > 0.5) & np.isfinite(qdist)
        k = np.flatnonzero(ok)
        measure = speed[k] * total / lengths[e[k]] / spp
        radiance = out.radiance[nz[k]].astype(np.float64)
        jump = (radiance[:, 0] - radiance[:, 1]) * (measure[:, None] * table[sel[k], 5:])
        rmesh = _mesh_of(first, order, rprim[k])
        return DeltaSamples(pix[sel[k]][:, None], np.ones((len(k), 1)), jump, light_e[e[k]], mesh_e[e[k]],
                            pairs_e[e[k], 0], pairs_e[e[k], 1], t[k], sigma[k],
                            np.einsum("nc,ncj->nj", normal[k], proj[k]) / dist[k, None], rmesh,
                            order[rprim[k]] - first[rmesh], rb[k])

    yield from _bands(width * height, spp, band)


def delta_shadow_boundary(scene: Scene, image_grad: np.ndarray, names: Sequence[str], *, spp: int = 4,
                          seed: int = 0, max_depth: int | None = None, parameters: SceneParameters | None = None,
                          device: Device | str | None = None) -> dict[str, np.ndarray]:
    """Reverse mode: the boundary term of point, spot and directional lights' hard shadows seen after the first
    bounce
    (:func:`delta_sample_chunks`) for ``names`` (meshes' ``vertex_positions`` and ``to_world``, as occluders and
    as receivers; point lights' ``position``, spot lights' ``to_world``), given dLoss/dImage ``image_grad``
    (H, W, 3). The sensor's parameters get none: a shading point's motion moves the outline and the receiver's
    point it covers alike. Add it to :func:`shadow_boundary`'s (the first bounce's)."""
    g = np.asarray(image_grad, np.float64)
    if g.ndim != 3 or g.shape[2] != 3:
        raise ValueError(f"image_grad must be (H, W, 3), got {g.shape}")
    height, width = g.shape[:2]
    params = parameters if parameters is not None else traverse(scene)
    light_names = {n: k for n, k in moving_light_names(scene).items() if n in names}
    wanted = _meshes_of(scene, [n for n in names if n not in moving_light_names(scene)
                                and n not in sensor_names(scene)])
    sums = {i: np.zeros((scene.meshes[i].positions.shape[0], 3)) for i in wanted}
    light_sums = {n: np.zeros(3) for n in light_names}
    for ds in delta_sample_chunks(scene, width, height, spp=spp, seed=seed, max_depth=max_depth, device=device):
        weight = sample_weights(ds.pixels, ds.weights, g, ds.jump)
        for i in wanted:
            m = ds.mesh == i
            add_on_edges(sums[i], ds.v0[m], ds.v1[m], ds.t[m], ds.velocity[m] * (ds.sigma[m] * weight[m])[:, None])
            r = ds.receiver == i
            add_on_triangles(sums[i], scene.meshes[i].indices, ds.rtri[r], ds.rbary[r],
                             -ds.velocity[r] * weight[r][:, None])
        for name, k in light_names.items():
            m = ds.light == k
            light_sums[name] += (ds.velocity[m] * ((1 - ds.sigma[m]) * weight[m])[:, None]).sum(0)
    out: dict[str, np.ndarray] = {}
    for i, mesh_names in wanted.items():
        vertex_gradients(params, scene, i, mesh_names, sums[i], out)
    for name, gl in light_sums.items():
        if name.endswith(".to_world"):  # a spot light's pose: its translation moves the outlines
            pose = np.zeros((4, 4))
            pose[:3, 3] = gl
            gl = pose
        out[name] = gl.astype(np.float32)
    for name in names:
        if name in sensor_names(scene):
            out[name] = np.zeros(np.shape(params[name]), np.float32)
    return out


def delta_shadow_boundary_forward(scene: Scene, name: str, tangent: np.ndarray, *, width: int | None = None,
                                  height: int | None = None, spp: int = 4, seed: int = 0,
                                  max_depth: int | None = None, parameters: SceneParameters | None = None,
                                  device: Device | str | None = None) -> np.ndarray:
    """Forward mode of :func:`delta_shadow_boundary`: d image (H, W, 3) along ``tangent`` (shaped as ``name``'s
    value), from the same samples for the same seed and size."""
    width, height, params, tan, image = _forward_start(scene, tangent, width, height, parameters)
    lights = moving_light_names(scene)
    if name in sensor_names(scene):
        return image.astype(np.float32)
    if name in lights:
        move = tan.reshape(4, 4)[:3, 3] if name.endswith(".to_world") else tan.reshape(3)
        for ds in delta_sample_chunks(scene, width, height, spp=spp, seed=seed, max_depth=max_depth, device=device):
            dx = np.where(ds.light == lights[name], (1 - ds.sigma) * (ds.velocity @ move), 0.0)
            image += splat_image(ds.pixels, ds.weights, ds.jump * dx[:, None], width, height)
        return image.astype(np.float32)
    i, dp = vertex_motion(params, scene, name, tan)
    for ds in delta_sample_chunks(scene, width, height, spp=spp, seed=seed, max_depth=max_depth, device=device):
        dx = np.where(ds.mesh == i, ds.sigma * edge_point_motion(ds.velocity, ds.v0, ds.v1, ds.t, dp), 0.0)
        r = ds.receiver == i
        if np.any(r):
            dx[r] -= np.einsum("nc,nc->n", ds.velocity[r], _point_motion(scene, i, ds.rtri[r], ds.rbary[r], dp))
        image += splat_image(ds.pixels, ds.weights, ds.jump * dx[:, None], width, height)
    return image.astype(np.float32)
