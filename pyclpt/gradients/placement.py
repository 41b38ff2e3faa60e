"""Parameters that move things (:func:`pyclpt.traverse`): where surfaces, instances, the sensor and point
and spot lights are, by Mitsuba 3's names.

- ``<mesh>.vertex_positions``: a mesh's vertices in world space, flat (3 V,) as Mitsuba's. A mesh with
  vertex normals gets them recomputed from the new positions (angle-weighted, as Mitsuba's
  ``recompute_vertex_normals`` does when positions change); one without keeps flat shading.
- ``<mesh>.to_world``: a pose (4x4) of the mesh relative to where it was when the scene was traversed
  (identity then): the positions at that moment are its object space, so setting a pose moves the whole
  shape, normals transformed by the inverse transpose. :func:`pyclpt.pose` makes one from a translation,
  a rotation and a scale. Setting ``vertex_positions`` keeps the pose (the new positions are
  world-space ones).
- ``<instance>.to_world``: an instance's transform (Mitsuba's name).
- ``<sensor>.to_world`` and ``<sensor>.x_fov`` (the horizontal field of view in degrees; setting it
  makes ``x`` the camera's fov axis, as Mitsuba stores it).
- ``<light>.position`` (a point light) and ``<light>.to_world`` (a spot light: 4x4, +z its axis).

Changing them goes through :meth:`SceneParameters.update`, which rebuilds the BVH of a changed geometry
on the devices that hold the scene (the kernels are not compiled again: the scene's specialisation does
not depend on where things are). Their gradients are not computed yet: the derivative of an image with
respect to a moving surface has a boundary term (silhouettes, shadow edges) that path replay does not
sample (docs/differentiable.md); they are listed by :meth:`SceneParameters.unsupported` with that reason.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
import trimesh

from pyclpt.buffers.lights import spot_frame
from pyclpt.scene.model import Camera, Instance, Mesh, PointLight, Scene, SpotLight, check_instance_transform
from pyclpt.scene.transform import apply_normals, apply_points

Accessors = tuple[Callable[[], np.ndarray], Callable[[np.ndarray], None]]


def vertex_normals(positions: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Angle-weighted vertex normals (Thürmer and Wüthrich, as Mitsuba's ``recompute_vertex_normals``),
    (V, 3) float32; a vertex of degenerate triangles only gets +z."""
    p = np.asarray(positions, np.float64)
    tris = p[indices]
    face_normals, valid = trimesh.triangles.normals(tris)
    fn = np.zeros((len(indices), 3))
    fn[valid] = face_normals
    angles = np.nan_to_num(trimesh.triangles.angles(tris))
    n = trimesh.geometry.weighted_vertex_normals(len(p), indices, fn, angles)
    n = np.asarray(n, np.float64)
    bad = ~np.isfinite(n).all(1) | (np.linalg.norm(n, axis=1) == 0)
    n[bad] = (0.0, 0.0, 1.0)
    return np.ascontiguousarray(n, np.float32)


def _matrix(v: np.ndarray, name: str) -> np.ndarray:
    return check_instance_transform(np.asarray(v, np.float64).reshape(4, 4), name)


def mesh_accessors(mesh: Mesh) -> tuple[Accessors, Accessors]:
    """(vertex_positions, to_world) of ``mesh``: see the module."""
    state = {"rest": mesh.positions.astype(np.float64), "rest_n": None if mesh.normals is None
             else mesh.normals.astype(np.float64), "pose": np.eye(4)}

    def get_positions() -> np.ndarray:
        return mesh.positions.reshape(-1).copy()

    def put_positions(v: np.ndarray) -> None:
        p = np.ascontiguousarray(np.asarray(v, np.float32).reshape(-1, 3))
        inv = np.linalg.inv(state["pose"])
        mesh.positions = p
        state["rest"] = apply_points(inv, p.astype(np.float64))
        if mesh.normals is not None:
            mesh.normals = vertex_normals(p, mesh.indices)
            state["rest_n"] = apply_normals(inv, mesh.normals).astype(np.float64)

    def get_pose() -> np.ndarray:
        return state["pose"].astype(np.float32)

    def put_pose(v: np.ndarray) -> None:
        m = _matrix(v, f"{mesh.name}.to_world")
        mesh.positions = np.ascontiguousarray(apply_points(m, state["rest"]), np.float32)
        if state["rest_n"] is not None:
            mesh.normals = apply_normals(m, state["rest_n"])
        state["pose"] = m

    return (get_positions, put_positions), (get_pose, put_pose)


def instance_accessors(inst: Instance) -> Accessors:
    def get() -> np.ndarray:
        return np.asarray(inst.to_world, np.float32).copy()

    def put(v: np.ndarray) -> None:
        inst.to_world = _matrix(v, f"instance {inst.name!r} to_world")

    return get, put


def camera_accessors(scene: Scene) -> tuple[Accessors, Accessors | None]:
    """(to_world, x_fov) of the scene's sensor; x_fov None for an orthographic camera (it has no fov)."""
    def cam() -> Camera:
        return scene.camera

    def get_m() -> np.ndarray:
        return np.asarray(cam().to_world, np.float32).copy()

    def put_m(v: np.ndarray) -> None:
        m = np.asarray(v, np.float64).reshape(4, 4)
        if abs(np.linalg.det(m[:3, :3])) < 1e-12:
            raise ValueError(f"the sensor's to_world must be invertible, got {m.tolist()}")
        cam().to_world = m

    if cam().kind == "orthographic":
        return (get_m, put_m), None

    def get_fov() -> np.ndarray:
        _, _, right, _ = cam().basis(scene.film.width, scene.film.height)
        return np.asarray([2 * np.degrees(np.arctan(np.linalg.norm(right)))], np.float32)

    def put_fov(v: np.ndarray) -> None:
        x = float(np.asarray(v, np.float64).reshape(-1)[0])
        if not 0.0 < x < 180.0:
            raise ValueError(f"x_fov must be in (0, 180) degrees, got {x}")
        cam().fov, cam().fov_axis = x, "x"

    return (get_m, put_m), (get_fov, put_fov)


def point_accessors(light: PointLight) -> Accessors:
    def get() -> np.ndarray:
        return np.asarray(light.position, np.float32).copy()

    def put(v: np.ndarray) -> None:
        light.position = tuple(float(x) for x in np.asarray(v, np.float64).reshape(3))

    return get, put


def spot_pose(light: SpotLight) -> np.ndarray:
    """A spot light's 4x4 to_world: its frame (+z the axis; the one the kernels use) and its position."""
    m = np.eye(4)
    m[:3, :3] = light.to_world if light.to_world is not None else spot_frame(light.direction)
    m[:3, 3] = light.position
    return m


def spot_accessors(light: SpotLight) -> Accessors:
    def get() -> np.ndarray:
        return spot_pose(light).astype(np.float32)

    def put(v: np.ndarray) -> None:
        m = np.asarray(v, np.float64).reshape(4, 4)
        frame = m[:3, :3]
        if not np.all(np.isfinite(m)) or abs(np.linalg.det(frame)) < 1e-12:
            raise ValueError(f"a spot light's to_world must be finite and invertible, got {m.tolist()}")
        z = frame[:, 2] / np.linalg.norm(frame[:, 2])
        light.position = tuple(float(x) for x in m[:3, 3])
        light.direction = tuple(float(x) for x in z)
        light.to_world = frame if light.to_world is not None or light.texture is not None else None

    return get, put
