"""Scene parameters by name: :func:`traverse` (Mitsuba 3's ``mi.traverse``).

A scene's parameters are named as Mitsuba 3 names them for the same scene loaded from a dict or XML
file: ``<bsdf id>.reflectance.value`` for a constant colour, ``<bsdf id>.reflectance.data`` for a
bitmap's texels (linear values, (H, W, C)), ``<bsdf id>.alpha.value`` for a rough conductor's or
dielectric's roughness (``.alpha`` for a rough plastic's), ``<shape id>.emitter.radiance.value`` for
an area light, ``<emitter id>.radiance.value`` for a constant environment and ``<emitter id>.data`` for
an environment map's texels. A BSDF without an id is named after its place (``floor.bsdf``); a
two-sided one's parameters sit under ``.brdf_0``, a mask's or bump map's under ``.nested_bsdf``.
Where things are: ``<shape id>.vertex_positions`` and ``<shape id>.to_world`` (a pose), an instance's,
a spot light's and the sensor's ``to_world``, the sensor's ``x_fov``, a point light's ``position``
(:mod:`pyclpt.gradients.placement`).

Values are numpy arrays. Assign a new value (``params[name] = value``), then call
:meth:`SceneParameters.update`: it checks the values, writes them into the scene and uploads what
changed to the devices that hold the scene for gradients (:mod:`pyclpt.gradients.replay`): a changed
geometry gets its BVH rebuilt there, the rest keeps it, and no kernel is compiled again; renders made
afterwards (``pyclpt.render``) see the changes too.

Parameters whose gradient pyclpt does not compute are listed too, with the reason
(:meth:`SceneParameters.unsupported`); they can still be changed with ``update``.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

import numpy as np

from pyclpt.common.image_io import srgb_to_linear
from pyclpt.gradients import placement
from pyclpt.gradients.flatten import instance_names
from pyclpt.scene.model import (
    Bitmap,
    BumpMap,
    Checkerboard,
    Conductor,
    Dielectric,
    Diffuse,
    DirectionalLight,
    Envmap,
    Instance,
    Mask,
    Material,
    Mesh,
    Plastic,
    PointLight,
    Scene,
    SpotLight,
    ThinDielectric,
    TwoSided,
)

#: Kinds of differentiable parameters (the -D GRAD_* groups of cl/gradients/params.h).
KINDS = ("color", "spec", "alpha", "emission", "env", "geometry", "camera")

NOT_DIFFERENTIABLE = {
    "ior": "index of refraction: not differentiated (changes Fresnel, refraction directions and sampling)",
    "conductor": "complex IOR of a conductor: not differentiated yet",
    "transmission": "dielectric reflectance and transmittance: not differentiated yet",
    "checkerboard": "checkerboard colours: not differentiated (only bitmap texels are)",
    "geometry": "where things are: update() moves it (the BVH refitted or rebuilt, no kernel compiled again); "
                "render_backward differentiates meshes' vertex_positions and to_world, instances' to_world, point "
                "and spot lights' positions and the sensor (docs/differentiable.md)",
    "spot_texture": "a textured spot light's frame: the texture's motion over the cone is not differentiated; "
                    "update() moves it",
    "point": "point light intensity: not differentiated yet",
    "spot": "spot light intensity: not differentiated yet",
    "directional": "directional light irradiance: not differentiated yet",
    "scale": "environment map scale: not differentiated (its texels are)",
    "mask": "opacity: changes visibility, not differentiated",
    "emission_texture": "the radiance of a textured area emitter: not differentiated yet",
    "anisotropic": "anisotropic roughness (alpha_u, alpha_v): not differentiated yet",
    "back": "the back BSDF of a twosided with two BSDFs: not differentiated yet",
}


def _jumping_texture(obj: object) -> bool:
    """Whether a material (or what it wraps) has a texture whose value jumps across the surface: a checkerboard,
    a bitmap filtered by nearest texel. (A bilinear bitmap is continuous: a point sliding over it changes its value
    smoothly, which the interior term has; a jump would be an outline of its own.)"""
    if isinstance(obj, Checkerboard):
        return True
    if isinstance(obj, Bitmap):
        return obj.filter != "bilinear"
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return any(_jumping_texture(getattr(obj, f.name)) for f in dataclasses.fields(obj))
    return False


def flat_shaded(mesh: Mesh, tolerance: float = 1e-4) -> bool:
    """Whether ``mesh`` is shaded by its triangles' normals: no vertex normals, or each triangle's three equal to
    its own (a rectangle's, a cube's)."""
    if mesh.normals is None:
        return True
    p = mesh.positions.astype(np.float64)
    f = mesh.indices
    n = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    vn = mesh.normals.astype(np.float64)[f]  # (T, 3, 3)
    vn /= np.maximum(np.linalg.norm(vn, axis=2, keepdims=True), 1e-300)
    return bool(np.all(np.abs(vn - n[:, None, :]) <= tolerance))


def _camera_boundary_reason(scene: Scene) -> str:
    """Why nothing that moves is differentiated under a camera other than a pinhole or an orthographic one, or ""
    when it may be: the boundary terms (camera silhouettes, the shadows' outlines mapped to the image) are written
    for those two (a thin lens's rays through its aperture are not)."""
    if scene.camera.kind in ("perspective", "orthographic"):
        return ""
    return (f"a {scene.camera.kind} camera: the boundary terms of moving geometry (silhouettes, shadows' outlines) "
            f"are implemented for perspective (pinhole) and orthographic cameras; update() moves it")


def moving_mesh_reason(scene: Scene, mesh: Mesh) -> str:
    """Why the gradient of where ``mesh`` is (its vertex_positions, its to_world) is not computed, or "" when it is:
    the interior term (cl/gradients/geometry.h) holds for meshes untextured or with bilinear bitmaps, flat or
    smooth-shaded (through the vertex normals update() writes: pyclpt/gradients/normals.py), in scenes with or
    without instances (the boundary terms see instances' triangles: pyclpt/gradients/flatten.py), seen by a pinhole
    or an orthographic camera (:func:`_camera_boundary_reason`)."""
    mat = scene.materials[mesh.material]
    if _camera_boundary_reason(scene):
        return _camera_boundary_reason(scene)
    if _jumping_texture(mat) or mesh.emission_texture is not None:
        return ("a checkerboard, a nearest-filtered bitmap or an emission texture: the outlines of a texture's jumps "
                "and a textured emitter's motion under the pixels are not differentiated (bilinear bitmaps are: "
                "cl/gradients/geometry.h, geo_bsdf_bary); update() moves it")
    if isinstance(mat, (BumpMap, Mask)) or getattr(mat, "anisotropic", False):
        return ("a bump-mapped, masked or anisotropic material: its shading frame's or opacity's motion is not "
                "differentiated; update() moves it")
    return ""


def moving_instance_reason(scene: Scene, inst: Instance) -> str:
    """Why the gradient of an instance's to_world is not computed, or "" when it is: the interior term
    (cl/gradients/geometry.h, -DGRAD_INSTANCES: the records' 12 floats) holds for a group of untextured meshes, flat
    or smooth-shaded, whose materials have no bump map, mask or anisotropic frame (as moving_mesh_reason's). Other
    instances of the same group are other records: they stay where they are."""
    for mesh in scene.groups[inst.group].meshes:
        reason = moving_mesh_reason(scene, mesh)
        if reason:
            return reason
    return ""


def moving_camera_reason(scene: Scene) -> str:
    """Why the gradient of where the sensor is (its to_world, its x_fov) is not computed, or "" when it is: the
    interior term (cl/gradients/geometry.h, -DGRAD_CAMERA) holds for a pinhole or an orthographic camera (its
    to_world: it has no x_fov) in a scene without an environment map, emission textures or textures whose value
    jumps (instances or not); bilinear bitmaps slide under the pixels as the camera's hits slide over them
    (geo_bsdf_bary)."""
    if scene.camera.kind not in ("perspective", "orthographic"):
        return (f"a {scene.camera.kind} camera: the gradients of where the sensor is are implemented for perspective "
                f"(pinhole) and orthographic cameras; update() moves it")
    if isinstance(scene.environment, Envmap) or any(_jumping_texture(m) for m in scene.materials) or any(
            m.emission_texture is not None for m in scene.meshes):
        return ("an environment map, an emission texture, a checkerboard or a nearest-filtered bitmap in view: what "
                "slides under the pixels as the camera moves (the map's, a jump's outline) is not differentiated; "
                "update() moves it")
    return ""


@dataclass
class Parameter:
    """One named parameter: how to read and write it in the scene model."""

    name: str
    kind: str  # one of KINDS, or "" when not differentiable
    get: Callable[[], np.ndarray]
    set: Callable[[np.ndarray], None]
    target: object  # the model element it belongs to (material, mesh, bitmap, envmap, scene)
    reason: str = ""  # why it is not differentiable
    material: int = -1  # the index in scene.materials of a material's parameter
    area: str = "appearance"  # what update() refreshes on the devices: appearance, geometry or camera

    @property
    def differentiable(self) -> bool:
        return bool(self.kind)


def _rgb_param(obj: object, attr: str) -> tuple[Callable, Callable]:
    def get() -> np.ndarray:
        return np.asarray(getattr(obj, attr), np.float32).reshape(3)

    def put(v: np.ndarray) -> None:
        setattr(obj, attr, tuple(float(x) for x in np.asarray(v, np.float64).reshape(3)))

    return get, put


def _scalar_param(obj: object, attr: str, positive: str = "") -> tuple[Callable, Callable]:
    def get() -> np.ndarray:
        return np.asarray([getattr(obj, attr)], np.float32)

    def put(v: np.ndarray) -> None:
        x = float(np.asarray(v, np.float64).reshape(-1)[0])
        if positive and not x > 0:
            raise ValueError(f"{positive} must stay > 0, got {x}")
        setattr(obj, attr, x)

    return get, put


def bitmap_linear(bitmap: Bitmap) -> np.ndarray:
    """A bitmap's texels as linear values, (H, W, C) float32 (sRGB-encoded ones decoded; alpha kept)."""
    px = bitmap.pixels
    if not bitmap.srgb:
        return px.copy()
    out = np.asarray(srgb_to_linear(px), np.float32)
    if px.shape[2] in (2, 4):  # alpha is linear
        out[..., -1] = px[..., -1]
    return out


def _bitmap_param(bitmap: Bitmap) -> tuple[Callable, Callable]:
    def get() -> np.ndarray:
        return bitmap_linear(bitmap)

    def put(v: np.ndarray) -> None:
        old = (bitmap.pixels, bitmap.srgb)
        bitmap.srgb = False  # the new texels are linear values
        try:
            bitmap.pixels = np.asarray(v, np.float32)
        except (ValueError, TypeError):
            bitmap.srgb = old[1]
            raise

    return get, put


def _envmap_param(env: Envmap) -> tuple[Callable, Callable]:
    def get() -> np.ndarray:
        return env.pixels.copy()

    def put(v: np.ndarray) -> None:
        env.pixels = np.asarray(v, np.float32)

    return get, put


class _Walker:
    """Collects the Parameters of a scene."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.params: dict[str, Parameter] = {}
        self.index = -1  # the material being walked
        self.only_listed = ""  # a reason that holds for every parameter added now (a TwoSided's back)

    def add(self, name: str, kind: str, accessors: tuple[Callable, Callable], target: object,
            reason: str = "", area: str = "appearance") -> None:
        get, put = accessors
        if self.only_listed:
            kind, reason = "", self.only_listed
        self.params[name] = Parameter(name, kind, get, put, target, NOT_DIFFERENTIABLE.get(reason, reason),
                                      self.index, area)

    def color(self, prefix: str, obj: object, attr: str, kind: str) -> None:
        value = getattr(obj, attr)
        if isinstance(value, Bitmap):
            self.add(f"{prefix}.{attr}.data", kind, _bitmap_param(value), value,
                     "" if kind else "transmission")
        elif isinstance(value, Checkerboard):
            for c in ("color0", "color1"):
                self.add(f"{prefix}.{attr}.{c}.value", "", _rgb_param(value, c), value, "checkerboard")
        else:
            self.add(f"{prefix}.{attr}.value", kind, _rgb_param(obj, attr), obj, "" if kind else "transmission")

    def material(self, prefix: str, mat: Material) -> None:
        while isinstance(mat, (Mask, BumpMap)):
            if isinstance(mat, Mask) and not isinstance(mat.opacity, (Bitmap, Checkerboard)):
                self.add(f"{prefix}.opacity.value", "", _rgb_param(mat, "opacity"), mat, "mask")
            prefix, mat = f"{prefix}.nested_bsdf", mat.material
        if isinstance(mat, TwoSided):  # Mitsuba's names: brdf_0 the front, brdf_1 the back
            self.base(f"{prefix}.brdf_0", mat.front)
            self.only_listed = "back"
            self.base(f"{prefix}.brdf_1", mat.back)
            self.only_listed = ""
            return
        if getattr(mat, "twosided", False):
            prefix = f"{prefix}.brdf_0"
        self.base(prefix, mat)

    def alpha(self, prefix: str, mat: Conductor | Dielectric) -> None:
        """A rough conductor's or dielectric's roughness: alpha, or alpha_u and alpha_v (listed only)."""
        if mat.anisotropic:
            self.add(f"{prefix}.alpha_u.value", "", _scalar_param(mat, "alpha", f"{prefix}.alpha_u.value"), mat,
                     "anisotropic")
            self.add(f"{prefix}.alpha_v.value", "", _scalar_param(mat, "alpha_v", f"{prefix}.alpha_v.value"),
                     mat, "anisotropic")
        else:
            get, put = _scalar_param(mat, "alpha", f"{prefix}.alpha.value")

            def put_both(v: np.ndarray) -> None:  # an explicit isotropic alpha_v stays equal to alpha
                put(v)
                if mat.alpha_v is not None:
                    mat.alpha_v = mat.alpha

            self.add(f"{prefix}.alpha.value", "alpha", (get, put_both), mat)

    def base(self, prefix: str, mat: Material) -> None:
        if isinstance(mat, Diffuse):
            self.color(prefix, mat, "reflectance", "color")
        elif isinstance(mat, Conductor):
            self.color(prefix, mat, "specular_reflectance", "spec")
            if mat.alpha > 0:
                self.alpha(prefix, mat)
            for c in ("eta", "k"):
                self.add(f"{prefix}.{c}.value", "", _rgb_param(mat, c), mat, "conductor")
        elif isinstance(mat, Plastic):
            self.color(prefix, mat, "diffuse_reflectance", "color")
            self.color(prefix, mat, "specular_reflectance", "spec")
            if mat.alpha > 0:
                self.add(f"{prefix}.alpha", "alpha", _scalar_param(mat, "alpha", f"{prefix}.alpha"), mat)
            self.add(f"{prefix}.int_ior", "", _scalar_param(mat, "int_ior"), mat, "ior")
        elif isinstance(mat, (Dielectric, ThinDielectric)):
            self.color(prefix, mat, "specular_reflectance", "")
            self.color(prefix, mat, "specular_transmittance", "")
            if isinstance(mat, Dielectric) and mat.alpha > 0:
                self.alpha(prefix, mat)
            self.add(f"{prefix}.int_ior", "", _scalar_param(mat, "int_ior"), mat, "ior")

    def mesh(self, mesh: Mesh) -> None:
        positions, pose = placement.mesh_accessors(mesh)
        reason = moving_mesh_reason(self.scene, mesh)
        self.add(f"{mesh.name}.vertex_positions", "" if reason else "geometry", positions, mesh, reason, "geometry")
        self.add(f"{mesh.name}.to_world", "" if reason else "geometry", pose, mesh, reason, "geometry")
        if mesh.emission is not None and mesh.emission_texture is not None:
            self.add(f"{mesh.name}.emitter.radiance.value", "", _rgb_param(mesh, "emission"), mesh,
                     "emission_texture")
        elif mesh.emission is not None:
            self.add(f"{mesh.name}.emitter.radiance.value", "emission", _rgb_param(mesh, "emission"), mesh)

    def walk(self) -> dict[str, Parameter]:
        sc = self.scene
        for i, mat in enumerate(sc.materials):
            self.index = i
            self.material(sc.ids.get(f"material:{i}", f"material_{i}"), mat)
        self.index = -1
        for mesh in sc.meshes:
            self.mesh(mesh)
        env = sc.environment
        env_name = sc.ids.get("environment", "environment")
        if isinstance(env, Envmap):
            self.add(f"{env_name}.data", "env", _envmap_param(env), env)
            self.add(f"{env_name}.scale", "", _scalar_param(env, "scale"), env, "scale")
        elif env is not None:
            self.add(f"{env_name}.radiance.value", "env", _rgb_param(sc, "environment"), sc)
        for k, light in enumerate(sc.lights):
            name = sc.ids.get(f"light:{k}", f"light_{k}")
            if isinstance(light, DirectionalLight):
                self.add(f"{name}.irradiance.value", "", _rgb_param(light, "irradiance"), light, "directional")
            else:
                self.add(f"{name}.intensity.value", "", _rgb_param(light, "intensity"), light,
                         "spot" if isinstance(light, SpotLight) else "point")
            if isinstance(light, SpotLight):
                reason = "spot_texture" if light.texture is not None else ""
                reason = _camera_boundary_reason(sc) or reason
                self.add(f"{name}.to_world", "" if reason else "geometry", placement.spot_accessors(light), light,
                         reason, "geometry")
            elif isinstance(light, PointLight):
                reason = _camera_boundary_reason(sc)
                self.add(f"{name}.position", "" if reason else "geometry", placement.point_accessors(light), light,
                         reason, "geometry")
        for name, inst in zip(instance_names(sc), sc.instances):
            reason = moving_instance_reason(sc, inst)
            self.add(f"{name}.to_world", "" if reason else "geometry", placement.instance_accessors(inst), inst,
                     reason, "geometry")
        sensor = sc.ids.get("camera", "sensor")
        to_world, x_fov = placement.camera_accessors(sc)
        reason = moving_camera_reason(sc)
        self.add(f"{sensor}.to_world", "" if reason else "camera", to_world, sc, reason, "camera")
        if x_fov is not None:
            self.add(f"{sensor}.x_fov", "" if reason else "camera", x_fov, sc, reason, "camera")
        return self.params


# What update() refreshes, by id(scene): the device copies of a scene kept for gradients
# (differentiate.py registers and forgets them).
_LISTENERS: dict[int, list[Callable[[frozenset[str]], object]]] = {}


def on_update(scene: Scene, refresh: Callable[[frozenset[str]], object]) -> None:
    """Call ``refresh(areas)`` after :meth:`SceneParameters.update` wrote new values into ``scene``; ``areas``:
    what changed (:attr:`Parameter.area`: ``appearance``, ``geometry``, ``camera``)."""
    _LISTENERS.setdefault(id(scene), []).append(refresh)


def forget(scene: Scene) -> None:
    """No more refreshes for ``scene`` (its device copies were dropped)."""
    _LISTENERS.pop(id(scene), None)


class SceneParameters(Mapping[str, np.ndarray]):
    """The parameters of a scene by name (:func:`traverse`): a mapping of names to numpy arrays.

    ``params[name] = value`` stages a new value (same shape, or a scalar for every element);
    :meth:`update` checks and applies the staged values."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self._params = _Walker(scene).walk()
        self._staged: dict[str, np.ndarray] = {}

    def __getitem__(self, name: str) -> np.ndarray:
        if name in self._staged:
            return self._staged[name].copy()
        return self._param(name).get()

    def __iter__(self) -> Iterator[str]:
        return iter(self._params)

    def __len__(self) -> int:
        return len(self._params)

    def __setitem__(self, name: str, value: object) -> None:
        current = self._param(name).get()
        try:
            arr = np.asarray(value, np.float32)
        except (TypeError, ValueError):
            raise ValueError(f"{name}: expected a number or an array of shape {current.shape}, "
                             f"got {value!r:.60}") from None
        if arr.size == 1:
            arr = np.full(current.shape, arr.reshape(-1)[0], np.float32)
        if arr.shape != current.shape:
            raise ValueError(f"{name}: expected shape {current.shape}, got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name}: values must be finite, got NaN or infinite values")
        self._staged[name] = arr.copy()

    def _param(self, name: str) -> Parameter:
        try:
            return self._params[name]
        except KeyError:
            close = [k for k in self._params if k.split(".")[0] == str(name).split(".")[0]]
            hint = f"; {name.split('.')[0]!r} has: {', '.join(close)}" if close else ""
            raise KeyError(f"scene {self.scene.name!r} has no parameter {name!r}{hint}") from None

    def parameter(self, name: str) -> Parameter:
        """The :class:`Parameter` behind ``name`` (its kind, the model element it belongs to)."""
        return self._param(name)

    @property
    def differentiable(self) -> list[str]:
        """The names whose gradients pyclpt computes."""
        return [k for k, p in self._params.items() if p.differentiable]

    def unsupported(self) -> dict[str, str]:
        """The names whose gradients pyclpt does not compute, each with the reason."""
        return {k: p.reason for k, p in self._params.items() if not p.differentiable}

    def update(self, values: Mapping[str, object] | None = None) -> list[str]:
        """Write the staged values, and ``values`` (a mapping of names to values: an optimiser), into the
        scene (each checked by the scene model: a bad value raises ValueError naming the parameter,
        nothing is written and the staged values are dropped), then upload what changed to the device
        copies kept for gradients. Returns the names updated."""
        try:
            for k, v in (values or {}).items():
                self[k] = v
        except Exception:  # all or nothing: a bad value drops every staged one, none is written later
            self._staged.clear()
            raise
        names = list(self._staged)
        targets = [id(self._params[k].target) for k in names if self._params[k].area == "geometry"
                   and isinstance(self._params[k].target, Mesh)]
        if len(targets) != len(set(targets)):
            twice = [k for k in names if targets.count(id(self._params[k].target)) > 1]
            self._staged.clear()
            raise ValueError(f"{' and '.join(twice)}: one mesh's positions and pose in one update; set one of "
                             f"them (the pose moves the positions)")
        areas = frozenset(self._params[k].area for k in names)
        olds = {k: self._params[k].get() for k in names}
        done: list[str] = []
        try:
            for k in names:
                self._params[k].set(self._staged[k])
                done.append(k)
        except (ValueError, TypeError) as exc:
            for k in done:  # leave the scene as it was, and drop the staged values
                self._params[k].set(olds[k])
            self._staged.clear()
            raise ValueError(f"{k}: {exc}") from None
        if names:
            try:
                for refresh in _LISTENERS.get(id(self.scene), []):
                    refresh(areas)
            except ValueError:
                for k in names:
                    self._params[k].set(olds[k])
                self._staged.clear()
                for refresh in _LISTENERS.get(id(self.scene), []):
                    refresh(areas)
                raise
        self._staged.clear()
        return names

    def __repr__(self) -> str:
        lines = [f"SceneParameters[{self.scene.name!r}]"]
        for k, p in self._params.items():
            lines.append(f"  {'*' if p.differentiable else ' '} {k}: {p.get().shape}")
        return "\n".join(lines)


def traverse(scene: Scene) -> SceneParameters:
    """The parameters of ``scene`` by name (see the module's docstring)."""
    if not isinstance(scene, Scene):
        raise TypeError(f"traverse needs a pyclpt.Scene, got {type(scene).__name__}")
    scene.validate()
    return SceneParameters(scene)
