"""Progressive rendering: one frame (one sample of every pixel) at a time, averaged on the
device by the film's :class:`~pyclpt.film.accumulator.Accumulator`, with automatic reset when the
scene changes.

    pr = pyclpt.ProgressiveRenderer(scene, seed=0, precision="double")
    for _ in range(64):
        pr.step()                 # renders sample index pr.sample_index, then advances it
        show(pr.image())          # the average so far
    pr.set_camera(pyclpt.Camera.look_at(...))   # resets: the next frame is sample 0 again

With a denoiser (``denoiser="svgf"``, ``"blend"`` or ``"oidn"``; :mod:`pyclpt.denoise`) every frame
also records its G-buffer (:mod:`pyclpt.film.aovs`) and is denoised; :meth:`denoised` is the result:

    pr = pyclpt.ProgressiveRenderer(scene, denoiser="svgf",
                                    camera_path=pyclpt.CameraPath.orbit(scene, 30, frames=16))
    for _ in range(16):
        pr.step()                 # frame k: the path's camera k, one sample per pixel, denoised
        show(pr.denoised())

Sample indices: the k-th frame rendered since the last reset uses sample index k, so the
image after N frames equals ``Renderer(scene).render(N, seed)`` bit for bit (same precision),
and a run is reproducible from its seed. With ``overflow="reset"`` or ``"ema"`` the sample
index keeps advancing past ``max_frame_count`` (each restart averages new samples); with
``"stop"`` no more frames are rendered once the count is reached.

Auto-reset: before the frames of every ``step``/``run`` call (the scene cannot change between
the frames of one call) a fingerprint of the scene (camera, materials, emitters, geometry,
resolution; numpy arrays by CRC-32 of their bytes: about 0.1 s for the 263k-triangle, 9-texture
staircase) is compared with the one the device holds. A change rebuilds what is on the device
and, with ``auto_reset`` (the default), restarts the accumulation at sample 0; camera jitter is
part of each sample (its random numbers), not of the scene, so new frames never reset.
Changing the scene dataclasses directly is detected the same way as the setters
(:meth:`set_camera`, :meth:`set_material`,
:meth:`set_emission`, :meth:`set_environment`, :meth:`set_meshes`, :meth:`set_resolution`).
A resolution change always resets (the buffers change size).

Camera motion: a :class:`~pyclpt.scene.camera_path.CameraPath` (``camera_path=``) sets the camera of
every frame (frame k of the renderer's life: ``camera_path.camera(k)``), and :meth:`set_camera` moves
it between frames. The frame after a move records motion vectors back to the camera before it (the
scene buffers hold both cameras), the frames without one record zero motion. Without a denoiser a
move resets as any camera change does. With one, a move (and any other scene change but the
resolution) restarts only the plain average (:meth:`image`): the sample index goes on, so frames
never repeat their random numbers, and the denoiser keeps its history, which it reprojects along the
motion vectors (SVGF) and clips where the scene changed; ``reprojections`` counts those moves.
"""
from __future__ import annotations

import dataclasses
import logging
import time
import zlib
from collections import Counter
from collections.abc import Callable, Hashable, Sequence
from typing import Any

import numpy as np

from pyclpt.common.checks import check_bool, check_int, check_optional_bool, check_optional_int, is_int
from pyclpt.denoise import MODES as DENOISER_MODES
from pyclpt.denoise import Denoiser, DenoiserSettings
from pyclpt.device.context import Device
from pyclpt.device.program import compile_notice
from pyclpt.film.accumulator import Accumulator, check_options
from pyclpt.film.aovs import AOV_NAMES, check_aovs
from pyclpt.film.film import DEFAULT_PRECISION
from pyclpt.rendering.frame_loop import progress_bar
from pyclpt.rendering.renderer import MAX_RESOLUTION, Renderer, RenderStats
from pyclpt.scene.camera_path import CameraPath
from pyclpt.scene.model import Camera, Mesh, ReconstructionFilter, Scene, check_material, rgb

log = logging.getLogger("pyclpt.rendering.progressive")

# What each change of the scene is called; fields not listed are "scene", spp/name/source are ignored.
SCENE_FIELDS = {"camera": "camera", "materials": "material", "environment": "emitter", "lights": "emitter",
                "film": "resolution", "max_depth": "max_depth"}
MESH_FIELDS = {"emission": "emitter", "material": "material"}  # all other mesh fields: "geometry"
IGNORED_FIELDS = ("spp", "name", "source")
CHANGE_KINDS = ("camera", "material", "emitter", "geometry", "resolution", "max_depth", "scene")


def digest(obj: Any) -> Hashable:
    """A hashable summary of a value: dataclasses field by field, sequences item by item,
    numpy arrays by dtype, shape and the CRC-32 of their bytes."""
    if isinstance(obj, np.ndarray):
        data = np.ascontiguousarray(obj).reshape(-1).view(np.uint8)
        return ("ndarray", obj.dtype.str, obj.shape, zlib.crc32(data))
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return (type(obj).__name__,) + tuple((f.name, digest(getattr(obj, f.name)))
                                             for f in dataclasses.fields(obj))
    if isinstance(obj, (list, tuple)):
        return (type(obj).__name__,) + tuple(digest(x) for x in obj)
    if isinstance(obj, dict):
        return ("dict",) + tuple((k, digest(v)) for k, v in sorted(obj.items(), key=lambda kv: str(kv[0])))
    if isinstance(obj, np.generic):
        return obj.item()
    try:
        hash(obj)
    except TypeError:
        return (type(obj).__name__, repr(obj))
    return obj


def scene_fingerprint(scene: Scene, *, resolution: tuple[int, int] | None = None,
                      max_depth: int | None = None) -> dict[str, Hashable]:
    """The scene's state by kind of change (see CHANGE_KINDS). ``resolution`` / ``max_depth``:
    the renderer's own overrides, which replace the scene's film / max_depth."""
    parts: dict[str, list] = {k: [] for k in CHANGE_KINDS}
    for f in dataclasses.fields(scene):
        name = f.name
        if name in IGNORED_FIELDS:
            continue
        value = getattr(scene, name)
        if name == "meshes":
            parts["geometry"].append(len(value))
            for mesh in value:
                for mf in dataclasses.fields(mesh):
                    parts[MESH_FIELDS.get(mf.name, "geometry")].append((mf.name, digest(getattr(mesh, mf.name))))
        elif name == "film" and resolution is not None:
            parts["resolution"].append(tuple(resolution))
            if value.rfilter != ReconstructionFilter():  # the size is overridden, not the filter (the box: as
                parts["scene"].append(("rfilter", digest(value.rfilter)))  # before filters, so cache keys stay)
        elif name == "max_depth" and max_depth is not None:
            parts["max_depth"].append(max_depth)
        else:
            parts[SCENE_FIELDS.get(name, "scene")].append((name, digest(value)))
    return {k: tuple(v) for k, v in parts.items()}


class ProgressiveRenderer:
    """A scene rendered one frame at a time into a device-side accumulation."""

    def __init__(self, scene: Scene, *, seed: int = 0, integrator: str = "megakernel", layout: str = "soa",
                 max_depth: int | None = None, width: int | None = None, height: int | None = None,
                 device: Device | str | None = None, precision: str = DEFAULT_PRECISION,
                 max_frame_count: int = 0, overflow: str = "stop", enabled: bool = True,
                 auto_reset: bool = True, wave_size: int | None = None, local_size: int | None = None,
                 schedule: str | None = None, aovs: Sequence[str] | str | bool | None = None,
                 denoiser: str | None = None, denoiser_settings: DenoiserSettings | None = None,
                 camera_path: CameraPath | None = None) -> None:
        seed = check_int(seed, "seed", lo=0, hi=2**32 - 1)
        width = check_optional_int(width, "width", lo=1, hi=MAX_RESOLUTION, note=" (None: the scene's)")
        height = check_optional_int(height, "height", lo=1, hi=MAX_RESOLUTION, note=" (None: the scene's)")
        if (width is None) != (height is None):
            raise ValueError(f"give both width and height or neither, got width={width}, height={height}")
        auto_reset = check_bool(auto_reset, "auto_reset")
        check_options(precision=precision, overflow=overflow, max_frame_count=max_frame_count, enabled=enabled)
        if denoiser is not None and denoiser not in DENOISER_MODES:
            raise ValueError(f"unknown denoiser {denoiser!r}; the denoisers are {', '.join(DENOISER_MODES)}")
        if camera_path is not None and not isinstance(camera_path, CameraPath):
            raise TypeError(f"camera_path must be a pyclpt.CameraPath, got {type(camera_path).__name__}")
        self.scene = scene
        self.seed = int(seed)
        self.auto_reset = bool(auto_reset)
        # the G-buffer: the AOVs asked for, every one when denoising (the denoisers' guides)
        self.aov_names = AOV_NAMES if denoiser else check_aovs(aovs)
        self.denoiser_mode = denoiser
        self._denoiser_settings = denoiser_settings
        self.camera_path = camera_path
        self.frame_index = 0  # frames rendered since this renderer was made: the camera path's time
        self.reprojections = 0  # camera moves the denoiser reprojected across instead of a reset
        self._last_camera: Camera | None = None  # the camera of the last frame rendered
        self._camera_moved = False  # the camera changed since the last frame
        self._max_depth = max_depth
        self._size = (int(width), int(height)) if width is not None else None
        self._renderer_options = dict(integrator=integrator, layout=layout, device=device, wave_size=wave_size,
                                      local_size=local_size, schedule=schedule, precision=precision)
        self._accumulation = dict(max_frame_count=int(max_frame_count), overflow=overflow, enabled=bool(enabled))
        self.sample_index = 0  # the sample index of the next frame
        self.reset_count = 0
        self.resets: Counter[str] = Counter()  # resets by reason (a change kind, or "explicit")
        self.last_reset_reason: str | None = None
        self.stats = RenderStats()
        if camera_path is not None:
            scene.camera = camera_path.camera(0)
        with compile_notice(scene.name):  # one compile message for the renderer's and the denoiser's programs
            self.renderer: Renderer = self._make_renderer()
            self.denoiser: Denoiser | None = self._make_denoiser()
        self._fingerprint = self.fingerprint()

    # -- the device side -------------------------------------------------------------------------
    def _make_renderer(self) -> Renderer:
        w, h = self._size if self._size else (None, None)
        r = Renderer(self.scene, max_depth=self._max_depth, width=w, height=h, aovs=self.aov_names or None,
                     **self._renderer_options)
        r.film.accumulator.configure(**self._accumulation)
        return r

    def _make_denoiser(self) -> Denoiser | None:
        if self.denoiser_mode is None:
            return None
        return Denoiser(self.device, self.width, self.height, mode=self.denoiser_mode,
                        settings=self._denoiser_settings)

    @property
    def device(self) -> Device:
        """The device the frames are rendered on."""
        return self.renderer.device

    @property
    def accumulator(self) -> Accumulator:
        """The film's accumulator: the running average of the frames."""
        return self.renderer.film.accumulator

    @property
    def width(self) -> int:
        """Image width in pixels."""
        return self.renderer.width

    @property
    def height(self) -> int:
        """Image height in pixels."""
        return self.renderer.height

    @property
    def frame_count(self) -> int:
        """Frames in the current average."""
        return self.accumulator.frame_count

    def fingerprint(self) -> dict[str, Hashable]:
        """The scene's state by kind of change (camera, material, geometry, ...), as :meth:`sync` compares it."""
        return scene_fingerprint(self.scene, resolution=self._size, max_depth=self._max_depth)

    def sync(self) -> list[str]:
        """Compare the scene with what the device holds; on a change, rebuild the device side and
        (with auto_reset, or always for a resolution change) reset. Returns the kinds that changed."""
        fp = self.fingerprint()
        changed = [k for k in CHANGE_KINDS if fp[k] != self._fingerprint[k]]
        if not changed:
            return []
        t = time.perf_counter()
        old = self.renderer
        if changed == ["camera"]:  # only the per-resolution constants depend on the camera
            self.scene.camera.validate()  # (a rebuild validates the whole scene)
        else:
            self.renderer = self._make_renderer()  # scene buffers, integrator (its specialisation), film
        if "camera" in changed:  # the next frame's motion vectors point back to the last frame's camera
            self.renderer.scene_buffers.refresh_camera(previous=self._last_camera)
            self._camera_moved = True
        self._fingerprint = fp
        if self.denoiser is not None and "resolution" not in changed:
            # the denoiser carries its history over (reprojection, clipping); only the plain average restarts
            self.renderer.film.clear()
            self.reprojections += "camera" in changed
            log.info("scene change (%s): device side updated in %.3f s, plain average restarted, denoiser "
                     "history kept", ", ".join(changed), time.perf_counter() - t)
            return changed
        keep = not self.auto_reset and "resolution" not in changed
        if keep:  # accumulate on: the old sum continues under the new scene
            self.renderer.film.keep_accumulation(old.film)
        log.info("scene change (%s): device side rebuilt in %.3f s%s", ", ".join(changed),
                 time.perf_counter() - t, "" if keep else ", accumulation reset")
        if "resolution" in changed and self.denoiser is not None:
            self.denoiser = self._make_denoiser()
        if not keep:
            self._restart(",".join(changed))
        return changed

    def _restart(self, reason: str) -> None:
        self.renderer.film.clear()
        self.sample_index = 0
        self.reset_count += 1
        self.resets[reason] += 1
        self.last_reset_reason = reason

    def reset(self) -> None:
        """Start the accumulation over, from sample index 0, and the denoiser's history."""
        self._restart("explicit")
        if self.denoiser is not None:
            self.denoiser.reset()

    # -- setters: change the scene, then sync ------------------------------------------------------
    def set_camera(self, camera: Camera) -> None:
        """Replace the camera, then :meth:`sync`."""
        if not isinstance(camera, Camera):
            raise TypeError(f"set_camera expects a pyclpt.Camera, got {type(camera).__name__}")
        self.scene.camera = camera
        self.sync()

    def set_material(self, index: int, material: Any) -> None:
        """Replace the scene's material ``index`` (negative counts from the end), then :meth:`sync`."""
        n = len(self.scene.materials)
        if not is_int(index) or not -n <= index < n:
            raise IndexError(f"material index {index!r} out of range: the scene has {n} materials")
        check_material(material, f"material {int(index) % n}")
        self.scene.materials[index] = material
        self.sync()

    def _mesh(self, mesh: int | str) -> Mesh:
        meshes = self.scene.meshes
        if isinstance(mesh, str):
            for m in meshes:
                if m.name == mesh:
                    return m
            raise KeyError(f"no mesh named {mesh!r} (meshes: {', '.join(m.name for m in meshes)})")
        if not is_int(mesh):
            raise TypeError(f"mesh must be a mesh index or name, got {type(mesh).__name__} {mesh!r}")
        if not -len(meshes) <= mesh < len(meshes):
            raise IndexError(f"mesh index {mesh} out of range: the scene has {len(meshes)} meshes")
        return meshes[mesh]

    def set_emission(self, mesh: int | str, radiance: object | None) -> None:
        """The area-emitter radiance of a mesh (by index or name); None makes it not emit."""
        m = self._mesh(mesh)
        value = None if radiance is None else rgb(radiance, f"mesh {m.name!r} emission")
        if value is not None and min(value) < 0:
            raise ValueError(f"mesh {m.name!r}: negative emitted radiance {value}")
        m.emission = value
        self.sync()

    def set_environment(self, radiance: object | None) -> None:
        """The constant environment radiance (None: none)."""
        self.scene.environment = None if radiance is None else rgb(radiance, "environment radiance")
        self.sync()

    def set_meshes(self, meshes: Sequence[Mesh]) -> None:
        """Replace the geometry (every mesh's material must exist in the scene)."""
        meshes = list(meshes)
        if not meshes:
            raise ValueError("set_meshes: a scene needs at least one mesh")
        for m in meshes:
            if not 0 <= m.material < len(self.scene.materials):
                raise ValueError(f"mesh {m.name!r} has material {m.material}, but the scene has "
                                 f"{len(self.scene.materials)} materials")
        self.scene.meshes = meshes
        self.sync()

    def set_resolution(self, width: int, height: int) -> None:
        """Render at ``width`` x ``height`` pixels from now on (the accumulation restarts)."""
        width = check_int(width, "width", lo=1, hi=MAX_RESOLUTION)
        height = check_int(height, "height", lo=1, hi=MAX_RESOLUTION)
        self._size = (width, height)
        self.sync()

    # -- rendering -------------------------------------------------------------------------------
    def step(self, frames: int = 1) -> int:
        """Render ``frames`` frames (fewer once overflow='stop' has reached max_frame_count).
        The scene is checked for changes once, before the first: nothing can change it between
        the frames of one call. Returns the number of frames rendered."""
        frames = check_int(frames, "frames", lo=0)
        self.sync()
        done = 0
        while done < int(frames) and self._frame():
            done += 1
            self.renderer.pacer.frame(self.device.queue)
        if done < int(frames):
            self.accumulator.ignored_frames += int(frames) - done
        return done

    def _frame(self) -> bool:
        """Render and accumulate the next sample index (the camera path's camera first), denoise it;
        False once the accumulator has stopped."""
        if self.accumulator.stopped and self.denoiser is None:
            return False
        if self.sample_index >= 2**32:
            raise OverflowError(f"sample index {self.sample_index} does not fit the 32-bit counter; reset()")
        if self.camera_path is not None:
            self.scene.camera = self.camera_path.camera(self.frame_index)
            self.sync()
        buffers, film = self.renderer.scene_buffers, self.renderer.film
        if not self._camera_moved and buffers.previous_camera is not None:
            buffers.refresh_camera(previous=None)  # the camera stood still since the last frame: no motion
        self._camera_moved = False
        if film.aov is not None and self.denoiser_mode in ("svgf", "blend"):
            film.aov.restart()  # the G-buffer of this frame alone: the real-time denoisers' guides
        self.renderer.integrator.render_frame(self.seed, self.sample_index)
        film.add_frame(self.seed, self.sample_index)
        if self.denoiser is not None:
            if self.denoiser_mode == "oidn":  # the offline anchor: the plain average and its averaged guides
                guides = self.renderer.aovs(["albedo", "normal"])  # (a splatting film: its own samples' average)
                self.denoiser.denoise(film.denoiser_image(), albedo=guides["albedo"], normal=guides["normal"])
            else:
                self.denoiser.denoise_buffers(film.denoiser_frame(), film.aov.mean)
        self._last_camera = dataclasses.replace(self.scene.camera, to_world=np.array(self.scene.camera.to_world))
        self.sample_index += 1
        self.frame_index += 1
        return True

    def image(self) -> np.ndarray:
        """The current plain average, (H, W, 3) float32."""
        return self.renderer.film.image()

    def frame_image(self) -> np.ndarray:
        """The last frame's own samples (one per pixel), (H, W, 3) float32: the real-time denoisers' input
        (a splatting film's before its gather: :meth:`Film.denoiser_frame <pyclpt.film.film.Film.denoiser_frame>`)."""
        return self.renderer.film.read_own_frame(0)

    def denoised(self) -> np.ndarray:
        """The denoiser's output for the last frame, (H, W, 3) float32."""
        if self.denoiser is None:
            raise ValueError("no denoiser: make the ProgressiveRenderer with denoiser='svgf' (or 'blend', 'oidn')")
        if self.frame_index == 0:
            raise ValueError("no frame rendered yet: step() first")
        return self.denoiser.image()

    def aovs(self, names: Sequence[str] | None = None) -> dict[str, np.ndarray]:
        """The G-buffer by name (:meth:`Renderer.aovs`): averaged over the frames of the plain average, as
        its image; with the ``svgf`` or ``blend`` denoiser, the last frame's (their guides)."""
        return self.renderer.aovs(names)

    def run(self, frames: int, progress: bool | None = None,
            on_frame: Callable[[int], None] | None = None) -> np.ndarray:
        """Render ``frames`` frames and return the image (the denoised last frame with a denoiser, else
        the plain average); ``stats`` describes the run. ``on_frame(k)`` is called after the k-th frame
        of the run (0-based), e.g. to write every frame of a sequence.
        ``progress``: True shows a bar once the run has lasted a couple of seconds; None or False show
        none. Ctrl-C raises KeyboardInterrupt within about a second and returns no image (the
        accumulation then holds part of the run; :meth:`reset` starts over)."""
        frames = check_int(frames, "frames", lo=1)
        progress = check_optional_bool(progress, "progress")
        self.sync()  # once: the scene cannot change during the run
        r = self.renderer
        r.integrator.profile.clear()
        if hasattr(r.integrator, "reset_stats"):
            r.integrator.reset_stats()
        start = time.perf_counter()
        done = 0
        with progress_bar(frames, f"{self.scene.name} {r.integrator.name}", "frame", progress) as bar:
            for _ in range(int(frames)):
                if not self._frame():
                    self.accumulator.ignored_frames += int(frames) - done
                    break
                if on_frame is not None:
                    on_frame(done)
                done += 1
                bar.update(self.renderer.pacer.frame(self.device.queue))
        image = self.denoised() if self.denoiser is not None and done else self.image()
        self.stats = self.renderer.collect_stats(self.frame_count, time.perf_counter() - start)
        if self.denoiser is not None:
            self.stats.denoise = self.denoiser.profile.table()
        return image
