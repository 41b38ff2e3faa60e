"""Small scenes for the gradient tests (tests/test_gradients.py), built with pyclpt.load_dict so that their
parameters have Mitsuba's names."""
from __future__ import annotations

import numpy as np

import pyclpt
from scenes import FRONT_CAMERA, object_under_sky, sensor


def textured_quad(texels: np.ndarray, size: int = 16, filter: str = "bilinear") -> pyclpt.Scene:
    """A square seen face-on filling the image, its diffuse reflectance the bitmap ``texels`` (linear,
    id ``tex``: parameter ``tex.reflectance.data``), under a constant sky (``sky``)."""
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": sensor(FRONT_CAMERA, fov=25.0, size=size),
        "sky": {"type": "constant", "radiance": 1.0},
        "quad": {"type": "rectangle", "bsdf": {"type": "diffuse", "id": "tex", "reflectance": {
            "type": "bitmap", "data": texels, "filter_type": filter}}},
    }, name="textured-quad")


def sphere_under_envmap(pixels: np.ndarray, size: int = 16) -> pyclpt.Scene:
    """A faceted diffuse sphere (id ``ball``) lit by an environment map (``env``, parameter ``env.data``)."""
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": sensor(FRONT_CAMERA, fov=40.0, size=size),
        "env": {"type": "envmap", "data": pixels},
        "ball": {"type": "sphere", "face_normals": True, "bsdf": {"type": "diffuse", "id": "ball",
                                                                   "reflectance": [0.6, 0.5, 0.4]}},
    }, name="sphere-under-envmap")


def filling_sphere(albedo: float, radiance: float) -> pyclpt.Scene:
    """A faceted diffuse sphere (``ball``) filling the whole image, in a uniform environment (``sky``):
    every pixel sees it, and its radiance is albedo * radiance (the object is convex)."""
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": sensor(FRONT_CAMERA, fov=8.0, size=8),
        "sky": {"type": "constant", "radiance": radiance},
        "ball": {"type": "sphere", "face_normals": True,
                 "bsdf": {"type": "diffuse", "id": "ball", "reflectance": albedo}},
    }, name="filling-sphere")


def material_under_sky(bsdf: dict) -> pyclpt.Scene:
    """``bsdf`` (give it the id ``m``) on a cube under a constant sky (``sky``)."""
    return object_under_sky(dict(bsdf, id="m"))


def update_differences(scene: pyclpt.Scene, params, name: str, tangent: np.ndarray, h: float
                        ) -> tuple[np.ndarray, np.ndarray]:
    """(central differences, forward mode) of the image along ``tangent`` in parameter ``name``, the differences
    through params.update() (what update() writes: recomputed normals, a spot light's record), 16 spp, the same
    seed on both sides."""
    base = np.asarray(params[name], np.float64)

    def render(s: float) -> np.ndarray:
        params.update({name: (base + s * tangent).astype(np.float32)})
        return pyclpt.render(scene, spp=16, seed=3, max_depth=2).astype(np.float64)

    fd = (render(h) - render(-h)) / (2 * h)
    params.update({name: base.astype(np.float32)})
    fwd = pyclpt.render_forward(scene, name, tangent, spp=16, seed=3, max_depth=2, boundary=False)
    return fd, fwd.astype(np.float64)
