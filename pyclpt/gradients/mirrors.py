"""The scene's mirrors as the boundary terms see them: which materials have a delta lobe (reflect or refract like
a mirror or smooth glass), and the planes of the meshes that reflect like a planar mirror.

A camera sees a planar mirror's reflection as a second camera would, its origin reflected across the plane: the
outlines it shows are the reflected scene's (:func:`pyclpt.gradients.edges.silhouette_edges`). A mesh made of a few
planes (a flat rectangle: one; a mirrored box: six) is a planar mirror on each; a curved one (a sphere, or more
than :data:`MAX_PLANES` planes), one whose shading normals are not its faces' (vertex normals that differ, a bump
map) is not.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pyclpt.scene.model import BumpMap, Conductor, Dielectric, Mesh, Scene, ThinDielectric

#: A mesh of more planes than this is treated as curved (a tessellated sphere), not as many small mirrors.
MAX_PLANES = 16

#: Two triangles lie in one plane when their unit normals differ by less than this and their planes' offsets by
#: less than this times the mesh's scale (its largest coordinate plus its extent: float32 positions round there).
PLANE_TOLERANCE = 1e-5


def delta_lobes(material: object) -> frozenset[str]:
    """The delta lobes of a material: ``reflect`` (a smooth conductor, a smooth dielectric's or a thin
    dielectric's reflection) and ``refract`` (a smooth dielectric's transmission, which bends rays; a thin
    dielectric's does not), through masks, bump maps and two-sided pairs."""
    if isinstance(material, ThinDielectric):
        return frozenset({"reflect"})
    if isinstance(material, Conductor):
        return frozenset({"reflect"}) if material.alpha == 0 else frozenset()
    if isinstance(material, Dielectric):
        return frozenset({"reflect", "refract"}) if material.alpha == 0 else frozenset()
    lobes: frozenset[str] = frozenset()
    for part in ("material", "front", "back"):
        if getattr(material, part, None) is not None:
            lobes |= delta_lobes(getattr(material, part))
    return lobes


def _bumped(material: object) -> bool:
    """Whether a bump map perturbs the material's shading normal (its mirror is then not a plane's)."""
    return isinstance(material, BumpMap) or any(
        _bumped(getattr(material, part)) for part in ("material", "front", "back")
        if getattr(material, part, None) is not None)


@dataclass(frozen=True)
class MirrorPlane:
    """A plane of a mesh that reflects like a planar mirror: ``mesh`` its index in ``scene.meshes``, ``point`` a
    point of the plane (3,), ``normal`` its unit normal (3,) (either side), ``faces`` the mesh's triangles in it."""

    mesh: int
    point: np.ndarray
    normal: np.ndarray
    faces: np.ndarray

    @property
    def matrix(self) -> np.ndarray:
        """R = I - 2 m m^T (3, 3): the reflection's linear part (symmetric, its own inverse)."""
        return np.eye(3) - 2.0 * np.outer(self.normal, self.normal)

    def reflect(self, p: np.ndarray) -> np.ndarray:
        """Points p (N, 3) or (3,) reflected across the plane: R (p - c) + c."""
        return p - 2.0 * ((p - self.point) @ self.normal)[..., None] * self.normal

    def side(self, p: np.ndarray) -> np.ndarray:
        """Signed distances of points p (N, 3) to the plane, positive on its normal's side."""
        return (p - self.point) @ self.normal


def planes_of(mesh: Mesh) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]] | None:
    """``mesh``'s triangles grouped by plane, (point, unit normal, triangles) each; None when it is curved: more
    than :data:`MAX_PLANES` planes, or vertex normals that are not their plane's. Degenerate triangles (no
    area) are in none."""
    p = mesh.positions.astype(np.float64)
    f = mesh.indices.astype(np.int64)
    scale = float(np.abs(p).max(initial=0.0) + np.ptp(p, axis=0).max(initial=0.0)) if len(p) else 0.0
    n = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    area = np.linalg.norm(n, axis=1)
    left = np.flatnonzero(area > 1e-12 * max(scale, 1e-30) ** 2)
    unit = n / np.maximum(area, 1e-300)[:, None]
    offset = np.einsum("ij,ij->i", unit, p[f[:, 0]])
    planes = []
    while left.size:
        if len(planes) == MAX_PLANES:
            return None
        r = left[0]
        s = np.where(unit[left] @ unit[r] < 0, -1.0, 1.0)
        same = ((np.linalg.norm(s[:, None] * unit[left] - unit[r], axis=1) < PLANE_TOLERANCE)
                & (np.abs(s * offset[left] - offset[r]) < PLANE_TOLERANCE * scale))
        faces = left[same]
        normal = (s[same, None] * n[faces]).sum(0)
        normal /= np.linalg.norm(normal)
        corners = np.unique(f[faces])
        if mesh.normals is not None:
            shading = np.asarray(mesh.normals, np.float64)[corners]
            lengths = np.linalg.norm(shading, axis=1)
            if np.any(np.abs(shading @ normal) < (1.0 - PLANE_TOLERANCE) * lengths):
                return None
        planes.append((p[corners].mean(0), normal, faces))
        left = left[~same]
    return planes


def mirror_planes(scene: Scene) -> list[MirrorPlane]:
    """The planes of the meshes whose material reflects like a smooth mirror (:func:`delta_lobes`: ``reflect``) and
    that are flat in pieces (:func:`planes_of`), without bump maps; in mesh order."""
    out = []
    for i, mesh in enumerate(scene.meshes):
        material = scene.materials[mesh.material]
        if "reflect" not in delta_lobes(material) or _bumped(material):
            continue
        for point, normal, faces in planes_of(mesh) or []:
            out.append(MirrorPlane(i, point, normal, faces))
    return out
