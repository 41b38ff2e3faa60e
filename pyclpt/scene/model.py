"""The scene model: plain dataclasses that every loader produces and every
integrator consumes (through :mod:`pyclpt.buffers.scene`).

Conventions follow Mitsuba 3 so that a scene means the same in both: BSDFs are
one-sided unless ``twosided``; area emitters emit on the front side of their
triangles (counter-clockwise winding); the camera looks along +z of its
``to_world`` frame with +x pointing left on the image.

Values are checked when an element is made and again whenever one of its fields is assigned
(``scene.materials[0].reflectance = (-3, 0, 0)`` raises at once, naming the value, and leaves the
old one). Radiance and reflectance-like values (colours, emission, environment, colour textures)
must be finite and >= 0, texels finite. Changes that no assignment sees (numpy arrays edited in
place, an element of a list replaced) are caught by :meth:`Scene.validate`, which checks every
element of the scene, naming it (material index, mesh name, texture or environment map name);
it runs before a scene is put on a device, so no negative or NaN value reaches the kernels.
"""
from __future__ import annotations

import abc
import dataclasses
import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, get_args

import numpy as np

from pyclpt.common.checks import check_bool, check_float, check_int
from pyclpt.scene.transform import apply_normals, apply_points

RGB = tuple[float, float, float]
FLOAT32_MAX = float(np.finfo(np.float32).max)


def rgb(value: object, what: str = "color") -> RGB:
    """A float or 3 floats as an RGB triple; raises ValueError naming ``what``."""
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected a number or 3 finite numbers, got {value!r}") from None
    if arr.size == 1:
        arr = np.repeat(arr, 3)
    if arr.size != 3 or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: expected a number or 3 finite numbers, got {value!r}")
    if np.any(np.abs(arr) > FLOAT32_MAX):  # finite here, infinite in the float32 the device stores
        raise ValueError(f"{what}: {arr.tolist()} is not finite in float32 (largest {FLOAT32_MAX:g}); "
                         f"give values within +-{FLOAT32_MAX:g}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def radiance(value: object, what: str) -> RGB:
    """An RGB triple of finite values >= 0 (a colour, a radiance); ValueError naming ``what``."""
    problem = f"{what}: expected a number or 3 finite numbers >= 0, got {value!r}"
    try:
        out = rgb(value, what)
    except ValueError as exc:
        if "not finite in float32" in str(exc):  # that message says more than the generic one
            raise
        raise ValueError(problem) from None
    if min(out) < 0:
        raise ValueError(problem)
    return out


WRAP_MODES = ("repeat", "mirror", "clamp", "black")
FILTERS = ("nearest", "bilinear")
DISTRIBUTIONS = ("ggx", "beckmann")
FOV_AXES = ("x", "y", "diagonal", "smaller", "larger")
CAMERA_KINDS = ("perspective", "thinlens", "orthographic")
FILTER_KINDS = ("box", "tent", "gaussian")
FILTER_ESTIMATORS = ("importance", "splat")  # ReconstructionFilter.estimator


def _uv(value: object, what: str) -> tuple[float, float]:
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected a number or 2 finite numbers, got {value!r}") from None
    if arr.size == 1:
        arr = np.repeat(arr, 2)
    if arr.size != 2 or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: expected a number or 2 finite numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]))


def _check_uv_transform(tex: Bitmap | Checkerboard) -> None:
    for name in ("uv_scale", "uv_offset", "uv_skew"):
        setattr(tex, name, _uv(getattr(tex, name), f"texture {tex.name!r} {name}"))


def uv_matrix(tex: Bitmap | Checkerboard) -> np.ndarray:
    """The texture's uv transform as a (2, 3) matrix, (s, t) = M (u, v, 1) in pyclpt's uv convention:
    ``[[uv_scale[0], uv_skew[0], uv_offset[0]], [uv_skew[1], uv_scale[1], uv_offset[1]]]`` (the skew
    terms hold a rotation or shear, e.g. of Mitsuba's ``to_uv``)."""
    (su, sv), (ku, kv), (ou, ov) = tex.uv_scale, tex.uv_skew, tex.uv_offset
    return np.array([[su, ku, ou], [kv, sv, ov]], np.float64)


def bad_texel(pixels: np.ndarray, *, negative: bool) -> str | None:
    """None when every texel is finite (and >= 0 unless ``negative``), else where the first bad one is."""
    ok = np.isfinite(pixels) if negative else (np.isfinite(pixels) & (pixels >= 0))
    if ok.all():
        return None
    bad = np.argwhere(~ok)
    r, c, ch = (int(i) for i in bad[0])
    count = f" ({len(bad)} bad values)" if len(bad) > 1 else ""
    return f"texel (row {r}, column {c}, channel {ch}) is {float(pixels[r, c, ch])!r}{count}"


# Elements whose _check() is running: its own assignments (normalised values) are not checked again.
# Kept out of the elements themselves so that their __dict__ holds their fields and nothing else.
_CHECKING: set[int] = set()
# Bumped by every field assignment an element accepts: what keeps a copy of the model (the gradient
# renderer's device buffers) can tell that something changed (generation()).
_GENERATION = [0]


def generation() -> int:
    """A number that changes whenever a field of any element of any scene is assigned."""
    return _GENERATION[0]


class Checked(abc.ABC):
    """Base of the model's dataclasses: ``_check()`` checks and normalises the fields (ValueError or
    TypeError naming the element and the value); it runs when the element is made and again when a
    field is assigned later, and a refused assignment leaves the old value."""

    def __post_init__(self) -> None:
        self._run_check()

    @abc.abstractmethod
    def _check(self) -> None:
        """Check and normalise this element's fields."""

    def validate(self) -> None:
        """Check every field again (after numpy arrays were changed in place, say)."""
        self._run_check()

    def _run_check(self) -> None:
        key = id(self)
        _CHECKING.add(key)
        try:
            self._check()
        finally:
            _CHECKING.discard(key)

    def __setattr__(self, name: str, value: Any) -> None:
        state = self.__dict__
        # The generated __init__ sets each field once (a first assignment); __post_init__ checks them.
        if name not in state or id(self) in _CHECKING or name not in self.__dataclass_fields__:  # type: ignore[attr-defined]
            object.__setattr__(self, name, value)
            return
        old = state[name]
        object.__setattr__(self, name, value)
        try:
            self._run_check()
        except BaseException:
            object.__setattr__(self, name, old)
            raise
        _GENERATION[0] += 1


@dataclass(eq=False)
class Bitmap(Checked):
    """An image texture (Mitsuba ``bitmap``), looked up at the surface's uv.

    ``pixels`` (H, W, C) float32 holds the decoded values: linear radiance-like
    values for ``raw`` or HDR files, sRGB-encoded values in [0, 1] otherwise
    (decoded to linear on the device, before filtering). ``scale`` multiplies
    the value (Mitsuba's ``scale`` texture). Row 0 of ``pixels`` is the top of
    the image, at v = 1 in pyclpt's uv convention (OBJ's, v up; Mitsuba's own v
    runs down from the top, v_mitsuba = 1 - v, and its loader converts). The uv
    transform is :func:`uv_matrix`. Texels must be finite; used as a colour (a
    reflectance, an opacity) they must also be >= 0 (a bump map's heights may not be).
    """

    pixels: np.ndarray
    name: str = "bitmap"
    srgb: bool = True  # pixels are sRGB-encoded (LDR files unless raw)
    filter: str = "bilinear"
    wrap_mode: str = "repeat"
    uv_scale: tuple[float, float] = (1.0, 1.0)
    uv_offset: tuple[float, float] = (0.0, 0.0)
    scale: RGB = (1.0, 1.0, 1.0)
    uv_skew: tuple[float, float] = (0.0, 0.0)

    def _check(self) -> None:
        px = np.asarray(self.pixels, dtype=np.float32)
        if px.ndim == 2:
            px = px[:, :, None]
        if px.ndim != 3 or px.shape[2] not in (1, 2, 3, 4) or px.shape[0] < 1 or px.shape[1] < 1:
            raise ValueError(f"texture {self.name!r}: expected an (H, W, C) image, got shape {px.shape}")
        bad = bad_texel(px, negative=True)
        if bad:
            raise ValueError(f"texture {self.name!r}: {bad}; texels must be finite (no NaN or infinite values)")
        self.pixels = np.ascontiguousarray(px)
        self.srgb = check_bool(self.srgb, f"texture {self.name!r} srgb")
        if self.filter not in FILTERS:
            raise ValueError(f"texture {self.name!r}: filter must be one of {FILTERS}, got {self.filter!r}")
        if self.wrap_mode not in WRAP_MODES:
            raise ValueError(f"texture {self.name!r}: wrap_mode must be one of {WRAP_MODES}, "
                             f"got {self.wrap_mode!r}")
        _check_uv_transform(self)
        self.scale = rgb(self.scale, f"texture {self.name!r} scale")

    def check_colour(self, what: str) -> None:
        """ValueError naming ``what`` unless the texture's values are >= 0 (it is used as a colour)."""
        if min(self.scale) < 0:
            raise ValueError(f"{what}: texture {self.name!r} has a negative scale {self.scale}; a colour "
                             f"must be >= 0")
        if self.pixels.min() < 0:
            raise ValueError(f"{what}: texture {self.name!r}: {bad_texel(self.pixels, negative=False)}; "
                             f"a colour must be >= 0")

    @property
    def width(self) -> int:
        """Pixels per row."""
        return int(self.pixels.shape[1])

    @property
    def height(self) -> int:
        """Rows of pixels."""
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
class Checkerboard(Checked):
    """Mitsuba's ``checkerboard``: at the transformed coordinates (s, t) = :func:`uv_matrix` (u, v, 1),
    ``color0`` where the fractional parts of s and of Mitsuba's t (1 - t: Mitsuba's v runs down) are
    both below or both above one half, ``color1`` elsewhere; ``scale`` multiplies both. Used as a
    scalar (a ``mask``'s opacity, a bump map's height) the two trade places, as Mitsuba 3.9's
    ``checkerboard.eval_1`` does: the mean of ``color1`` where ``eval`` gives ``color0``."""

    color0: RGB = (0.4, 0.4, 0.4)
    color1: RGB = (0.2, 0.2, 0.2)
    uv_scale: tuple[float, float] = (1.0, 1.0)
    uv_offset: tuple[float, float] = (0.0, 0.0)
    scale: RGB = (1.0, 1.0, 1.0)
    name: str = "checkerboard"
    uv_skew: tuple[float, float] = (0.0, 0.0)

    def _check(self) -> None:
        self.color0 = rgb(self.color0, f"texture {self.name!r} color0")
        self.color1 = rgb(self.color1, f"texture {self.name!r} color1")
        _check_uv_transform(self)
        self.scale = rgb(self.scale, f"texture {self.name!r} scale")

    def check_colour(self, what: str) -> None:
        """ValueError naming ``what`` unless both colours times the scale are >= 0."""
        for name in ("color0", "color1", "scale"):
            if min(getattr(self, name)) < 0:
                raise ValueError(f"{what}: texture {self.name!r} {name} {getattr(self, name)} is negative; "
                                 f"a colour must be >= 0")


Texture = Bitmap | Checkerboard
# A material parameter: a constant RGB or a texture.
Color = RGB | Bitmap | Checkerboard


def color(value: object, what: str) -> Color:
    """A texture as is, or an RGB triple (see :func:`rgb`); either way its values must be >= 0."""
    if isinstance(value, (Bitmap, Checkerboard)):
        value.check_colour(what)
        return value
    return radiance(value, what)


def _alpha(value: float, what: str) -> float:
    return check_float(value, f"{what}: roughness alpha", lo=0.0, hi=4.0)


def _alpha_v(value: float | None, alpha: float, what: str) -> float | None:
    """None (isotropic) or Mitsuba's alpha_v, which needs a rough material (alpha = alpha_u > 0)."""
    if value is None:
        return None
    v = _alpha(value, f"{what} alpha_v")
    if v != alpha and not (alpha > 0 and v > 0):
        raise ValueError(f"{what}: anisotropic roughness needs alpha (alpha_u) and alpha_v both > 0, "
                         f"got {alpha!r}, {v!r}")
    return v


def _distribution(value: str, what: str) -> str:
    if value not in DISTRIBUTIONS:
        raise ValueError(f"{what}: microfacet distribution must be one of {DISTRIBUTIONS}, got {value!r}")
    return value


def _ior(value: float, what: str) -> float:
    v = check_float(value, what)
    if not v > 0.0:
        raise ValueError(f"{what}: an index of refraction must be positive and finite, got {value!r}")
    return v


@dataclass
class Diffuse(Checked):
    """Lambertian reflection (Mitsuba ``diffuse``)."""

    reflectance: Color = (0.5, 0.5, 0.5)
    twosided: bool = False

    def _check(self) -> None:
        self.reflectance = color(self.reflectance, "diffuse reflectance")
        self.twosided = check_bool(self.twosided, "diffuse twosided")


@dataclass
class Conductor(Checked):
    """Metal with complex IOR ``eta + i k``; smooth when ``alpha == 0``, else rough
    (``distribution`` GGX or Beckmann; Mitsuba ``conductor`` / ``roughconductor``)."""

    eta: RGB = (0.0, 0.0, 0.0)
    k: RGB = (1.0, 1.0, 1.0)
    alpha: float = 0.0
    specular_reflectance: Color = (1.0, 1.0, 1.0)
    twosided: bool = False
    distribution: str = "ggx"
    alpha_v: float | None = None  # anisotropic: alpha is then Mitsuba's alpha_u (along the tangent dp/du)

    def _check(self) -> None:
        self.eta = radiance(self.eta, "conductor eta")
        self.k = radiance(self.k, "conductor k")
        self.alpha = _alpha(self.alpha, "conductor")
        self.specular_reflectance = color(self.specular_reflectance, "conductor specular_reflectance")
        self.twosided = check_bool(self.twosided, "conductor twosided")
        self.distribution = _distribution(self.distribution, "conductor")
        self.alpha_v = _alpha_v(self.alpha_v, self.alpha, "conductor")

    @property
    def anisotropic(self) -> bool:
        """alpha_u (``alpha``) != ``alpha_v``."""
        return self.alpha_v is not None and self.alpha_v != self.alpha


@dataclass
class Dielectric(Checked):
    """Glass-like interface between ``int_ior`` (inside) and ``ext_ior``; smooth when
    ``alpha == 0``, else rough (Mitsuba ``dielectric`` / ``roughdielectric``)."""

    int_ior: float = 1.5046
    ext_ior: float = 1.000277
    specular_reflectance: Color = (1.0, 1.0, 1.0)
    specular_transmittance: Color = (1.0, 1.0, 1.0)
    alpha: float = 0.0
    distribution: str = "ggx"
    alpha_v: float | None = None  # anisotropic: alpha is then Mitsuba's alpha_u (along the tangent dp/du)

    def _check(self) -> None:
        self.int_ior = _ior(self.int_ior, "dielectric int_ior")
        self.ext_ior = _ior(self.ext_ior, "dielectric ext_ior")
        self.specular_reflectance = color(self.specular_reflectance, "dielectric specular_reflectance")
        self.specular_transmittance = color(self.specular_transmittance, "dielectric specular_transmittance")
        self.alpha = _alpha(self.alpha, "dielectric")
        self.distribution = _distribution(self.distribution, "dielectric")
        self.alpha_v = _alpha_v(self.alpha_v, self.alpha, "dielectric")

    @property
    def anisotropic(self) -> bool:
        """alpha_u (``alpha``) != ``alpha_v``."""
        return self.alpha_v is not None and self.alpha_v != self.alpha


@dataclass
class ThinDielectric(Checked):
    """A thin sheet of glass (Mitsuba ``thindielectric``): reflection with the
    summed internal reflections, transmission without refraction."""

    int_ior: float = 1.5046
    ext_ior: float = 1.000277
    specular_reflectance: Color = (1.0, 1.0, 1.0)
    specular_transmittance: Color = (1.0, 1.0, 1.0)

    def _check(self) -> None:
        self.int_ior = _ior(self.int_ior, "thindielectric int_ior")
        self.ext_ior = _ior(self.ext_ior, "thindielectric ext_ior")
        self.specular_reflectance = color(self.specular_reflectance, "thindielectric specular_reflectance")
        self.specular_transmittance = color(self.specular_transmittance,
                                            "thindielectric specular_transmittance")


@dataclass
class Plastic(Checked):
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

    def _check(self) -> None:
        self.diffuse_reflectance = color(self.diffuse_reflectance, "plastic diffuse_reflectance")
        self.specular_reflectance = color(self.specular_reflectance, "plastic specular_reflectance")
        self.int_ior = _ior(self.int_ior, "plastic int_ior")
        self.ext_ior = _ior(self.ext_ior, "plastic ext_ior")
        self.alpha = _alpha(self.alpha, "plastic")
        self.distribution = _distribution(self.distribution, "plastic")
        self.nonlinear = check_bool(self.nonlinear, "plastic nonlinear")
        self.twosided = check_bool(self.twosided, "plastic twosided")


BaseMaterial = Diffuse | Conductor | Dielectric | ThinDielectric | Plastic


@dataclass
class Mask(Checked):
    """Mitsuba ``mask``: the nested material with probability ``opacity``, else the
    ray passes through (honoured by closest-hit and shadow queries alike)."""

    opacity: Color
    material: Material

    def _check(self) -> None:
        self.opacity = color(self.opacity, "mask opacity")
        _check_material_type(self.material, "mask material")


@dataclass
class BumpMap(Checked):
    """Mitsuba ``bumpmap``: the shading normal perturbed by the gradient of a height texture."""

    height: Texture
    material: Material
    scale: float = 1.0

    def _check(self) -> None:
        if not isinstance(self.height, (Bitmap, Checkerboard)):
            raise TypeError(f"bumpmap height: expected a texture (Bitmap, Checkerboard), "
                            f"got {type(self.height).__name__}")
        _check_material_type(self.material, "bumpmap material")
        self.scale = check_float(self.scale, "bumpmap scale")


@dataclass
class TwoSided(Checked):
    """Mitsuba ``twosided`` with two BSDFs: ``front`` where the path arrives from above the shading normal,
    ``back`` (which sees the directions mirrored to its own front) from below. Both reflect only (no
    dielectrics, as Mitsuba requires) and have no wrappers; a mask or bump map goes around the pair.
    (``twosided`` with one BSDF is the material's own ``twosided`` flag.)"""

    front: BaseMaterial
    back: BaseMaterial

    def _check(self) -> None:
        for side in ("front", "back"):
            mat = getattr(self, side)
            if not isinstance(mat, (Diffuse, Conductor, Plastic)):
                raise TypeError(f"twosided {side}: expected a reflecting material (Diffuse, Conductor, Plastic), "
                                f"got {type(mat).__name__} {mat!r:.60}")


Material = Diffuse | Conductor | Dielectric | ThinDielectric | Plastic | TwoSided | Mask | BumpMap
MATERIALS = get_args(Material)  # the classes, for isinstance


def _check_material_type(mat: object, what: str) -> None:
    if not isinstance(mat, MATERIALS):
        names = ", ".join(t.__name__ for t in MATERIALS)
        raise TypeError(f"{what}: expected a pyclpt material ({names}), got {type(mat).__name__} {mat!r:.60}")


def check_material(mat: object, what: str) -> None:
    """Check a material and everything in it (nested materials, textures) again, with errors
    prefixed by ``what`` (e.g. ``"material 2 (used by 'floor')"``)."""
    _check_material_type(mat, what)
    order: list[Checked] = []  # the material and what it holds, depth first
    stack: list[Checked] = [mat]  # type: ignore[list-item]
    while stack:
        obj = stack.pop()
        if any(obj is seen for seen in order):
            continue
        order.append(obj)
        stack.extend(v for v in (getattr(obj, f) for f in obj.__dataclass_fields__)  # type: ignore[attr-defined]
                     if isinstance(v, Checked))
    try:
        for obj in reversed(order):  # textures and nested materials before what holds them
            obj.validate()
    except (ValueError, TypeError) as exc:
        raise type(exc)(f"{what}: {exc}") from None


def _point(value: object, what: str) -> tuple[float, float, float]:
    """3 finite numbers as a tuple; ValueError naming ``what``."""
    try:
        p = np.asarray(value, np.float64).reshape(-1)
    except (TypeError, ValueError):
        p = np.zeros(0)
    if p.size != 3 or not np.all(np.isfinite(p)):
        raise ValueError(f"{what}: expected 3 finite numbers, got {value!r}")
    return (float(p[0]), float(p[1]), float(p[2]))


@dataclass
class PointLight(Checked):
    """An isotropic point emitter of ``intensity`` (W/sr, rgb) at ``position``."""

    position: tuple[float, float, float]
    intensity: RGB = (1.0, 1.0, 1.0)

    def _check(self) -> None:
        self.position = _point(self.position, "point light position")
        self.intensity = rgb(self.intensity, "point light intensity")
        if min(self.intensity) < 0:
            raise ValueError(f"point light: negative intensity {self.intensity}")


def _unit_vector(value: object, what: str) -> tuple[float, float, float]:
    v = np.asarray(value, np.float64).reshape(-1)
    n = float(np.linalg.norm(v)) if v.size == 3 and np.all(np.isfinite(v)) else 0.0
    if not n > 0:
        raise ValueError(f"{what}: expected 3 finite numbers, not all 0, got {value!r}")
    return (float(v[0] / n), float(v[1] / n), float(v[2] / n))


@dataclass
class DirectionalLight(Checked):
    """A distant light (Mitsuba ``directional``): light travelling along ``direction`` everywhere, with
    ``irradiance`` (W/m^2, rgb) on a surface facing it. A delta light: found by next-event estimation
    only."""

    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    irradiance: RGB = (1.0, 1.0, 1.0)

    def _check(self) -> None:
        self.direction = _unit_vector(self.direction, "directional light direction")
        self.irradiance = radiance(self.irradiance, "directional light irradiance")


@dataclass
class SpotLight(Checked):
    """A spot light (Mitsuba ``spot``) at ``position`` shining along ``direction``: ``intensity`` (W/sr,
    rgb) within ``beam_width`` degrees of the axis, falling linearly in angle to 0 at ``cutoff_angle``
    (Mitsuba's defaults: 20 degrees, and 3/4 of the cutoff for the beam). A delta light."""

    position: tuple[float, float, float]
    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    intensity: RGB = (1.0, 1.0, 1.0)
    cutoff_angle: float = 20.0
    beam_width: float | None = None
    # Mitsuba's ``texture``: projected over the cone, at uv = 1/2 + d_xy / (2 d_z tan(cutoff)) of the
    # direction d in the light's frame (``to_world``'s 3x3 part: +z the axis), v as Mitsuba's (down)
    texture: Bitmap | Checkerboard | None = None
    to_world: np.ndarray | None = None  # (3, 3) the light's frame; None: one built around ``direction``

    def _check(self) -> None:
        self.position = _point(self.position, "spot light position")
        self.direction = _unit_vector(self.direction, "spot light direction")
        self.intensity = radiance(self.intensity, "spot light intensity")
        if self.texture is not None:
            if not isinstance(self.texture, (Bitmap, Checkerboard)):
                raise ValueError(f"spot light texture must be a Bitmap or a Checkerboard, got "
                                 f"{type(self.texture).__name__}")
            self.texture.validate()
            self.texture.check_colour("spot light texture")
        if self.to_world is not None:
            m = np.asarray(self.to_world, np.float64)
            if m.shape != (3, 3) or not np.all(np.isfinite(m)) or abs(np.linalg.det(m)) < 1e-12:
                raise ValueError(f"spot light to_world must be a finite, invertible 3x3 matrix, got {m.tolist()}")
            if np.dot(m[:, 2] / np.linalg.norm(m[:, 2]), self.direction) < 1 - 1e-5:
                raise ValueError("spot light to_world's +z axis must be its direction")
            self.to_world = m
        cutoff = check_float(self.cutoff_angle, "spot light cutoff_angle")
        if not 0.0 < cutoff <= 90.0:
            raise ValueError(f"spot light cutoff_angle must be in (0, 90] degrees, got {self.cutoff_angle}")
        self.cutoff_angle = cutoff
        beam = 0.75 * cutoff if self.beam_width is None else check_float(self.beam_width, "spot light beam_width")
        if not 0.0 < beam <= cutoff:
            raise ValueError(f"spot light beam_width must be in (0, cutoff_angle = {cutoff}] degrees, got {beam}")
        self.beam_width = beam


Light = PointLight | DirectionalLight | SpotLight
LIGHTS = (PointLight, DirectionalLight, SpotLight)


@dataclass(eq=False)
class Envmap(Checked):
    """A lat-long environment map (Mitsuba ``envmap``): ``pixels`` (H, W, 3) linear radiance,
    row 0 at the top (+y in the map's frame), ``to_world`` rotating the map into the scene.
    ``sunsky`` emitters are baked into one of these (pyclpt.scene.sky)."""

    pixels: np.ndarray
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    scale: float = 1.0
    name: str = "envmap"

    def _check(self) -> None:
        px = np.asarray(self.pixels, np.float32)
        if px.ndim == 2:
            px = np.repeat(px[:, :, None], 3, axis=2)
        if px.ndim != 3 or px.shape[2] < 3 or px.shape[0] < 2 or px.shape[1] < 2:
            raise ValueError(f"environment map {self.name!r}: expected an (H, W, 3) image, got {px.shape}")
        px = px[:, :, :3]
        bad = bad_texel(px, negative=False)
        if bad:
            raise ValueError(f"environment map {self.name!r}: {bad}; values must be finite and >= 0")
        self.pixels = np.ascontiguousarray(px)
        m = np.asarray(self.to_world, np.float64).reshape(4, 4)
        if not np.all(np.isfinite(m)):
            raise ValueError(f"environment map {self.name!r}: to_world holds NaN or infinite values")
        self.to_world = m
        if isinstance(self.scale, (bool, np.bool_)) or not (np.isfinite(self.scale) and self.scale >= 0):
            raise ValueError(f"environment map {self.name!r}: scale must be >= 0, got {self.scale}")
        self.scale = float(self.scale)


def base_material(mat: Material) -> BaseMaterial:
    """The BSDF under any mask / bump-map wrappers (the front one of a :class:`TwoSided`)."""
    while isinstance(mat, (Mask, BumpMap)):
        mat = mat.material
    return mat.front if isinstance(mat, TwoSided) else mat


def back_material(mat: Material) -> BaseMaterial | None:
    """The back BSDF of a :class:`TwoSided` under any wrappers, else None."""
    while isinstance(mat, (Mask, BumpMap)):
        mat = mat.material
    return mat.back if isinstance(mat, TwoSided) else None


@dataclass(eq=False)
class Mesh(Checked):
    """A triangle mesh in world space with one material and an optional area emitter."""

    name: str
    positions: np.ndarray  # (V, 3) float32
    indices: np.ndarray  # (T, 3) int32
    material: int  # index into Scene.materials
    normals: np.ndarray | None = None  # (V, 3) float32 shading normals
    uvs: np.ndarray | None = None  # (V, 2) float32
    emission: RGB | None = None  # radiance of an area emitter on the front side
    # an area emitter's radiance texture, looked up at the uv (radiance = emission x texture)
    emission_texture: Bitmap | Checkerboard | None = None

    @property
    def triangle_count(self) -> int:
        """Triangles of the mesh."""
        return int(self.indices.shape[0])

    def placed(self, to_world: np.ndarray, name: str) -> Mesh:
        """A copy named ``name`` in the space ``to_world`` (4x4) maps this mesh's into, as the kernels place an
        instance's meshes: positions by the matrix, normals by its inverse transpose, and the winding reversed
        under a mirroring transform, so that the geometric normal is the transformed one."""
        m = np.asarray(to_world, np.float64)
        normals = None if self.normals is None else apply_normals(m, self.normals.astype(np.float64))
        indices = self.indices[:, ::-1].copy() if np.linalg.det(m[:3, :3]) < 0 else self.indices
        return dataclasses.replace(self, name=name, positions=apply_points(m, self.positions.astype(np.float64)),
                                   normals=normals, indices=indices)

    def _check(self) -> None:
        where = f"mesh {self.name!r}"
        self.positions = np.ascontiguousarray(self.positions, dtype=np.float32).reshape(-1, 3)
        self.indices = np.ascontiguousarray(self.indices, dtype=np.int32).reshape(-1, 3)
        if self.normals is not None:
            self.normals = np.ascontiguousarray(self.normals, dtype=np.float32).reshape(-1, 3)
        if self.uvs is not None:
            self.uvs = np.ascontiguousarray(self.uvs, dtype=np.float32).reshape(-1, 2)
        self.material = check_int(self.material, f"{where} material", lo=0)
        nv = self.positions.shape[0]
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
            if arr is not None and not np.all(np.isfinite(arr)):
                bad = int(np.argwhere(~np.isfinite(arr))[0, 0])
                raise ValueError(f"{where}: vertex {bad} has NaN or infinite {attr} {arr[bad].tolist()}")
        if self.emission is not None:
            self.emission = rgb(self.emission, f"{where} emission")
            if min(self.emission) < 0:
                raise ValueError(f"{where}: negative emitted radiance {self.emission}")
        if self.emission_texture is not None:
            if not isinstance(self.emission_texture, (Bitmap, Checkerboard)):
                raise ValueError(f"{where}: emission_texture must be a Bitmap or a Checkerboard, got "
                                 f"{type(self.emission_texture).__name__}")
            if self.emission is None:
                raise ValueError(f"{where}: an emission_texture needs an emission (its scale, e.g. (1, 1, 1))")
            self.emission_texture.validate()
            self.emission_texture.check_colour(f"{where} emission_texture")


@dataclass(eq=False)
class ShapeGroup(Checked):
    """Mitsuba's ``shapegroup``: meshes in object space, drawn only through :class:`Instance` s. The
    group is stored (and its BVH built) once however many instances use it. Emitters are not allowed
    (Mitsuba 3 refuses them too: "Instancing of emitters is not supported")."""

    name: str
    meshes: list[Mesh]

    @property
    def triangle_count(self) -> int:
        """Triangles of the group's meshes (once, whatever the number of instances)."""
        return sum(m.triangle_count for m in self.meshes)

    def _check(self) -> None:
        where = f"shapegroup {self.name!r}"
        if not isinstance(self.meshes, list) or not all(isinstance(m, Mesh) for m in self.meshes):
            raise TypeError(f"{where} meshes: expected a list of pyclpt.Mesh")
        if not self.meshes:
            raise ValueError(f"{where} has no shapes")
        for m in self.meshes:
            if m.emission is not None:
                raise ValueError(f"{where}: mesh {m.name!r} is an area emitter; emitters inside a shapegroup are "
                                 "not supported (nor by Mitsuba 3): put it outside the group")


def check_instance_transform(m: object, where: str) -> np.ndarray:
    """``m`` as a 4x4 float64 affine object-to-world matrix whose 3x3 part is invertible (ValueError naming
    ``where`` otherwise)."""
    a = np.array(m, dtype=np.float64)
    if a.shape != (4, 4):
        raise ValueError(f"{where}: to_world must be a 4x4 matrix, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{where}: to_world has NaN or infinite entries")
    if not np.array_equal(a[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f"{where}: to_world must be affine (last row 0 0 0 1), got {a[3].tolist()}")
    lin = a[:3, :3]
    scale = float(np.abs(lin).max())
    det = float(np.linalg.det(lin))
    if not (scale > 0 and abs(det) > 1e-9 * scale ** 3):
        raise ValueError(f"{where}: degenerate to_world (determinant {det:.3g} of its 3x3 part): an instance "
                         "must be an invertible transform of its shapegroup")
    return a


@dataclass(eq=False)
class Instance(Checked):
    """Mitsuba's ``instance``: the shapegroup named ``group`` placed by ``to_world`` (4x4, invertible).
    Normals transform by the inverse transpose (Mitsuba's instances), also under a mirroring transform."""

    group: str
    to_world: np.ndarray
    name: str = "instance"

    def _check(self) -> None:
        if not isinstance(self.group, str):
            raise TypeError(f"instance {self.name!r}: group must be a shapegroup name, got {self.group!r:.60}")
        self.to_world = check_instance_transform(self.to_world, f"instance {self.name!r}")


@dataclass
class Camera(Checked):
    """A camera; ``to_world`` maps camera space (looking along +z) to world.

    ``kind``: ``perspective`` (a pinhole, Mitsuba ``perspective``), ``thinlens`` (Mitsuba ``thinlens``: a
    lens of ``aperture_radius`` focused at ``focus_distance`` along +z; to_world must not scale), or
    ``orthographic`` (Mitsuba ``orthographic``: parallel rays along +z from the camera-space square x in
    [-1, 1], y in [-1/aspect, 1/aspect], scaled by to_world; ``fov`` unused)."""

    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    fov: float = 45.0  # degrees, along fov_axis
    fov_axis: str = "x"  # x | y | diagonal | smaller | larger
    kind: str = "perspective"
    aperture_radius: float = 0.0
    focus_distance: float = 0.0

    def _check(self) -> None:
        m = np.asarray(self.to_world, dtype=np.float64).reshape(4, 4)
        if not np.all(np.isfinite(m)):
            raise ValueError(f"camera to_world holds NaN or infinite values: {m.tolist()}")
        self.to_world = m
        fov = check_float(self.fov, "camera fov")
        if not 0.0 < fov < 180.0:
            raise ValueError(f"camera fov must be in (0, 180) degrees, got {self.fov}")
        self.fov = fov
        if self.fov_axis not in FOV_AXES:
            raise ValueError(f"camera fov_axis must be x, y, diagonal, smaller or larger, got {self.fov_axis!r}")
        if self.kind not in CAMERA_KINDS:
            raise ValueError(f"camera kind must be one of {CAMERA_KINDS}, got {self.kind!r}")
        self.aperture_radius = check_float(self.aperture_radius, "camera aperture_radius", lo=0.0)
        self.focus_distance = check_float(self.focus_distance, "camera focus_distance", lo=0.0)
        if self.kind == "thinlens" and self.aperture_radius > 0 and not self.focus_distance > 0:
            raise ValueError(f"a thinlens camera with aperture_radius {self.aperture_radius} needs a "
                             f"focus_distance > 0, got {self.focus_distance}")
        if self.kind == "orthographic" and not (abs(np.linalg.det(m[:3, :3])) > 0):
            raise ValueError("an orthographic camera's to_world must not be singular (its scale is the extent)")

    @staticmethod
    def look_at(origin, target, up=(0.0, 1.0, 0.0), fov: float = 45.0, fov_axis: str = "x") -> Camera:
        """A camera at ``origin`` looking at ``target`` with ``up`` upwards; ``fov`` in degrees along ``fov_axis``."""
        from pyclpt.scene.transform import look_at

        return Camera(look_at(origin, target, up), fov, fov_axis)

    def basis(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(origin, forward, right, up) with right/up scaled by the half-extent of the image plane at z=1;
        for an orthographic camera, by the half-extent of the image in world units (the camera-space
        square x in [-1, 1], y in [-1/aspect, 1/aspect] through to_world, as Mitsuba's)."""
        m = self.to_world
        origin = m[:3, 3]
        cols = [m[:3, i] / max(np.linalg.norm(m[:3, i]), 1e-30) for i in range(3)]
        aspect = width / height
        if self.kind == "orthographic":
            return origin, cols[2], -m[:3, 0], m[:3, 1] / aspect
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
class ReconstructionFilter(Checked):
    """The film's pixel filter, Mitsuba's ``rfilter``: a separable w(x) w(y), x and y in pixels from the
    pixel's centre. ``box`` (w = 1 on [-0.5, 0.5)), ``tent`` (``w = max(0, 1 - |x| / radius)``, ``radius``
    default 1) or ``gaussian`` (w = max(0, exp(-x^2 / (2 stddev^2)) - exp(-8)), cut off at 4 stddev,
    ``stddev`` default 0.5: Mitsuba's default filter). ``radius`` is read by the tent only and
    ``stddev`` by the gaussian only. ``estimator`` (tent and gaussian; the box has one): ``splat`` (the
    default) draws each camera ray uniformly in its pixel and lets it count in every pixel the filter
    reaches, as Mitsuba's film (pyclpt/film/splat.py: Mitsuba's variance at equal spp); ``importance`` draws
    each camera ray's offset from the filter (cl/film/rfilter.h), every sample in its own pixel with weight 1
    (the same mean, 2 to 4 times the variance; each pixel's noise independent of its neighbours')."""

    kind: str = "box"
    radius: float = 1.0
    stddev: float = 0.5
    estimator: str = "splat"

    def _check(self) -> None:
        if self.kind not in FILTER_KINDS:
            raise ValueError(f"reconstruction filter kind must be one of {FILTER_KINDS}, got {self.kind!r}")
        if self.estimator not in FILTER_ESTIMATORS:
            raise ValueError(f"reconstruction filter estimator must be one of {FILTER_ESTIMATORS}, got "
                             f"{self.estimator!r}")
        self.radius = check_float(self.radius, "tent filter radius", lo=0.0)
        self.stddev = check_float(self.stddev, "gaussian filter stddev", lo=0.0)
        if not self.radius > 0:
            raise ValueError(f"tent filter radius must be > 0 pixels, got {self.radius}")
        if not self.stddev > 0:
            raise ValueError(f"gaussian filter stddev must be > 0 pixels, got {self.stddev}")

    @property
    def extent(self) -> float:
        """The filter's support radius in pixels (Mitsuba's ``radius()``)."""
        return {"box": 0.5, "tent": self.radius, "gaussian": 4.0 * self.stddev}[self.kind]

    @property
    def splat_reach(self) -> int:
        """Pixels on each side that a splatting film's samples reach, ceil(extent + 1/2) - 1: the margin it
        renders beyond its window (Mitsuba's ``sample_border``; 0 unless ``estimator="splat"``, the box's)."""
        if self.estimator != "splat" or self.kind == "box":
            return 0
        return max(0, math.ceil(self.extent + 0.5) - 1)


@dataclass
class Film(Checked):
    """The image size and its reconstruction filter (pyclpt's default: ``box``; a Mitsuba scene without
    an ``rfilter`` gets Mitsuba's ``gaussian``)."""

    width: int = 256
    height: int = 256
    rfilter: ReconstructionFilter = field(default_factory=ReconstructionFilter)

    def _check(self) -> None:
        self.width = check_int(self.width, "film width", lo=1, hi=65536)
        self.height = check_int(self.height, "film height", lo=1, hi=65536)
        if not isinstance(self.rfilter, ReconstructionFilter):
            raise TypeError(f"film rfilter: expected a pyclpt.ReconstructionFilter, got {type(self.rfilter).__name__}")
        self.rfilter.validate()


@dataclass(eq=False)
class Scene(Checked):
    """Everything a render needs. ``spp`` and ``max_depth`` are the scene's defaults.

    Assigning a field checks the scene's own values (element types, material indices, the
    environment, spp, max_depth); :meth:`validate` checks every element too."""

    meshes: list[Mesh]
    materials: list[Material]
    camera: Camera = field(default_factory=Camera)
    film: Film = field(default_factory=Film)
    environment: RGB | Envmap | None = None  # constant radiance or an environment map
    spp: int = 64
    max_depth: int = -1
    name: str = "scene"
    source: Path | None = None
    lights: list[Light] = field(default_factory=list)  # emitters that are neither shapes nor the environment
    # Mitsuba's names of objects the meshes' names do not give ("material:3" -> "red", "environment",
    # "light:0"): set by the dict and XML loaders, used by pyclpt.traverse
    ids: dict[str, str] = field(default_factory=dict)
    # Mitsuba's shapegroups by name, and the instances placing them (docs/bvh.md, "Instances")
    groups: dict[str, ShapeGroup] = field(default_factory=dict)
    instances: list[Instance] = field(default_factory=list)
    # every file the loaders read for this scene (the scene file, its includes, meshes, textures,
    # spectra), absolute: what a cache of the loaded scene checks (pyclpt.distributed.worker)
    files: list[Path] = field(default_factory=list)

    def _check(self) -> None:
        where = f"scene {self.name!r}"
        for attr, kind in (("meshes", Mesh), ("materials", MATERIALS), ("lights", LIGHTS),
                           ("instances", Instance)):
            items = getattr(self, attr)
            if not isinstance(items, list):
                raise TypeError(f"{where} {attr}: expected a list, got {type(items).__name__}")
            for i, item in enumerate(items):
                if not isinstance(item, kind):
                    names = ", ".join(t.__name__ for t in (kind if isinstance(kind, tuple) else (kind,)))
                    raise TypeError(f"{where} {attr}[{i}]: expected {names}, got {type(item).__name__} "
                                    f"{item!r:.60}")
        if not self.meshes and not self.instances:
            raise ValueError(f"scene {self.name!r} has no shapes")
        if not isinstance(self.groups, dict) or not all(isinstance(g, ShapeGroup) for g in self.groups.values()):
            raise TypeError(f"{where} groups: expected a dict of names to pyclpt.ShapeGroup")
        for mesh in (*self.meshes, *(m for g in self.groups.values() for m in g.meshes)):
            if not 0 <= mesh.material < len(self.materials):
                raise ValueError(f"mesh {mesh.name!r} has material {mesh.material}, "
                                 f"but the scene has {len(self.materials)} materials")
        for inst in self.instances:
            if inst.group not in self.groups:
                raise ValueError(f"instance {inst.name!r} refers to shapegroup {inst.group!r}, which the scene does "
                                 f"not have (shapegroups: {', '.join(map(repr, self.groups)) or 'none'})")
        if self.environment is not None and not isinstance(self.environment, Envmap):
            self.environment = radiance(self.environment, f"{where} environment radiance")
        if not isinstance(self.camera, Camera):
            raise TypeError(f"{where} camera: expected a pyclpt.Camera, got {type(self.camera).__name__}")
        if not isinstance(self.film, Film):
            raise TypeError(f"{where} film: expected a pyclpt.Film, got {type(self.film).__name__}")
        self.spp = check_int(self.spp, f"{where} spp", lo=1)
        if not isinstance(self.ids, dict) or not all(isinstance(k, str) and isinstance(v, str)
                                                     for k, v in self.ids.items()):
            raise TypeError(f"{where} ids: expected a dict of str to str, got {self.ids!r:.80}")
        self.max_depth = check_int(self.max_depth, f"{where} max_depth", lo=-1, note=" (-1 = unlimited)")

    def material_label(self, index: int) -> str:
        """``material 3 (Diffuse, used by 'floor', 'wall')``, for messages."""
        mat = self.materials[index]
        users = [m.name for m in self.meshes if m.material == index]
        shown = ", ".join(repr(n) for n in users[:3]) + (f" and {len(users) - 3} more" if len(users) > 3 else "")
        return f"material {index} ({type(mat).__name__}, {'used by ' + shown if users else 'unused'})"

    def validate(self) -> None:
        """Check every value of the scene again, element by element: the scene's own fields, then
        every material (with its textures), mesh, light, the environment, camera and film. Catches
        what assignments do not see (arrays changed in place, list items replaced); errors name the
        element (material index and the meshes using it, mesh name, texture or environment map
        name) and the value. Run before a scene is packed for a device."""
        self._run_check()
        for i in range(len(self.materials)):
            check_material(self.materials[i], f"scene {self.name!r} {self.material_label(i)}")
        for element in (*self.meshes, *self.lights, *self.groups.values(),
                        *(m for g in self.groups.values() for m in g.meshes), *self.instances, self.camera, self.film):
            element.validate()
        if isinstance(self.environment, Envmap):
            self.environment.validate()

    @property
    def triangle_count(self) -> int:
        """Triangles of the scene's meshes (instanced triangles: :attr:`instanced_triangle_count`)."""
        return sum(m.triangle_count for m in self.meshes)

    @property
    def emitter_count(self) -> int:
        """Emitting triangles, plus the environment (if any) and the point, spot and directional lights."""
        return (sum(m.triangle_count for m in self.meshes if m.emission is not None)
                + (1 if self.environment is not None else 0) + len(self.lights))

    @property
    def instanced_triangle_count(self) -> int:
        """Triangles drawn through instances (each instance counts its group's triangles)."""
        return sum(self.groups[i.group].triangle_count for i in self.instances)

    def flattened(self) -> Scene:
        """This scene with every instance expanded into plain world-space meshes (copies of its group's
        meshes through its ``to_world``, normals by the inverse transpose, the winding reversed under a
        mirroring transform so the geometric normal is the transformed one, as for instances) and no
        groups: what instancing saves memory on. Materials, camera and the rest are shared."""
        meshes = list(self.meshes)
        for k, inst in enumerate(self.instances):
            group = self.groups[inst.group].meshes
            meshes += [mesh.placed(inst.to_world, f"{inst.name}/{k}/{mesh.name}") for mesh in group]
        return Scene(meshes, self.materials, self.camera, self.film, self.environment, self.spp, self.max_depth,
                     self.name, self.source, self.lights, dict(self.ids))


_GEOMETRY_FIELDS = {Mesh: ("positions", "indices", "normals", "uvs"), Instance: ("to_world",)}


def content_digest(scene: Scene, *, values: bool = True) -> tuple[bytes, bytes]:
    """A cheap digest of what ``scene`` holds, in one pass: (geometry, everything else). Geometry: every
    mesh's (and shapegroup mesh's) positions, indices, normals and uvs, and the instances' transforms;
    the rest: every other array (texels, environment map, transforms) and, with ``values``, every other
    field (numbers, names, enum-like strings) of every element. Arrays are hashed by their bytes, dtype
    and shape, so an in-place edit (a vertex moved, a texel set to NaN) changes the digest. Cost: one
    SHA-1 pass over the arrays (not a security use; about 2 GB/s: ~0.1 ms for the Cornell box, ~1.7 ms
    for a 100k-triangle mesh with normals and uvs)."""
    geo, rest = hashlib.sha1(usedforsecurity=False), hashlib.sha1(usedforsecurity=False)  # SHA-NI: ~2 GB/s

    def array(h, a: np.ndarray) -> None:
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(memoryview(np.ascontiguousarray(a)).cast("B") if a.dtype != object else repr(a).encode())

    def walk(h, obj: object) -> None:
        if isinstance(obj, np.ndarray):
            array(h, obj)
        elif isinstance(obj, Checked):
            h.update(type(obj).__name__.encode())
            split = _GEOMETRY_FIELDS.get(type(obj), ())
            for name, value in vars(obj).items():
                walk(geo if name in split else h, value)
        elif isinstance(obj, (list, tuple)):
            h.update(f"[{len(obj)}".encode())
            for item in obj:
                walk(h, item)
        elif isinstance(obj, dict):
            h.update(f"{{{len(obj)}".encode())
            for k, v in obj.items():
                walk(h, k)
                walk(h, v)
        elif values:
            h.update(repr(obj).encode())

    walk(rest, scene)
    return geo.digest(), rest.digest()
