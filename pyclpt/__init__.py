"""pyclpt: a wavefront Monte Carlo path tracer with OpenCL C kernels, driven from Python.

    import pyclpt
    scene = pyclpt.load("cornell-box")
    image = pyclpt.render(scene, spp=64, seed=0)          # (H, W, 3) float32, linear
    pyclpt.write_image("cornell.png", image)

Data flow, one subpackage per step (lower layers never import higher ones; docs/architecture.md):
scene file -> scene model (:mod:`pyclpt.scene`) -> BVH (:mod:`pyclpt.accel`) -> device buffers
(:mod:`pyclpt.buffers`) -> integrator (:mod:`pyclpt.integrators`) -> film and accumulation
(:mod:`pyclpt.film`, with the G-buffer: :mod:`pyclpt.film.aovs`) -> denoiser (:mod:`pyclpt.denoise`)
-> image (:mod:`pyclpt.common.image_io`); gradients by path replay: :mod:`pyclpt.gradients`.
Camera motion: :mod:`pyclpt.scene.camera_path`. OpenCL devices and programs:
:mod:`pyclpt.device`; rendering sessions: :mod:`pyclpt.rendering`; renders on a Dask cluster:
:mod:`pyclpt.distributed`; the command line: :mod:`pyclpt.cli`.
"""
from __future__ import annotations

from pyclpt.common.env import EnvironmentVariableError
from pyclpt.common.image_io import read_image, write_image
from pyclpt.denoise import Denoiser, DenoiserSettings
from pyclpt.device.context import (
    Device,
    DeviceError,
    DeviceMemoryError,
    default_device,
    get_device,
    list_devices,
    open_device,
)
from pyclpt.device.program import KernelBuildError
from pyclpt.distributed import DistributedRenderer, render  # render: local, or on a Dask cluster (client=)
from pyclpt.film.accumulator import Accumulator, AccumulatorError
from pyclpt.gradients import SceneParameters, optim, render_backward, render_forward, traverse
from pyclpt.rendering.progressive import ProgressiveRenderer
from pyclpt.rendering.renderer import Renderer, RenderStats
from pyclpt.scene.camera_path import CameraPath, Keyframe
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
    DirectionalLight,
    Envmap,
    Film,
    Instance,
    Mask,
    Mesh,
    Plastic,
    PointLight,
    ReconstructionFilter,
    Scene,
    ShapeGroup,
    SpotLight,
    ThinDielectric,
    TwoSided,
)

__version__ = "0.1.0"

__all__ = [
    "Accumulator", "AccumulatorError", "Bitmap", "builtin_scenes", "BumpMap", "Camera", "CameraPath", "Checkerboard",
    "Conductor", "default_device", "Denoiser", "DenoiserSettings", "Device", "DeviceError", "DeviceMemoryError",
    "Dielectric", "Diffuse", "DirectionalLight", "DistributedRenderer", "EnvironmentVariableError", "Envmap", "Film",
    "get_device",
    "Instance", "Keyframe", "KernelBuildError", "list_devices", "load", "load_dict", "load_xml", "Mask", "Mesh",
    "open_device", "Plastic", "PointLight", "ProgressiveRenderer", "read_image", "ReconstructionFilter", "render",
    "Renderer", "RenderStats", "Scene", "SceneDictError", "SceneXMLError", "ShapeGroup", "SpotLight", "ThinDielectric",
    "TwoSided", "write_image",
    "SceneParameters", "optim", "render_backward", "render_forward", "traverse",
]
