"""The scene model: plain dataclasses that every loader produces and every
integrator consumes (through :mod:`pyclpt.buffers.scene`).

Conventions follow Mitsuba 3 so that a scene means the same in both: BSDFs are
one-sided unless ``twosided``; area emitters emit on the front side of their
triangles (counter-clockwise winding); the camera looks along +z of its
``to_world`` frame with +x pointing left on the image.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

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


WRAP_MODES = ("repeat", "mirror", "clamp", "black")
FILTERS = ("nearest", "bilinear")
DISTRIBUTIONS = ("ggx", "beckmann")


def _uv(value: object, what: str) -> tuple[float, float]:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.size == 1:
        arr = np.repeat(arr, 2)
    if arr.size != 2 or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: expected a number or 2 finite numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]))


@dataclass(eq=False)
class Bitmap:
    """An image texture (Mitsuba ``bitmap``), looked up at the surface's uv.

    ``pixels`` (H, W, C) float32 holds the decoded values: linear radiance-like
    values for ``raw`` or HDR files, sRGB-encoded values in [0, 1] otherwise
    (decoded to linear on the device, before filtering). ``scale`` multiplies
    the value (Mitsuba's ``scale`` texture). Row 0 of ``pixels`` is the top of
    the image, which is v = 1 as in Mitsuba.
    """

    pixels: np.ndarray
    name: str = "bitmap"
    srgb: bool = True  # pixels are sRGB-encoded (LDR files unless raw)
    filter: str = "bilinear"
    wrap_mode: str = "repeat"
    uv_scale: tuple[float, float] = (1.0, 1.0)
    uv_offset: tuple[float, float] = (0.0, 0.0)
    scale: RGB = (1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        px = np.asarray(self.pixels, dtype=np.float32)
        if px.ndim == 2:
            px = px[:, :, None]
        if px.ndim != 3 or px.shape[2] not in (1, 2, 3, 4) or px.shape[0] < 1 or px.shape[1] < 1:
            raise ValueError(f"texture {self.name!r}: expected an (H, W, C) image, got shape {px.shape}")
        if not np.all(np.isfinite(px)):
            raise ValueError(f"texture {self.name!r}: the image holds NaN or infinite values")
        self.pixels = np.ascontiguousarray(px)
        if self.filter not in FILTERS:
            raise ValueError(f"texture {self.name!r}: filter must be one of {FILTERS}, got {self.filter!r}")
        if self.wrap_mode not in WRAP_MODES:
            raise ValueError(f"texture {self.name!r}: wrap_mode must be one of {WRAP_MODES}, "
                             f"got {self.wrap_mode!r}")
        self.uv_scale = _uv(self.uv_scale, f"texture {self.name!r} uv_scale")
        self.uv_offset = _uv(self.uv_offset, f"texture {self.name!r} uv_offset")
        self.scale = rgb(self.scale, f"texture {self.name!r} scale")

    @property
    def width(self) -> int:
        return int(self.pixels.shape[1])

    @property
    def height(self) -> int:
        return int(self.pixels.shape[0])

    def rgba(self) -> np.ndarray:
        """The pixels as (H, W, 4): gray replicated, alpha 1 where absent."""
        px = self.pixels
        c = px.shape[2]
        out = np.ones(px.shape[:2] + (4,), np.float32)
        if c in (1, 2):
            out[..., :3] = px[..., :1]
            if c == 2:
                out[..., 3] = px[..., 1]
        else:
            out[..., :c] = px
        return out


@dataclass(eq=False)
class Checkerboard:
    """Mitsuba's ``checkerboard``: ``color0`` where the fractional parts of u and v are both below
    or both above one half, ``color1`` elsewhere (after the uv transform); ``scale`` multiplies both."""

    color0: RGB = (0.4, 0.4, 0.4)
    color1: RGB = (0.2, 0.2, 0.2)
    uv_scale: tuple[float, float] = (1.0, 1.0)
    uv_offset: tuple[float, float] = (0.0, 0.0)
    scale: RGB = (1.0, 1.0, 1.0)
    name: str = "checkerboard"

    def __post_init__(self) -> None:
        self.color0 = rgb(self.color0, f"texture {self.name!r} color0")
        self.color1 = rgb(self.color1, f"texture {self.name!r} color1")
        self.uv_scale = _uv(self.uv_scale, f"texture {self.name!r} uv_scale")
        self.uv_offset = _uv(self.uv_offset, f"texture {self.name!r} uv_offset")
        self.scale = rgb(self.scale, f"texture {self.name!r} scale")


Texture = Bitmap | Checkerboard
# A material parameter: a constant RGB or a texture.
Color = RGB | Bitmap | Checkerboard


def color(value: object, what: str) -> Color:
    """A texture as is, or an RGB triple (see :func:`rgb`)."""
    if isinstance(value, (Bitmap, Checkerboard)):
        return value
    return rgb(value, what)


def _alpha(value: float, what: str) -> float:
    v = float(value)
    if not 0.0 <= v <= 4.0 or not np.isfinite(v):
        raise ValueError(f"{what}: roughness alpha must be in [0, 4], got {value!r}")
    return v


def _distribution(value: str, what: str) -> str:
    if value not in DISTRIBUTIONS:
        raise ValueError(f"{what}: microfacet distribution must be one of {DISTRIBUTIONS}, got {value!r}")
    return value


def _ior(value: float, what: str) -> float:
    v = float(value)
    if not (v > 0.0 and np.isfinite(v)):
        raise ValueError(f"{what}: an index of refraction must be positive and finite, got {value!r}")
    return v


@dataclass
class Diffuse:
    """Lambertian reflection (Mitsuba ``diffuse``)."""

    reflectance: Color = (0.5, 0.5, 0.5)
    twosided: bool = False

    def __post_init__(self) -> None:
        self.reflectance = color(self.reflectance, "diffuse reflectance")


@dataclass
class Conductor:
    """Metal with complex IOR ``eta + i k``; smooth when ``alpha == 0``, else rough
    (``distribution`` GGX or Beckmann; Mitsuba ``conductor`` / ``roughconductor``)."""

    eta: RGB = (0.0, 0.0, 0.0)
    k: RGB = (1.0, 1.0, 1.0)
    alpha: float = 0.0
    specular_reflectance: Color = (1.0, 1.0, 1.0)
    twosided: bool = False
    distribution: str = "ggx"

    def __post_init__(self) -> None:
        self.eta = rgb(self.eta, "conductor eta")
        self.k = rgb(self.k, "conductor k")
        self.alpha = _alpha(self.alpha, "conductor")
        self.specular_reflectance = color(self.specular_reflectance, "conductor specular_reflectance")
        self.distribution = _distribution(self.distribution, "conductor")


@dataclass
class Dielectric:
    """Glass-like interface between ``int_ior`` (inside) and ``ext_ior``; smooth when
    ``alpha == 0``, else rough (Mitsuba ``dielectric`` / ``roughdielectric``)."""

    int_ior: float = 1.5046
    ext_ior: float = 1.000277
    specular_reflectance: Color = (1.0, 1.0, 1.0)
    specular_transmittance: Color = (1.0, 1.0, 1.0)
    alpha: float = 0.0
    distribution: str = "ggx"

    def __post_init__(self) -> None:
        self.int_ior = _ior(self.int_ior, "dielectric int_ior")
        self.ext_ior = _ior(self.ext_ior, "dielectric ext_ior")
        self.specular_reflectance = color(self.specular_reflectance, "dielectric specular_reflectance")
        self.specular_transmittance = color(self.specular_transmittance, "dielectric specular_transmittance")
        self.alpha = _alpha(self.alpha, "dielectric")
        self.distribution = _distribution(self.distribution, "dielectric")


@dataclass
class ThinDielectric:
    """A thin sheet of glass (Mitsuba ``thindielectric``): reflection with the
    summed internal reflections, transmission without refraction."""

    int_ior: float = 1.5046
    ext_ior: float = 1.000277
    specular_reflectance: Color = (1.0, 1.0, 1.0)
    specular_transmittance: Color = (1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        self.int_ior = _ior(self.int_ior, "thindielectric int_ior")
        self.ext_ior = _ior(self.ext_ior, "thindielectric ext_ior")
        self.specular_reflectance = color(self.specular_reflectance, "thindielectric specular_reflectance")
        self.specular_transmittance = color(self.specular_transmittance,
                                            "thindielectric specular_transmittance")


@dataclass
class Plastic:
    """A diffuse base under a dielectric coating (Mitsuba ``plastic`` / ``roughplastic``);
    smooth coating when ``alpha == 0``."""

    diffuse_reflectance: Color = (0.5, 0.5, 0.5)
    specular_reflectance: Color = (1.0, 1.0, 1.0)
    int_ior: float = 1.49
    ext_ior: float = 1.000277
    alpha: float = 0.0
    distribution: str = "ggx"
    nonlinear: bool = False
    twosided: bool = False

    def __post_init__(self) -> None:
        self.diffuse_reflectance = color(self.diffuse_reflectance, "plastic diffuse_reflectance")
        self.specular_reflectance = color(self.specular_reflectance, "plastic specular_reflectance")
        self.int_ior = _ior(self.int_ior, "plastic int_ior")
        self.ext_ior = _ior(self.ext_ior, "plastic ext_ior")
        self.alpha = _alpha(self.alpha, "plastic")
        self.distribution = _distribution(self.distribution, "plastic")


BaseMaterial = Diffuse | Conductor | Dielectric | ThinDielectric | Plastic


@dataclass
class Mask:
    """Mitsuba ``mask``: the nested material with probability ``opacity``, else the
    ray passes through (honoured by closest-hit and shadow queries alike)."""

    opacity: Color
    material: Material

    def __post_init__(self) -> None:
        self.opacity = color(self.opacity, "mask opacity")


@dataclass
class BumpMap:
    """Mitsuba ``bumpmap``: the shading normal perturbed by the gradient of a height texture."""

    height: Texture
    material: Material
    scale: float = 1.0


Material = Diffuse | Conductor | Dielectric | ThinDielectric | Plastic | Mask | BumpMap


@dataclass
class PointLight:
    """An isotropic point emitter of ``intensity`` (W/sr, rgb) at ``position``."""

    position: tuple[float, float, float]
    intensity: RGB = (1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        p = np.asarray(self.position, np.float64).reshape(-1)
        if p.size != 3 or not np.all(np.isfinite(p)):
            raise ValueError(f"point light position: expected 3 finite numbers, got {self.position!r}")
        self.position = (float(p[0]), float(p[1]), float(p[2]))
        self.intensity = rgb(self.intensity, "point light intensity")
        if min(self.intensity) < 0:
            raise ValueError(f"point light: negative intensity {self.intensity}")


@dataclass(eq=False)
class Envmap:
    """A lat-long environment map (Mitsuba ``envmap``): ``pixels`` (H, W, 3) linear radiance,
    row 0 at the top (+y in the map's frame), ``to_world`` rotating the map into the scene.
    ``sunsky`` emitters are baked into one of these (pyclpt.scene.sunsky)."""

    pixels: np.ndarray
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    scale: float = 1.0
    name: str = "envmap"

    def __post_init__(self) -> None:
        px = np.asarray(self.pixels, np.float32)
        if px.ndim == 2:
            px = np.repeat(px[:, :, None], 3, axis=2)
        if px.ndim != 3 or px.shape[2] < 3 or px.shape[0] < 2 or px.shape[1] < 2:
            raise ValueError(f"environment map {self.name!r}: expected an (H, W, 3) image, got {px.shape}")
        px = px[:, :, :3]
        if not np.all(np.isfinite(px)) or px.min() < 0:
            raise ValueError(f"environment map {self.name!r}: values must be finite and >= 0")
        self.pixels = np.ascontiguousarray(px)
        self.to_world = np.asarray(self.to_world, np.float64).reshape(4, 4)
        if not (np.isfinite(self.scale) and self.scale >= 0):
            raise ValueError(f"environment map {self.name!r}: scale must be >= 0, got {self.scale}")


def base_material(mat: Material) -> BaseMaterial:
    """The BSDF under any mask / bump-map wrappers."""
    while isinstance(mat, (Mask, BumpMap)):
        mat = mat.material
    return mat


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
    def look_at(origin, target, up=(0.0, 1.0, 0.0), fov: float = 45.0, fov_axis: str = "x") -> Camera:
        from pyclpt.scene.transform import look_at

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
    environment: RGB | Envmap | None = None  # constant radiance or an environment map
    spp: int = 64
    max_depth: int = -1
    name: str = "scene"
    source: Path | None = None
    lights: list[PointLight] = field(default_factory=list)  # emitters that are not shapes

    def __post_init__(self) -> None:
        if not self.meshes:
            raise ValueError(f"scene {self.name!r} has no shapes")
        for mesh in self.meshes:
            if not 0 <= mesh.material < len(self.materials):
                raise ValueError(f"mesh {mesh.name!r} has material {mesh.material}, "
                                 f"but the scene has {len(self.materials)} materials")
        if self.environment is not None and not isinstance(self.environment, Envmap):
            self.environment = rgb(self.environment, "environment radiance")

    @property
    def triangle_count(self) -> int:
        return sum(m.triangle_count for m in self.meshes)

    @property
    def emitter_count(self) -> int:
        return (sum(m.triangle_count for m in self.meshes if m.emission is not None)
                + (1 if self.environment is not None else 0) + len(self.lights))
