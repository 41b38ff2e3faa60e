"""pyclpt: a wavefront Monte Carlo path tracer with OpenCL C kernels, driven from Python.

    import pyclpt
    scene = pyclpt.load("cornell-box")
    image = pyclpt.render(scene, spp=64, seed=0)          # (H, W, 3) float32, linear
    pyclpt.write_image("cornell.png", image)

Data flow: scene file -> scene model (:mod:`pyclpt.scene.model`) -> BVH (:mod:`pyclpt.accel.bvh`)
-> device buffers (:mod:`pyclpt.buffers.scene`) -> integrator (:mod:`pyclpt.integrators.megakernel`,
:mod:`pyclpt.integrators.wavefront`) -> film and accumulator (:mod:`pyclpt.film.film`, :mod:`pyclpt.film.accumulator`;
progressive rendering: :mod:`pyclpt.rendering.progressive`) -> image (:mod:`pyclpt.common.image_io`).
"""
from __future__ import annotations

from pyclpt.common.image_io import read_image, write_image
from pyclpt.device.context import Device, DeviceError, default_device, get_device, list_devices, open_device
from pyclpt.device.program import KernelBuildError
from pyclpt.film.accumulator import Accumulator, AccumulatorError
from pyclpt.rendering.progressive import ProgressiveRenderer
from pyclpt.rendering.renderer import Renderer, RenderStats, render
from pyclpt.scene.library import builtin_scenes, load
from pyclpt.scene.mitsuba_dict import SceneDictError, load_dict
from pyclpt.scene.mitsuba_xml import SceneXMLError, load_xml
from pyclpt.scene.model import (
                    Bitmap,
                    BumpMap,
                    Camera,
                    Checkerboard,
                    Conductor,
                    Dielectric,
                    Diffuse,
                    Envmap,
                    Film,
                    Mask,
                    Mesh,
                    Plastic,
                    PointLight,
                    Scene,
                    ThinDielectric,
)

__version__ = "0.1.0"

__all__ = [
    "Accumulator", "AccumulatorError", "ProgressiveRenderer",
    "Bitmap", "BumpMap", "Checkerboard", "Envmap", "Mask", "Plastic", "PointLight", "ThinDielectric",
    "Camera", "Conductor", "Device", "DeviceError", "Dielectric", "Diffuse", "Film", "KernelBuildError",
    "Mesh", "RenderStats", "Renderer", "Scene", "SceneDictError", "SceneXMLError", "builtin_scenes",
    "default_device", "get_device", "list_devices", "load", "load_dict", "load_xml", "open_device", "read_image",
    "render", "write_image",
]
