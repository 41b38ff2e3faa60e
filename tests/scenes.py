"""Small analytic scenes for the tests, built with pyclpt.scene.mitsuba_dict."""
from __future__ import annotations

import pyclpt

CENTER_CAMERA = [{"look_at": {"origin": [0, 0, 0], "target": [0, 0, -1], "up": [0, 1, 0]}}]
FRONT_CAMERA = [{"look_at": {"origin": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0]}}]


def sensor(to_world, fov=60.0, size=16, spp=64):
    return {"type": "perspective", "fov": fov, "to_world": to_world,
            "film": {"width": size, "height": size}, "sampler": {"sample_count": spp}}


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
