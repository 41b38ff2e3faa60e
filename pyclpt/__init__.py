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
:mod:`pyclpt.distributed`; the live viewer and notebook images: :mod:`pyclpt.viewer`; the command line:
:mod:`pyclpt.cli`.

The names of ``__all__`` are loaded on first use (a module ``__getattr__``), so ``import pyclpt`` and
the command line's start-up do not load pyopencl, numpy, Dask, the denoisers or OpenImageIO until
something needs them; ``from pyclpt import X`` works as for any attribute.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

# Each public name and the module that defines it, imported on first use (__getattr__ below).
_SOURCES: dict[str, tuple[str, ...]] = {
    "pyclpt.common.env": ("EnvironmentVariableError",),
    "pyclpt.common.image_io": ("read_image", "write_image"),
    "pyclpt.denoise": ("Denoiser", "DenoiserSettings"),
    "pyclpt.device.context": ("Device", "DeviceError", "DeviceMemoryError", "default_device", "get_device",
                              "list_devices", "open_device"),
    "pyclpt.device.program": ("KernelBuildError",),
    "pyclpt.distributed": ("DistributedRenderer",),
    "pyclpt.film.accumulator": ("Accumulator", "AccumulatorError"),
    "pyclpt.gradients": ("SceneParameters", "optim", "render_backward", "render_forward", "traverse"),
    "pyclpt.rendering.progressive": ("ProgressiveRenderer",),
    "pyclpt.rendering.renderer": ("Renderer", "RenderStats", "render"),  # render: local, or on a cluster (client=)
    "pyclpt.scene.camera_path": ("CameraPath", "Keyframe"),
    "pyclpt.scene.library": ("builtin_scenes", "load"),
    "pyclpt.scene.mitsuba_dict": ("SceneDictError", "load_dict"),
    "pyclpt.scene.mitsuba_xml": ("SceneXMLError", "load_xml"),
    "pyclpt.scene.model": ("Bitmap", "BumpMap", "Camera", "Checkerboard", "Conductor", "Dielectric", "Diffuse",
                           "DirectionalLight", "Envmap", "Film", "Instance", "Mask", "Mesh", "Plastic", "PointLight",
                           "ReconstructionFilter", "Scene", "ShapeGroup", "SpotLight", "ThinDielectric",
                           "TwoSided"),
    "pyclpt.viewer": ("show", "view"),  # the live viewer (view: the [viewer] extra) and notebook images
}
_MODULE_OF = {name: module for module, names in _SOURCES.items() for name in names}

if TYPE_CHECKING:  # what static tools see: the same names, imported eagerly
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
    from pyclpt.distributed import DistributedRenderer
    from pyclpt.film.accumulator import Accumulator, AccumulatorError
    from pyclpt.gradients import SceneParameters, optim, render_backward, render_forward, traverse
    from pyclpt.rendering.progressive import ProgressiveRenderer
    from pyclpt.rendering.renderer import Renderer, RenderStats, render
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
    from pyclpt.viewer import show, view


def __getattr__(name: str) -> Any:
    """A public name of :data:`__all__`, imported from its module on first use (then kept here)."""
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'pyclpt' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})


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
    "show", "view",
]
