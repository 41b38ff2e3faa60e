"""The scene model: plain dataclasses that every loader produces and every
integrator consumes (through :mod:`pyclpt.scene_buffers`).

Conventions follow Mitsuba 3 so that a scene means the same in both: BSDFs are
one-sided unless ``twosided``; area emitters emit on the front side of their
triangles (counter-clockwise winding); the camera looks along +z of its
``to_world`` frame with +x pointing left on the image.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Union

import numpy as np

RGB = tuple[float, float, float]


def rgb(value: object, what: str = "color") -> RGB:
    """A float or 3 floats as an RGB triple; raises ValueError naming ``what``."""
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.size == 1:
        arr = np.repeat(arr, 3)
    if arr.size != 3 or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: expected a number or 3 finite numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


@dataclass
class Diffuse:
    """Lambertian reflection (Mitsuba ``diffuse``)."""

    reflectance: RGB = (0.5, 0.5, 0.5)
    twosided: bool = False


@dataclass
class Conductor:
    """Metal with complex IOR ``eta + i k``; smooth when ``alpha == 0``, else GGX rough."""

    eta: RGB = (0.0, 0.0, 0.0)
    k: RGB = (1.0, 1.0, 1.0)
    alpha: float = 0.0
    specular_reflectance: RGB = (1.0, 1.0, 1.0)
    twosided: bool = False


@dataclass
class Dielectric:
    """Smooth glass-like interface between ``int_ior`` (inside) and ``ext_ior``."""

    int_ior: float = 1.5046
    ext_ior: float = 1.000277
    specular_reflectance: RGB = (1.0, 1.0, 1.0)
    specular_transmittance: RGB = (1.0, 1.0, 1.0)


Material = Union[Diffuse, Conductor, Dielectric]


@dataclass(eq=False)
class Mesh:
    """A triangle mesh in world space with one material and an optional area emitter."""

    name: str
    positions: np.ndarray  # (V, 3) float32
    indices: np.ndarray  # (T, 3) int32
    material: int  # index into Scene.materials
    normals: np.ndarray | None = None  # (V, 3) float32 shading normals
    uvs: np.ndarray | None = None  # (V, 2) float32
    emission: RGB | None = None  # radiance of an area emitter on the front side

    def __post_init__(self) -> None:
        self.positions = np.ascontiguousarray(self.positions, dtype=np.float32).reshape(-1, 3)
        self.indices = np.ascontiguousarray(self.indices, dtype=np.int32).reshape(-1, 3)
        if self.normals is not None:
            self.normals = np.ascontiguousarray(self.normals, dtype=np.float32).reshape(-1, 3)
        if self.uvs is not None:
            self.uvs = np.ascontiguousarray(self.uvs, dtype=np.float32).reshape(-1, 2)
        self.validate()

    @property
    def triangle_count(self) -> int:
        return int(self.indices.shape[0])

    def validate(self) -> None:
        nv = self.positions.shape[0]
        where = f"mesh {self.name!r}"
        if self.indices.size == 0:
            raise ValueError(f"{where} has no triangles")
        if not np.all(np.isfinite(self.positions)):
            bad = int(np.argwhere(~np.isfinite(self.positions))[0, 0])
            raise ValueError(f"{where}: vertex {bad} has a NaN or infinite coordinate")
        lo, hi = int(self.indices.min()), int(self.indices.max())
        if lo < 0 or hi >= nv:
            tri = int(np.argwhere((self.indices < 0) | (self.indices >= nv))[0, 0])
            raise ValueError(
                f"{where}: triangle {tri} references vertex {self.indices[tri].tolist()} "
                f"but the mesh has {nv} vertices"
            )
        for attr, width in (("normals", 3), ("uvs", 2)):
            arr = getattr(self, attr)
            if arr is not None and arr.shape != (nv, width):
                raise ValueError(f"{where}: {attr} has shape {arr.shape}, expected ({nv}, {width})")
        if self.emission is not None:
            self.emission = rgb(self.emission, f"{where} emission")
            if min(self.emission) < 0:
                raise ValueError(f"{where}: negative emitted radiance {self.emission}")


@dataclass
class Camera:
    """Perspective pinhole camera; ``to_world`` maps camera space (looking along +z) to world."""

    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    fov: float = 45.0  # degrees, along fov_axis
    fov_axis: str = "x"  # x | y | diagonal | smaller | larger

    def __post_init__(self) -> None:
        self.to_world = np.asarray(self.to_world, dtype=np.float64).reshape(4, 4)
        if not 0.0 < self.fov < 180.0:
            raise ValueError(f"camera fov must be in (0, 180) degrees, got {self.fov}")
        if self.fov_axis not in ("x", "y", "diagonal", "smaller", "larger"):
            raise ValueError(f"camera fov_axis must be x, y, diagonal, smaller or larger, got {self.fov_axis!r}")

    @staticmethod
    def look_at(origin, target, up=(0.0, 1.0, 0.0), fov: float = 45.0, fov_axis: str = "x") -> "Camera":
        from .transform import look_at

        return Camera(look_at(origin, target, up), fov, fov_axis)

    def basis(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(origin, forward, right, up) with right/up scaled by the half-extent of the image plane at z=1."""
        m = self.to_world
        origin = m[:3, 3]
        cols = [m[:3, i] / max(np.linalg.norm(m[:3, i]), 1e-30) for i in range(3)]
        aspect = width / height
        axis = self.fov_axis
        if axis == "smaller":
            axis = "y" if aspect > 1 else "x"
        elif axis == "larger":
            axis = "x" if aspect > 1 else "y"
        t = np.tan(np.radians(self.fov) / 2)
        if axis == "x":
            tx, ty = t, t / aspect
        elif axis == "y":
            tx, ty = t * aspect, t
        else:
            diag = np.hypot(width, height)
            tx, ty = t * width / diag, t * height / diag
        # Mitsuba's camera space has +x to the left of the image.
        return origin, cols[2], -cols[0] * tx, cols[1] * ty


@dataclass
class Film:
    width: int = 256
    height: int = 256

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or not 0 < int(v) <= 65536:
                raise ValueError(f"film {name} must be an integer in 1..65536, got {v!r}")


@dataclass(eq=False)
class Scene:
    """Everything a render needs. ``spp`` and ``max_depth`` are the scene's defaults."""

    meshes: list[Mesh]
    materials: list[Material]
    camera: Camera = field(default_factory=Camera)
    film: Film = field(default_factory=Film)
    environment: RGB | None = None  # constant environment radiance
    spp: int = 64
    max_depth: int = -1
    name: str = "scene"
    source: Path | None = None

    def __post_init__(self) -> None:
        if not self.meshes:
            raise ValueError(f"scene {self.name!r} has no shapes")
        for mesh in self.meshes:
            if not 0 <= mesh.material < len(self.materials):
                raise ValueError(f"mesh {mesh.name!r} has material {mesh.material}, "
                                 f"but the scene has {len(self.materials)} materials")
        if self.environment is not None:
            self.environment = rgb(self.environment, "environment radiance")

    @property
    def triangle_count(self) -> int:
        return sum(m.triangle_count for m in self.meshes)

    @property
    def emitter_count(self) -> int:
        return sum(m.triangle_count for m in self.meshes if m.emission is not None) + (
            1 if self.environment is not None else 0)
