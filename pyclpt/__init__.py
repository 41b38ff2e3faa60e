"""pyclpt: a wavefront Monte Carlo path tracer with OpenCL C kernels, driven from Python.

    import pyclpt
    scene = pyclpt.load("cornell-box")
    image = pyclpt.render(scene, spp=64, seed=0)          # (H, W, 3) float32, linear
    pyclpt.write_image("cornell.png", image)

Data flow: scene file -> scene model (:mod:`pyclpt.scene`) -> BVH (:mod:`pyclpt.bvh`)
-> device buffers (:mod:`pyclpt.scene_buffers`) -> integrator (:mod:`pyclpt.megakernel`,
:mod:`pyclpt.wavefront`) -> film and accumulator (:mod:`pyclpt.film`, :mod:`pyclpt.accumulator`;
progressive rendering: :mod:`pyclpt.progressive`) -> image (:mod:`pyclpt.image_io`).
"""
from __future__ import annotations

from .accumulator import Accumulator, AccumulatorError
from .device import Device, DeviceError, default_device, get_device, list_devices, open_device
from .image_io import read_image, write_image
from .load_dict import SceneDictError, load_dict
from .mitsuba_xml import SceneXMLError, load_xml
from .program import KernelBuildError
from .progressive import ProgressiveRenderer
from .renderer import Renderer, RenderStats, render
from .scene import (Bitmap, BumpMap, Camera, Checkerboard, Conductor, Dielectric, Diffuse, Envmap, Film, Mask, Mesh,
                    Plastic, PointLight, Scene, ThinDielectric)
from .scene_library import builtin_scenes, load

__version__ = "0.1.0"

__all__ = [
    "Accumulator", "AccumulatorError", "ProgressiveRenderer",
    "Bitmap", "BumpMap", "Checkerboard", "Envmap", "Mask", "Plastic", "PointLight", "ThinDielectric",
    "Camera", "Conductor", "Device", "DeviceError", "Dielectric", "Diffuse", "Film", "KernelBuildError",
    "Mesh", "RenderStats", "Renderer", "Scene", "SceneDictError", "SceneXMLError", "builtin_scenes",
    "default_device", "get_device", "list_devices", "load", "load_dict", "load_xml", "open_device", "read_image",
    "render", "write_image",
]
