"""Small analytic scenes for the tests, built with pyclpt.scene.mitsuba_dict."""
from __future__ import annotations

import pyclpt

CENTER_CAMERA = [{"look_at": {"origin": [0, 0, 0], "target": [0, 0, -1], "up": [0, 1, 0]}}]
FRONT_CAMERA = [{"look_at": {"origin": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0]}}]


def sensor(to_world, fov=60.0, size=16, spp=64, rfilter="box"):
    """A camera; the box filter by default (Mitsuba's default is the gaussian): the tests reason about
    what each pixel's own footprint sees."""
    return {"type": "perspective", "fov": fov, "to_world": to_world,
            "film": {"width": size, "height": size, "rfilter": {"type": rfilter}}, "sampler": {"sample_count": spp}}


def interior_furnace(albedo: float, radiance: float = 1.0) -> pyclpt.Scene:
    """Camera at the centre of a closed emissive diffuse sphere (faceted, normals inward):
    radiance is Le * sum_{k<d} albedo^k for max_depth d."""
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": sensor(CENTER_CAMERA),
        "shell": {"type": "sphere", "radius": 3.0, "flip_normals": True, "face_normals": True,
                  "bsdf": {"type": "diffuse", "reflectance": albedo},
                  "emitter": {"type": "area", "radiance": radiance}},
    }, name="interior-furnace")


def object_under_sky(bsdf: dict, radiance: float = 1.5, shape: str = "cube") -> pyclpt.Scene:
    """A convex faceted object lit by a constant environment, seen from the front."""
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": sensor(FRONT_CAMERA, fov=40.0, size=24),
        "sky": {"type": "constant", "radiance": radiance},
        "object": {"type": shape, "face_normals": True, "bsdf": bsdf,
                   "to_world": [{"rotate": {"axis": [1, 1, 0], "angle": 30}}]},
    }, name="object-under-sky")


ZOO_MATERIALS = [
    {"type": "diffuse", "reflectance": {"type": "checkerboard", "color0": [0.8, 0.2, 0.2], "color1": [0.1, 0.6, 0.9]}},
    {"type": "conductor", "material": "Au"},
    {"type": "roughconductor", "material": "Cu", "alpha": 0.2},
    {"type": "roughconductor", "material": "Al", "alpha": 0.3, "distribution": "beckmann"},
    {"type": "dielectric", "int_ior": 1.5},
    {"type": "roughdielectric", "int_ior": 1.5, "alpha": 0.15},
    {"type": "roughdielectric", "int_ior": 1.33, "alpha": 0.3, "distribution": "beckmann"},
    {"type": "thindielectric", "int_ior": 1.5},
    {"type": "plastic", "diffuse_reflectance": [0.2, 0.5, 0.2]},
    {"type": "roughplastic", "diffuse_reflectance": [0.5, 0.2, 0.5], "alpha": 0.2},
    {"type": "twosided", "bsdf": {"type": "plastic", "nonlinear": True}},
    {"type": "bumpmap", "arg": {"type": "checkerboard"}, "scale": 0.5, "bsdf": {"type": "diffuse"}},
    {"type": "mask", "opacity": {"type": "checkerboard", "color0": 0.2, "color1": 0.9}, "bsdf": {"type": "diffuse"}},
]


def material_zoo(size: int = 32) -> pyclpt.Scene:
    """Every material kind (two distributions for the rough ones), a texture, a bump map and a mask, on
    cubes and spheres (faceted and smooth) in a row, over an emissive floor, lit by a point light and a
    constant environment: every branch of the shading code in one small scene."""
    objects = {}
    for i, bsdf in enumerate(ZOO_MATERIALS):
        x, y = (i % 5) * 2.2 - 4.4, (i // 5) * 2.2 - 2.2
        objects[f"object{i}"] = {"type": "sphere" if i % 2 else "cube", "face_normals": i % 3 == 0, "bsdf": bsdf,
                                 "to_world": [{"scale": 0.9}, {"rotate": {"axis": [1, 1, 0], "angle": 30}},
                                              {"translate": [x, y, 0]}]}
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": sensor([{"look_at": {"origin": [0, 0, 9], "target": [0, 0, 0], "up": [0, 1, 0]}}], size=size),
        "sky": {"type": "constant", "radiance": 0.6},
        "lamp": {"type": "point", "position": [2, 4, 5], "intensity": 40.0},
        "floor": {"type": "rectangle", "bsdf": {"type": "diffuse"}, "emitter": {"type": "area", "radiance": 0.3},
                  "to_world": [{"scale": 20}, {"translate": [0, 0, -2]}]},
        **objects,
    }, name="material-zoo")
