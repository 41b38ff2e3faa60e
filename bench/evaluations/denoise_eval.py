"""The denoising evaluation: plain accumulation, the fixed blend, SVGF and Intel Open Image Denoise
against converged references, on a static and an orbiting camera; flicker, lag after a change, and
the denoiser's cost at 1280x720. See docs/denoising-eval.md.

    python -m bench.evaluations.denoise_eval --scenes cornell-box cornell-bunny living-room --frames 16 \\
        --out docs/denoising --device intel [--size auto|WxH] [--modes none blend svgf oidn]
    python -m bench.evaluations.denoise_eval --from-json docs/denoising/results.json   # rewrite the report only

Every frame is rendered at 1 sample per pixel by ``pyclpt.ProgressiveRenderer`` (the megakernel);
the modes are

- ``none``: the plain average of the frames since the last reset (a camera move or a light change
  resets it);
- ``blend``, ``svgf``: ``ProgressiveRenderer(denoiser=...)``'s output for the frame;
- ``oidn``: Intel Open Image Denoise (pyclpt/denoise/oidn.py) on the plain average of the same frames
  (the ``none`` run's) with the albedo and normal AOVs averaged over those frames as guides.

Per scene, at the quality size (``--size``; ``auto``: about 160x90 pixels at the scene's aspect ratio),
against references of ``--ref-spp`` samples per pixel (bench/evaluations/denoise_references.py, cached):

1. static: ``--frames`` frames from the scene's camera; relMSE, SSIM and FLIP per frame
   (bench/evaluations/denoise_metrics.py) and the temporal instability mean |D_t - D_{t-1}|;
2. light change: after the static frames every emitter is scaled by ``--light-scale`` (0: off) and
   ``--after`` more frames are rendered; the error in the changed region (where the reference changes)
   is compared frame by frame with a fresh run of the changed scene (the same mode with no history,
   frames since its start = frames since the change); the lag is the frames until the error is under
   ``--lag-factor`` times that baseline (plus ``--lag-floor``). The changed scene's reference is the
   static one times the scale (light transport is linear in the emission), so it costs no render;
3. orbit: the camera turns ``--orbit-degrees`` about the scene's centre over ``--frames`` frames
   (``pyclpt.scene.camera_path.CameraPath.orbit``), then holds still for ``--after`` frames; relMSE,
   SSIM and FLIP at every ``--orbit-ref-every``-th frame and the last moving one (a reference each);
   the lag in the region disoccluded during the last ``--disocclusion-frames`` moves (from the mesh-id
   and motion AOVs), against a fresh static run from the final camera, as in 2.

Then, at ``--timing-size`` (1280x720), per scene of ``--timing-scenes``: ``--timing-frames`` frames per
mode after ``--timing-warmup``; the wall time of a frame, the render kernels' and each denoiser pass's
device time per frame (OpenCL profiling events), OIDN's host time per call; the denoiser's share of a
1-spp frame.

Writes ``results.json`` (every figure and setting, the machine), ``report.md`` (the tables), and PNGs:
``<scene>_static.png`` / ``<scene>_orbit.png`` (side by side: noisy 1 spp, plain accumulation, blend,
svgf, oidn, reference), ``<scene>_curves.png`` (error against frame, lag). Timings are never checked by
the tests; they depend on the machine (the report names its CPU) and on what else runs on it.
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import math
import shlex
import statistics
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..report.options import positive as _positive
from ..report.options import size_type
from . import denoise_metrics as M

FORMAT = 1
MODES = ("none", "blend", "svgf", "oidn")
# Which ProgressiveRenderer run gives which mode's output: oidn filters the plain run's average.
RUN_OF = {"none": "none", "oidn": "none", "blend": "blend", "svgf": "svgf"}
AUTO_PIXELS = 160 * 90
DEFAULTS = {
    "scenes": ["cornell-box", "cornell-bunny", "living-room"],
    "modes": list(MODES),
    "frames": 16,
    "image_frame": 8,
    "size": "auto",
    "ref_spp": 4096,
    "seed": 0,
    "light_scale": 0.25,
    "after": 8,
    "orbit_degrees": 12.0,
    "orbit_ref_every": 8,
    "disocclusion_frames": 3,
    "lag_factor": 1.5,
    "lag_floor": 1e-4,
    "flip": "ldr",
    "exposure": 0.0,
    "timing_size": "1280x720",
    "timing_frames": 7,
    "timing_warmup": 2,
    "timing_scenes": None,  # None: the quality scenes
    "oidn_quality": "high",
}
QUICK = {"scenes": ["cornell-box"], "frames": 8, "image_frame": 4, "size": "64x64", "ref_spp": 256, "after": 4,
         "orbit_ref_every": 4, "timing_size": "320x180", "timing_frames": 2, "timing_warmup": 1}
# The denoiser issue's goals: svgf's relMSE at frame --image-frame over the plain average's (per scene),
# its FLIP over OIDN's (the Cornell box), the lag after a change, the cost share of a 1-spp frame.
GOALS = {"relmse_ratio": 0.25, "flip_vs_oidn": 1.3, "lag_frames": 4, "cost_share": 0.25}
RELMSE_GOALS = {"cornell-box": 0.25, "cornell-bunny": 0.25, "shared/living-room": 0.35}
FLIP_GOAL_SCENES = ("cornell-box",)


# -- command line ------------------------------------------------------------------------------
_size = size_type("auto", minimum=8)


def _exposure(text: str) -> str | float:
    if text == "auto":
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected stops (a number) or 'auto', got {text!r}") from None


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m bench.evaluations.denoise_eval", description=__doc__.splitlines()[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="Defaults: " + ", ".join(f"{k}={v}" for k, v in DEFAULTS.items()) +
                                "; --quick: " + ", ".join(f"{k}={v}" for k, v in QUICK.items()))
    p.add_argument("-o", "--out", default=None, help="output folder (default denoise-eval, or --from-json's folder)")
    p.add_argument("--quick", action="store_true", help="a small smoke run (cornell-box, 64x64, 256-spp reference)")
    p.add_argument("--scenes", nargs="+", default=None,
                   help="built-in scene names, shared scene folders (living-room) or scene files")
    p.add_argument("--modes", nargs="+", choices=MODES, default=None)
    p.add_argument("--frames", type=_positive, default=None, help="frames of the static and orbit sequences")
    p.add_argument("--image-frame", type=_positive, default=None,
                   help="the static frame of the side-by-side images and the goal table (1-based)")
    p.add_argument("--size", type=_size, default=None,
                   help="WIDTHxHEIGHT of the quality runs, or auto (about 160x90 pixels at each scene's aspect)")
    p.add_argument("--ref-spp", type=_positive, default=None, help="samples per pixel of the references")
    p.add_argument("--reference-cache", default=None,
                   help="reference folder (default $PYCLPT_CACHE_DIR/denoise-references, else in the platform's "
                        "cache folder: ~/.cache/pyclpt/... on Linux); "
                        "'none': no cache")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--device", default=None, help="OpenCL device: intel, pocl, P:D or a name substring "
                   "(default: Intel's CPU runtime if installed, else PoCL)")
    p.add_argument("--light-scale", type=float, default=None, help="emitter scale of the light change (0: off)")
    p.add_argument("--after", type=_positive, default=None, help="frames after a change (light, camera stop)")
    p.add_argument("--orbit-degrees", type=float, default=None)
    p.add_argument("--orbit-ref-every", type=_positive, default=None,
                   help="orbit frames with a reference: every Nth and the last moving one")
    p.add_argument("--disocclusion-frames", type=_positive, default=None,
                   help="the orbit lag's region: pixels disoccluded by the last N moves")
    p.add_argument("--lag-factor", type=float, default=None)
    p.add_argument("--lag-floor", type=float, default=None)
    p.add_argument("--flip", choices=M.FLIP_MODES, default=None, help="LDR-FLIP on the tonemapped images, "
                   "or HDR-FLIP on the linear ones")
    p.add_argument("--exposure", type=_exposure, default=None,
                   help="stops before the tonemap of SSIM/FLIP/images (default 0: the scene as authored), "
                        "or auto (each reference's median to middle grey)")
    p.add_argument("--timing-size", type=_size, default=None)
    p.add_argument("--timing-frames", type=_positive, default=None)
    p.add_argument("--timing-warmup", type=int, default=None)
    p.add_argument("--timing-scenes", nargs="*", default=None, help="(default: --scenes; none: no timing)")
    p.add_argument("--no-timing", action="store_true")
    p.add_argument("--no-quality", action="store_true", help="timing only")
    p.add_argument("--oidn-quality", choices=("high", "balanced", "fast"), default=None)
    p.add_argument("--from-json", default=None, metavar="RESULTS",
                   help="rewrite report.md and the plots from a saved results.json (no rendering; the "
                        "side-by-side images are redrawn only where their .npz are found, see --arrays)")
    p.add_argument("--arrays", default=None, help="folder of the side-by-side figures' images (.npz; "
                   "default OUT/arrays)")
    p.add_argument("--no-progress", action="store_true")
    return p


def settings_from(a: argparse.Namespace) -> dict:
    s = dict(DEFAULTS)
    if a.quick:
        s.update(QUICK)
    for key in DEFAULTS:
        v = getattr(a, key, None)
        if v is not None:
            s[key] = v
    if a.no_timing:
        s["timing_scenes"] = []
    if s["timing_scenes"] is None:
        s["timing_scenes"] = list(s["scenes"])
    s["quality"] = not a.no_quality
    s["device"] = a.device
    s["reference_cache"] = a.reference_cache
    s["arrays"] = a.arrays
    s["quick"] = bool(a.quick)
    s["modes"] = [m for m in MODES if m in s["modes"]]
    if not 0 <= s["light_scale"]:
        raise ValueError(f"--light-scale must be >= 0, got {s['light_scale']}")
    if s["image_frame"] > s["frames"]:
        raise ValueError(f"--image-frame {s['image_frame']} is past the last frame (--frames {s['frames']})")
    return s


# -- scenes ---------------------------------------------------------------------------------------
def quality_size(scene: Any, size: str) -> tuple[int, int]:
    """``WxH``, or for ``auto`` about AUTO_PIXELS pixels at the scene film's aspect ratio (even sides)."""
    if size != "auto":
        w, h = (int(x) for x in size.split("x"))
        return w, h
    aspect = scene.film.width / scene.film.height
    h = math.sqrt(AUTO_PIXELS / aspect)
    w = h * aspect
    return max(8, 2 * round(w / 2)), max(8, 2 * round(h / 2))


def clone_scene(scene: Any) -> Any:
    """A copy whose camera, emitters and lights can change without touching ``scene`` (meshes are
    copied shallowly: their arrays are shared)."""
    out = copy.copy(scene)
    out.meshes = [copy.copy(m) for m in scene.meshes]
    out.lights = [copy.copy(light) for light in scene.lights]
    return out


def _scale_rgb(value: Any, s: float) -> tuple[float, float, float] | None:
    if value is None or s == 0:
        return None
    return tuple(float(c) * s for c in value)


def scale_emitters(scene: Any, s: float, pr: Any = None) -> int:
    """Scale every emitter of ``scene`` by ``s`` (0: off): area emitters, the environment, point lights.
    With ``pr`` (a ProgressiveRenderer of this scene) area emitters change through its
    ``set_emission`` and the rest is picked up by its next frame. Returns the emitters changed."""
    n = 0
    for i, m in enumerate(scene.meshes):
        if m.emission is None:
            continue
        n += 1
        value = _scale_rgb(m.emission, s)
        if pr is not None:
            pr.set_emission(i, value)
        else:
            m.emission = value
    env = scene.environment
    if env is not None:
        n += 1
        if hasattr(env, "scale") and dataclasses.is_dataclass(env):
            scene.environment = dataclasses.replace(env, scale=float(env.scale) * s) if s > 0 else None
        else:
            scene.environment = _scale_rgb(env, s)
    if scene.lights:
        n += len(scene.lights)
        scene.lights = [dataclasses.replace(lt, intensity=tuple(float(c) * s for c in lt.intensity))
                        for lt in scene.lights if s > 0]
    if pr is not None and hasattr(pr, "sync"):
        pr.sync()
    return n


MIDDLE_GREY = 0.18


def auto_exposure(reference: np.ndarray) -> float:
    """``--exposure auto``: the stops that bring the reference's median luminance to middle grey (0.18),
    as a camera's auto-exposure would; 0 for a black reference."""
    lum = M.luminance(reference)
    lum = lum[np.isfinite(lum)]
    med = float(np.median(lum)) if lum.size else 0.0
    return math.log2(MIDDLE_GREY / med) if med > 0 else 0.0


def camera_path_class() -> Any:
    import pyclpt

    cls = getattr(pyclpt, "CameraPath", None)
    if cls is None:
        from pyclpt.scene.camera_path import CameraPath as cls  # noqa: N813
    return cls


def orbit_path(scene: Any, degrees: float, frames: int) -> Any:
    return camera_path_class().orbit(scene, degrees, frames)


# -- one renderer run of a mode -------------------------------------------------------------------
def default_factory(scene: Any, **kwargs: Any) -> Any:
    import pyclpt

    return pyclpt.ProgressiveRenderer(scene, **kwargs)


class ModeRun:
    """A ProgressiveRenderer for one run (``none``, ``blend`` or ``svgf``) and the outputs of the modes it
    serves (``none`` also serves ``oidn``)."""

    def __init__(self, scene: Any, run: str, modes: list[str], width: int, height: int, *, device: Any, seed: int,
                 factory: Callable[..., Any], oidn: Any = None, camera_path: Any = None,
                 aovs: list[str] | None = None) -> None:
        self.run, self.modes = run, modes
        kwargs: dict[str, Any] = dict(seed=seed, width=width, height=height, device=device, integrator="megakernel")
        if run != "none":
            kwargs["denoiser"] = run
        else:
            wanted = list(aovs or [])
            if "oidn" in modes:
                wanted += ["albedo", "normal"]
            if wanted:
                kwargs["aovs"] = list(dict.fromkeys(wanted))
        if camera_path is not None:
            kwargs["camera_path"] = camera_path
        self.pr = factory(scene, **kwargs)
        self.oidn = oidn
        self.frames = 0

    def step(self) -> None:
        self.pr.step()
        self.frames += 1

    def noisy(self) -> np.ndarray:
        return self.pr.frame_image()

    def aovs(self, names: list[str]) -> dict[str, np.ndarray]:
        return self.pr.aovs(names)

    def outputs(self) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        for mode in self.modes:
            if mode == "none":
                out[mode] = self.pr.image()
            elif mode == "oidn":
                plain = out["none"] if "none" in out else self.pr.image()
                guides = self.pr.aovs(["albedo", "normal"])
                out[mode] = self.oidn.run_numpy(plain, guides["albedo"], guides["normal"])
            else:
                out[mode] = self.pr.denoised()
        return out


def runs_for(modes: list[str]) -> dict[str, list[str]]:
    runs: dict[str, list[str]] = {}
    for m in modes:
        runs.setdefault(RUN_OF[m], []).append(m)
    return runs


# -- the quality part of one scene ----------------------------------------------------------------
class Metrics:
    def __init__(self, exposure: float, flip_mode: str) -> None:
        self.exposure, self.flip_mode = exposure, flip_mode

    def all(self, x: np.ndarray, ref: np.ndarray) -> dict[str, float]:
        return {"relmse": M.relmse(x, ref), "ssim": M.ssim(x, ref, exposure=self.exposure),
                "flip": M.flip(x, ref, mode=self.flip_mode, exposure=self.exposure)}


def _series() -> dict[str, list]:
    return {"relmse": [], "ssim": [], "flip": []}


def _lag(errors: list[float], baseline: list[float], factor: float, floor: float) -> dict:
    thr = [factor * b + floor for b in baseline]
    return {"frames": M.lag_frames(errors, thr), "threshold": thr}


def add_lags(rec: dict, s: dict) -> None:
    """``lag`` and ``recovery`` of a light-change or orbit record, from its region error series.
    lag: frames until the region's error <= lag_factor x the fresh run's at the same age + lag_floor
    (what history from before the change costs beyond a reset); recovery: frames until it is
    <= lag_factor x the fresh run's error at its last frame + lag_floor (back to the quality a run of
    that many frames reaches; for a method without history this is the noise of a young average)."""
    f, floor = s["lag_factor"], s["lag_floor"]
    rec["lag"], rec["recovery"] = {}, {}
    for m, errs in rec.get("region", {}).items():
        base = rec.get("baseline", {}).get(m) or []
        if not errs or not base:
            continue
        rec["lag"][m] = _lag(errs, base, f, floor)["frames"]
        rec["recovery"][m] = M.lag_frames(errs, f * base[-1] + floor)


def evaluate_scene(entry: Any, s: dict, device: Any, out: Path, *, factory: Callable[..., Any] = default_factory,
                   references: Callable[..., Any] | None = None, log: Callable[[str], None] = print) -> dict:
    """The static, light-change and orbit sequences of one scene (see the module docstring)."""
    from . import denoise_references as R

    scene = entry.scene
    w, h = quality_size(scene, s["size"])
    rec: dict[str, Any] = {"scene": entry.label, "source": entry.source, "width": w, "height": h,
                           "triangles": int(getattr(scene, "triangle_count", 0)), "errors": {}}
    cache = s.get("reference_cache")
    folder = False if cache == "none" else cache
    make_refs = references or (lambda sc, label: R.ReferenceRenderer(sc, label, w, h, s["ref_spp"], device=device,
                                                                       folder=folder))
    refs = make_refs(clone_scene(scene), entry.label)
    t0 = time.perf_counter()
    log(f"{entry.label}: reference ({w}x{h}, {s['ref_spp']} spp)")
    ref_static = refs.render()
    exposure = auto_exposure(ref_static) if s["exposure"] == "auto" else float(s["exposure"])
    rec["exposure"] = exposure
    metrics = Metrics(exposure, s["flip"])
    modes = s["modes"]
    oidn = None
    if "oidn" in modes:
        from pyclpt.denoise.oidn import Oidn

        oidn = Oidn(w, h, quality=s["oidn_quality"])
    N, A, k_img = s["frames"], s["after"], s["image_frame"]
    lscale = float(s["light_scale"])

    def new_run(run: str, sc: Any, **kw: Any) -> ModeRun:
        return ModeRun(sc, run, runs_for(modes)[run], w, h, device=device, seed=s["seed"], factory=factory,
                       oidn=oidn, **kw)

    # 1. static, then 2. the light change on the same renderers
    static = {m: _series() for m in modes}
    instability = {m: [] for m in modes}
    light_ref = ref_static * np.float32(lscale)
    light_mask = M.change_mask(ref_static, light_ref)
    light = {"scale": lscale, "after_static_frames": N, "region_pixels": int(light_mask.sum()),
             "region": {m: [] for m in modes}, "whole": {m: [] for m in modes}, "baseline": {m: [] for m in modes}}
    images: dict[str, np.ndarray] = {"reference": ref_static}
    emitters = 0
    for run, served in runs_for(modes).items():
        try:
            sc = clone_scene(scene)
            mr = new_run(run, sc)
            prev: dict[str, np.ndarray] = {}
            for k in range(1, N + 1):
                mr.step()
                outs = mr.outputs()
                for m, img in outs.items():
                    for key, v in metrics.all(img, ref_static).items():
                        static[m][key].append(v)
                    tm = M.tonemap(img, exposure)
                    if m in prev:
                        instability[m].append(float(np.mean(np.abs(tm.astype(np.float64) - prev[m]))))
                    prev[m] = tm.astype(np.float64)
                    if k == k_img:
                        images[m] = img
                if k == k_img and "noisy" not in images:
                    images["noisy"] = mr.noisy()
            emitters = scale_emitters(sc, lscale, mr.pr)
            for _ in range(A):
                mr.step()
                for m, img in mr.outputs().items():
                    light["region"][m].append(M.relmse(img, light_ref, mask=light_mask))
                    light["whole"][m].append(M.relmse(img, light_ref))
            del mr
            sc = clone_scene(scene)
            scale_emitters(sc, lscale)
            base = new_run(run, sc)
            for _ in range(A):
                base.step()
                for m, img in base.outputs().items():
                    light["baseline"][m].append(M.relmse(img, light_ref, mask=light_mask))
            del base
        except Exception as exc:  # noqa: BLE001 - a mode that fails is recorded, the others go on
            for m in served:
                rec["errors"][m] = f"{type(exc).__name__}: {exc}"
            log(f"{entry.label}: run {run} failed: {type(exc).__name__}: {exc}")
            traceback.print_exc()
    light["emitters"] = emitters
    add_lags(light, s)
    rec["static"] = {"frames": list(range(1, N + 1)), "metrics": static, "instability": instability,
                     "mean_instability": {m: (statistics.fmean(v) if v else None) for m, v in instability.items()}}
    rec["light"] = light
    save_arrays(arrays_folder(s, out) / f"{_file(entry.label)}_static.npz", images)

    # 3. orbit, then hold still
    orbit_rec = evaluate_orbit(entry, s, scene, refs, metrics, new_run, out, rec["errors"], log)
    rec["orbit"] = orbit_rec
    rec["references"] = {"spp": s["ref_spp"], "hits": getattr(refs, "hits", None),
                         "misses": getattr(refs, "misses", None), "render_seconds": getattr(refs, "seconds", None),
                         "files": getattr(refs, "files", [])}
    if hasattr(refs, "release"):
        refs.release()
    rec["seconds"] = time.perf_counter() - t0
    if oidn is not None:
        rec["oidn"] = oidn.stats()
        oidn.close()
    return rec


def evaluate_orbit(entry: Any, s: dict, scene: Any, refs: Any, metrics: Metrics, new_run: Callable[..., ModeRun],
                   out: Path, errors: dict, log: Callable[[str], None]) -> dict:
    modes = s["modes"]
    N, A = s["frames"], s["after"]
    path = orbit_path(scene, s["orbit_degrees"], N)
    every = s["orbit_ref_every"]
    ref_frames = sorted({k for k in range(N) if (k + 1) % every == 0} | {N - 1})  # 0-based frame indices
    log(f"{entry.label}: orbit references at frames {[k + 1 for k in ref_frames]}")
    orbit_refs = {k: refs.render(path.camera(k)) for k in ref_frames}
    final_ref = orbit_refs[N - 1]
    series = {m: _series() for m in modes}
    rec: dict[str, Any] = {"degrees": s["orbit_degrees"], "frames": N, "ref_frames": [k + 1 for k in ref_frames],
                           "metrics": series, "region": {m: [] for m in modes}, "whole": {m: [] for m in modes},
                           "baseline": {m: [] for m in modes}}
    images: dict[str, np.ndarray] = {"reference": final_ref}
    D = s["disocclusion_frames"]
    region: np.ndarray | None = None
    history: list[dict[str, np.ndarray]] = []
    for run, served in runs_for(modes).items():
        try:
            if region is None:
                history = []
            sc = clone_scene(scene)
            mr = new_run(run, sc, camera_path=path, aovs=["mesh_id", "motion"])
            for k in range(N + A):
                mr.step()
                if region is None and N - 1 - D <= k <= N - 1:
                    history.append(mr.aovs(["mesh_id", "motion"]))
                    if k == N - 1:
                        region = _disoccluded(history, D)
                        log(f"{entry.label}: orbit region {int(region.sum())} pixels disoccluded in the last {D} moves")
                outs = mr.outputs()
                if k in orbit_refs:
                    for m, img in outs.items():
                        for key, v in metrics.all(img, orbit_refs[k]).items():
                            series[m][key].append(v)
                if k == N - 1:
                    images.update(outs)
                    images.setdefault("noisy", mr.noisy())
                if k >= N - 1:
                    for m, img in outs.items():
                        rec["region"][m].append(M.relmse(img, final_ref, mask=region))
                        rec["whole"][m].append(M.relmse(img, final_ref))
            del mr
            sc = clone_scene(scene)
            sc.camera = path.camera(N - 1)
            base = new_run(run, sc)
            for _ in range(A + 1):
                base.step()
                for m, img in base.outputs().items():
                    rec["baseline"][m].append(M.relmse(img, final_ref, mask=region))
            del base
        except Exception as exc:  # noqa: BLE001
            for m in served:
                errors[m] = f"{type(exc).__name__}: {exc}"
            log(f"{entry.label}: orbit run {run} failed: {type(exc).__name__}: {exc}")
            traceback.print_exc()
    rec["region_pixels"] = int(region.sum()) if region is not None else None
    add_lags(rec, s)
    images["region"] = region if region is not None else np.zeros(final_ref.shape[:2], bool)
    save_arrays(arrays_folder(s, out) / f"{_file(entry.label)}_orbit.npz", images)
    return rec


def arrays_folder(s: dict, out: Path, create: bool = True) -> Path:
    """Where the images of the side-by-side figures are kept (``--arrays``; default OUT/arrays)."""
    folder = Path(s["arrays"]) if s.get("arrays") else out / "arrays"
    if create:
        folder.mkdir(parents=True, exist_ok=True)
    return folder


def save_arrays(path: Path, images: dict[str, np.ndarray]) -> None:
    np.savez_compressed(path, **{k: (v if v.dtype == bool else v.astype(np.float32)) for k, v in images.items()})


def _disoccluded(history: list[dict[str, np.ndarray]], moves: int) -> np.ndarray:
    """Pixels disoccluded by the last ``moves`` camera moves (each frame's mesh ids against the
    frame before, along its motion vectors), dilated by one pixel. Mesh ids, not triangle ids: the
    two triangles of a wall are one surface."""
    h, w = history[-1]["mesh_id"].shape
    mask = np.zeros((h, w), bool)
    for prev, cur in list(zip(history, history[1:]))[-moves:]:
        mask |= M.disocclusion_mask(prev["mesh_id"], cur["mesh_id"], cur["motion"])
    grown = mask.copy()
    grown[1:] |= mask[:-1]
    grown[:-1] |= mask[1:]
    grown[:, 1:] |= mask[:, :-1]
    grown[:, :-1] |= mask[:, 1:]
    return grown


def _file(label: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in label.removeprefix("shared/"))


# -- timing at 1280x720 ---------------------------------------------------------------------------
def _profile_ms(profile: Any) -> dict[str, float]:
    """Device ms per kernel name of a profile since its last clear (OpenCL profiling events)."""
    if profile is None:
        return {}
    return {str(r.get("kernel", r.get("name"))): float(r["total_ms"]) for r in profile.table()}


def _summary(values: list[float]) -> dict:
    return {"median": statistics.median(values), "min": min(values), "max": max(values), "frames": values}


def time_scene(entry: Any, s: dict, device: Any, *, factory: Callable[..., Any] = default_factory,
               log: Callable[[str], None] = print) -> dict:
    """Frames at the timing size with each run (``none``, ``blend``, ``svgf``), round-robin (frame i of
    every run, the order rotating each round, as bench/runner.py does: a change in the machine's load
    hits every mode alike) after the warm-up frames. Per frame: the wall time of ``step`` (queue
    finished), the render kernels' and each denoiser pass's device time; medians over the frames.
    Then OIDN's host time per call on the plain run's last frame with its guides."""
    w, h = (int(x) for x in s["timing_size"].split("x"))
    from ..report.machine import load_average

    rec: dict[str, Any] = {"scene": entry.label, "width": w, "height": h, "frames": s["timing_frames"],
                           "warmup": s["timing_warmup"], "modes": {}, "errors": {},
                           "load_average_start": load_average()}
    runs = [r for r in ("none", "blend", "svgf") if r in {RUN_OF[m] for m in s["modes"]}]
    if "none" not in runs:
        runs.insert(0, "none")  # the 1-spp frame without a denoiser: the denominator
    prs: dict[str, Any] = {}
    for run in runs:
        log(f"{entry.label}: timing {run} at {w}x{h}")
        try:
            kwargs: dict[str, Any] = dict(seed=s["seed"], width=w, height=h, device=device, integrator="megakernel")
            if run != "none":
                kwargs["denoiser"] = run
            pr = factory(clone_scene(entry.scene), **kwargs)
            for _ in range(s["timing_warmup"]):
                pr.step()
            device.queue.finish()
            prs[run] = pr
        except Exception as exc:  # noqa: BLE001
            rec["errors"][run] = f"{type(exc).__name__}: {exc}"
            log(f"{entry.label}: timing {run} failed: {type(exc).__name__}: {exc}")
            traceback.print_exc()
    wall: dict[str, list[float]] = {r: [] for r in prs}
    render: dict[str, list[float]] = {r: [] for r in prs}
    denoise: dict[str, list[float]] = {r: [] for r in prs}
    passes: dict[str, dict[str, list[float]]] = {r: {} for r in prs}
    kernels: dict[str, dict[str, list[float]]] = {r: {} for r in prs}
    order = list(prs)
    for i in range(s["timing_frames"]):
        k = i % max(len(order), 1)
        for run in order[k:] + order[:k]:
            if run in rec["errors"]:
                continue
            pr = prs[run]
            try:
                integ = pr.renderer.integrator.profile
                den = getattr(getattr(pr, "denoiser", None), "profile", None)
                integ.clear()
                if den is not None:
                    den.clear()
                t = time.perf_counter()
                pr.step()
                device.queue.finish()
                wall[run].append(1e3 * (time.perf_counter() - t))
                rk, dk = _profile_ms(integ), _profile_ms(den)
                render[run].append(sum(rk.values()))
                denoise[run].append(sum(dk.values()))
                for name, ms in dk.items():
                    passes[run].setdefault(name, []).append(ms)
                for name, ms in rk.items():
                    kernels[run].setdefault(name, []).append(ms)
            except Exception as exc:  # noqa: BLE001
                rec["errors"][run] = f"{type(exc).__name__}: {exc}"
                log(f"{entry.label}: timing {run} failed: {type(exc).__name__}: {exc}")
    for run in order:
        if run in rec["errors"] or not wall[run]:
            continue
        rec["modes"][run] = {
            "wall_ms": _summary(wall[run]), "render_ms": statistics.median(render[run]),
            "render_kernels": [{"kernel": n, "ms_per_frame": statistics.median(v)} for n, v in kernels[run].items()],
            "denoise_ms": statistics.median(denoise[run]) if run != "none" else 0.0,
            "denoise_frames_ms": denoise[run],
            "passes": [{"kernel": n, "ms_per_frame": statistics.median(v)} for n, v in passes[run].items()]}
    plain = prs.get("none")
    if "oidn" in s["modes"] and plain is not None and "none" not in rec["errors"]:
        try:
            from pyclpt.denoise.oidn import Oidn

            color = plain.image()
            donor = next((prs[r] for r in ("svgf", "blend") if r in prs), None)  # the plain run records no AOVs
            if donor is None:
                donor = factory(clone_scene(entry.scene), seed=s["seed"], width=w, height=h, device=device,
                                integrator="megakernel", aovs=["albedo", "normal"])
                donor.step()
            guides = donor.aovs(["albedo", "normal"])  # timing only: any frame's guides will do
            with Oidn(w, h, quality=s["oidn_quality"]) as oidn:
                oidn.run_numpy(color, guides["albedo"], guides["normal"])  # the first call commits the filter
                times = []
                for _ in range(s["timing_frames"]):
                    t = time.perf_counter()
                    oidn.run_numpy(color, guides["albedo"], guides["normal"])
                    times.append(1e3 * (time.perf_counter() - t))
            rec["modes"]["oidn"] = {"wall_ms": _summary(times), "denoise_ms": statistics.median(times), "host": True,
                                    "passes": []}
        except Exception as exc:  # noqa: BLE001
            rec["errors"]["oidn"] = f"{type(exc).__name__}: {exc}"
            log(f"{entry.label}: timing oidn failed: {type(exc).__name__}: {exc}")
    prs.clear()
    rec["load_average_end"] = load_average()
    base = rec["modes"].get("none")
    if base:
        for run, r in rec["modes"].items():
            if run == "none":
                continue
            r["share_of_render"] = r["denoise_ms"] / base["render_ms"] if base["render_ms"] > 0 else None
            r["share_of_frame_wall"] = r["denoise_ms"] / base["wall_ms"]["median"]
            if "render_ms" in r:
                r["gbuffer_render_overhead"] = r["render_ms"] / base["render_ms"] - 1.0 if base["render_ms"] else None
    return rec


# -- running --------------------------------------------------------------------------------------
def missing_packages(modes: list[str]) -> list[str]:
    """The optional packages this run needs that do not import: scikit-image and flip-evaluator (the
    metrics), pyoidn (mode oidn)."""
    import importlib

    wanted = {"skimage.metrics": "scikit-image", "flip_evaluator": "flip-evaluator"}
    if "oidn" in modes:
        wanted["pyoidn"] = "pyoidn"
    missing = []
    for module, package in wanted.items():
        try:
            importlib.import_module(module)
        except ImportError:
            missing.append(package)
    return missing


def open_device(name: str | None) -> Any:
    import pyclpt

    if name:
        return pyclpt.get_device(name)
    try:
        return pyclpt.get_device("intel")
    except Exception:  # noqa: BLE001 - Intel's runtime is optional
        return pyclpt.get_device(None)


def run(s: dict, out: Path, *, factory: Callable[..., Any] = default_factory,
        references: Callable[..., Any] | None = None, device: Any = None, log: Callable[[str], None] = print) -> dict:
    from ..report import machine, scenes

    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    device = device if device is not None else open_device(s["device"])
    res: dict[str, Any] = {"format": FORMAT, "meta": machine.describe(device), "settings": s, "scenes": [],
                           "timing": [], "command": command_line(s)}
    res["meta"]["lscpu_model"] = lscpu_model()
    names = list(dict.fromkeys(list(s["scenes"] if s["quality"] else []) + list(s["timing_scenes"])))
    by_name = {}
    for name in names:
        entry = scenes.resolve([name])[0]
        log(f"loading {entry.label}")
        by_name[name] = scenes.load(entry)
    if s["quality"]:
        for name in s["scenes"]:
            e = by_name[name]
            if e.skipped:
                res["scenes"].append({"scene": e.label, "skipped": e.skipped})
                continue
            res["scenes"].append(evaluate_scene(e, s, device, out, factory=factory, references=references, log=log))
            save_json(res, out)
    for name in s["timing_scenes"]:
        e = by_name[name]
        if e.skipped:
            res["timing"].append({"scene": e.label, "skipped": e.skipped})
            continue
        res["timing"].append(time_scene(e, s, device, factory=factory, log=log))
        save_json(res, out)
    res["seconds"] = time.perf_counter() - t0
    save_json(res, out)
    return res


def lscpu_model() -> str | None:
    import subprocess

    try:
        text = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    for line in text.splitlines():
        if line.strip().lower().startswith("model name"):
            return line.split(":", 1)[1].strip()
    return None


def command_line(s: dict) -> str:
    args = ["python", "bench/evaluations/denoise_eval.py", "--scenes", *s["scenes"], "--modes", *s["modes"],
            "--frames", str(s["frames"]), "--size", s["size"], "--ref-spp", str(s["ref_spp"])]
    if s.get("device"):
        args += ["--device", s["device"]]
    if s["timing_scenes"] != s["scenes"]:
        args += ["--timing-scenes", *s["timing_scenes"]]
    return shlex.join(args)


def _jsonable(o: Any) -> Any:
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, (np.floating, float)):
        v = float(o)
        return v if math.isfinite(v) else None
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.ndarray):
        return _jsonable(o.tolist())
    if isinstance(o, Path):
        return str(o)
    return o


def save_json(res: dict, out: Path) -> None:
    tmp = out / "results.json.tmp"
    tmp.write_text(json.dumps(_jsonable(res), indent=1))
    tmp.replace(out / "results.json")


# -- figures (matplotlib, Agg) ---------------------------------------------------------------------
PANELS = [("noisy", "noisy, 1 spp"), ("none", "plain accumulation"), ("blend", "blend"), ("svgf", "svgf"),
          ("oidn", "oidn"), ("reference", "reference")]
COLORS = {"none": "#606060", "blend": "#1f77b4", "svgf": "#d62728", "oidn": "#2ca02c"}
DPI = 100


def _save(fig, out: Path, name: str) -> str:
    from ..report.plots import save_figure

    return save_figure(fig, out, name, dpi=DPI, software="pyclpt bench/evaluations/denoise_eval.py")


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def side_by_side(sc: dict, kind: str, npz: Path, out: Path, s: dict) -> str:
    """One row: noisy 1 spp, plain accumulation, blend, svgf, oidn, reference (those present), each
    tonemapped with the scene's exposure; under each its relMSE, SSIM and FLIP at that frame."""
    plt = _plt()
    data = np.load(npz)
    panels = [(k, t) for k, t in PANELS if k in data.files]
    ref = data["reference"]
    h, w = ref.shape[:2]
    fig, axes = plt.subplots(1, len(panels), figsize=(2.6 * len(panels), 2.6 * h / w + 0.9), squeeze=False)
    if kind == "static":
        frame = s["image_frame"]
        when = f"static camera, frame {frame}"
    else:
        frame = sc["orbit"]["frames"]
        when = f"orbit, frame {frame} (the last moving one)"
    for ax, (key, title) in zip(axes[0], panels):
        img = data[key]
        ax.imshow(M.tonemap(img, sc["exposure"]), interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        if key == "reference":
            label = f"{title}, {s['ref_spp']} spp"
        else:
            label = title if key != "none" or kind != "static" else f"{title}, {frame} frames"
            fl = M.flip(img, ref, mode=s["flip"], exposure=sc["exposure"])
            label += f"\nrelMSE {M.relmse(img, ref):.3g}  FLIP {fl:.3f}"
        ax.set_title(label, fontsize=8)
        if kind == "orbit" and key == "reference" and "region" in data.files and data["region"].any():
            ax.contour(data["region"], levels=[0.5], colors="cyan", linewidths=0.6)
    fig.suptitle(f"{sc['scene']} ({w}x{h}), {when}", fontsize=9)
    name = f"{_file(sc['scene'])}_{kind}.png"
    return _save(fig, out, name)


def curves(sc: dict, out: Path, s: dict) -> str | None:
    """relMSE against frame (static), and the changed region's relMSE after the light change and after
    the orbit stops, each mode beside its fresh-run baseline (dashed)."""
    if "static" not in sc:
        return None
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.4))
    ax = axes[0]
    for m, met in sc["static"]["metrics"].items():
        if met["relmse"]:
            ax.plot(sc["static"]["frames"][:len(met["relmse"])], met["relmse"], "o-", ms=3, label=m,
                    color=COLORS.get(m))
    ax.set(title="static camera", xlabel="frame", ylabel="relMSE", yscale="log")
    for ax, key, title in ((axes[1], "light", f"light x{s['light_scale']} after frame {s['frames']}"),
                           (axes[2], "orbit", "orbit stops (region disoccluded)")):
        rec = sc.get(key, {})
        for m in rec.get("region", {}):
            if rec["region"][m]:
                lag = rec.get("lag", {}).get(m)
                ax.plot(range(len(rec["region"][m])), rec["region"][m], "o-", ms=3, color=COLORS.get(m),
                        label=f"{m} (lag {'never' if lag is None and m in rec.get('lag', {}) else lag})")
            if rec.get("baseline", {}).get(m):
                ax.plot(range(len(rec["baseline"][m])), rec["baseline"][m], "--", color=COLORS.get(m), alpha=0.6)
        ax.set(title=title, xlabel="frames after the change", ylabel="relMSE in the region", yscale="log")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"{sc['scene']}: dashed = a fresh run of the changed scene (no history)", fontsize=9)
    name = f"{_file(sc['scene'])}_curves.png"
    return _save(fig, out, name)


# -- report ---------------------------------------------------------------------------------------
def _f(v: Any, fmt: str = ".3g") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return format(v, fmt)


def _at(series: list, k: int) -> float | None:
    return series[k - 1] if len(series) >= k else None


def machine_line(res: dict) -> str:
    m = res["meta"]
    dev = m.get("opencl", {})
    cpu = m.get("lscpu_model") or m.get("cpu")
    return (f"CPU: **{cpu}** ({m.get('cores')} cores, {m.get('memory_gib')} GiB), OpenCL: {dev.get('device', '?')} "
            f"on {dev.get('platform', '?')} ({dev.get('driver_version', '?')}); {m.get('date')}, "
            f"pyclpt {m.get('pyclpt')} ({m.get('git_revision')}), "
            f"load average at the start {m.get('load_average_start')}")


def goal_rows(res: dict) -> list[list[str]]:
    """The issue's goals, measured: one row per goal and scene."""
    s = res["settings"]
    k = s["image_frame"]
    rows = []
    for sc in res["scenes"]:
        if sc.get("skipped") or "static" not in sc:
            continue
        met = sc["static"]["metrics"]
        plain = _at(met.get("none", {}).get("relmse", []), k)
        oidn_flip = _at(met.get("oidn", {}).get("flip", []), k)
        for m in ("svgf", "blend"):
            if m not in met:
                continue
            rel = _at(met[m]["relmse"], k)
            fl = _at(met[m]["flip"], k)
            ratio = rel / plain if rel is not None and plain else None
            fratio = fl / oidn_flip if fl is not None and oidn_flip else None
            limit = RELMSE_GOALS.get(sc["scene"], GOALS["relmse_ratio"])
            goal = sc["scene"] in RELMSE_GOALS and m == "svgf"
            rows.append([sc["scene"], m, f"relMSE / plain at frame {k}", _f(ratio),
                         f"<= {limit}", _verdict(ratio, limit) if goal else "(beside)"])
            goal = sc["scene"] in FLIP_GOAL_SCENES and m == "svgf"
            rows.append([sc["scene"], m, f"FLIP / OIDN's at frame {k}", _f(fratio), f"<= {GOALS['flip_vs_oidn']}",
                         _verdict(fratio, GOALS["flip_vs_oidn"]) if goal else "(beside)"])
        for what, key in (("light", "light change"), ("orbit", "orbit")):
            for m, lag in sc.get(what, {}).get("lag", {}).items():
                if m in ("svgf", "blend"):
                    rows.append([sc["scene"], m, f"{key} lag (frames)", _f(lag, "d") if lag is not None else "never",
                                 f"< {GOALS['lag_frames']}",
                                 "yes" if lag is not None and lag < GOALS["lag_frames"] else "no"])
    for t in res.get("timing", []):
        for m, r in t.get("modes", {}).items():
            if m in ("svgf", "blend") and r.get("share_of_render") is not None:
                rows.append([t["scene"], m, f"denoiser / 1-spp render at {t['width']}x{t['height']}",
                             _f(r["share_of_render"], ".1%"), f"<= {GOALS['cost_share']:.0%}",
                             _verdict(r["share_of_render"], GOALS["cost_share"])])
    return rows


def _verdict(v: float | None, limit: float) -> str:
    return "-" if v is None else ("yes" if v <= limit else "no")


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head), *["| " + " | ".join(r) + " |" for r in rows]]


def markdown(res: dict) -> str:
    s = res["settings"]
    k = s["image_frame"]
    lines = ["# Denoising evaluation", "", machine_line(res), "",
             f"Command: `{res.get('command', '')}`; {_f(res.get('seconds'), '.0f')} s in all.", "",
             f"Quality runs: 1 sample per pixel per frame, megakernel; references {s['ref_spp']} spp "
             f"(seed 1); FLIP: {s['flip'].upper()}-FLIP; SSIM, FLIP, flicker and images on tonemapped images "
             f"(exposure {s['exposure']}, clip to [0, 1], sRGB).", ""]
    lines += ["## Goals", ""]
    lines += _table(["scene", "mode", "measure", "value", "goal", "met"], goal_rows(res))
    lines += ["", f"## Static camera, frame {k}", ""]
    rows = []
    for sc in res["scenes"]:
        if sc.get("skipped"):
            rows.append([sc["scene"], "skipped: " + sc["skipped"], "", "", "", ""])
            continue
        met = sc["static"]["metrics"]
        for m in s["modes"]:
            if m in sc.get("errors", {}) and not met[m]["relmse"]:
                rows.append([sc["scene"], m, "failed: " + sc["errors"][m], "", "", ""])
                continue
            rows.append([f"{sc['scene']} ({sc['width']}x{sc['height']})", m, _f(_at(met[m]["relmse"], k)),
                         _f(_at(met[m]["ssim"], k), ".4f"), _f(_at(met[m]["flip"], k), ".4f"),
                         _f(sc["static"]["mean_instability"].get(m), ".4f")])
    lines += _table(["scene", "mode", "relMSE", "SSIM", "FLIP", "mean abs(D_t - D_t-1)"], rows)
    lines += ["", "## Lag after a change", "",
              f"Frames after the change until the changed region's relMSE <= {s['lag_factor']} x a fresh run's "
              f"(no history) + {s['lag_floor']}: lag, against the fresh run at the same age; recovery, against the "
              f"fresh run after {s['after']} frames. 0: the first frame after the change already is; never: not "
              f"within {s['after']} frames.", ""]
    rows = []
    for sc in res["scenes"]:
        if sc.get("skipped") or "light" not in sc:
            continue
        li, orb = sc["light"], sc["orbit"]
        for m in s["modes"]:
            rows.append([sc["scene"], m, _lagtext(li.get("lag", {}), m), _lagtext(li.get("recovery", {}), m),
                         _lagtext(orb.get("lag", {}), m), _lagtext(orb.get("recovery", {}), m)])
    pixels = ", ".join(f"{sc['scene']} {sc['light'].get('region_pixels')} / {sc['orbit'].get('region_pixels')}"
                       for sc in res["scenes"] if "light" in sc and "orbit" in sc)
    lines += _table(["scene", "mode", f"light x{s['light_scale']}: lag", "recovery", "orbit stop: lag", "recovery"],
                    rows)
    lines += ["", f"Region pixels (light / orbit): {pixels}."]
    lines += ["", f"## Orbit ({s['orbit_degrees']} degrees over {s['frames']} frames), at the frames with a reference",
              ""]
    rows = []
    for sc in res["scenes"]:
        if sc.get("skipped") or "orbit" not in sc:
            continue
        o = sc["orbit"]
        for m in s["modes"]:
            met = o["metrics"][m]
            for i, f in enumerate(o["ref_frames"]):
                if i < len(met["relmse"]):
                    rows.append([sc["scene"], m, str(f), _f(met["relmse"][i]), _f(met["ssim"][i], ".4f"),
                                 _f(met["flip"][i], ".4f")])
    lines += _table(["scene", "mode", "frame", "relMSE", "SSIM", "FLIP"], rows)
    lines += ["", "## Cost per frame", ""]
    rows = []
    for t in res.get("timing", []):
        if t.get("skipped"):
            rows.append([t["scene"], "skipped", "", "", "", "", ""])
            continue
        for m, r in t["modes"].items():
            passes = ", ".join(f"{p['kernel']} {p['ms_per_frame']:.2f}" for p in r.get("passes", []))
            rows.append([f"{t['scene']} ({t['width']}x{t['height']})", m, _f(r["wall_ms"]["median"], ".1f"),
                         _f(r.get("render_ms"), ".1f"), _f(r.get("denoise_ms"), ".2f"),
                         _f(r.get("share_of_render"), ".1%"),
                         passes or ("host (OIDN, all cores)" if r.get("host") else "")])
        for m, err in t.get("errors", {}).items():
            rows.append([t["scene"], m, "failed: " + err, "", "", "", ""])
    lines += _table(["scene", "mode", "frame wall ms (median)", "render kernels ms", "denoiser ms",
                     "denoiser / render", "passes (device ms per frame)"], rows)
    loads = [f"{t['scene']} {t.get('load_average_start')} -> {t.get('load_average_end')}"
             for t in res.get("timing", []) if not t.get("skipped")]
    if loads:
        lines += ["", f"Medians of {s['timing_frames']} frames per mode after {s['timing_warmup']} warm-up frames, "
                  "the modes' frames interleaved; render and denoiser columns: device time (OpenCL profiling), "
                  "OIDN: host time per call. Load average (1, 5, 15 min) before -> after: " + "; ".join(loads) + "."]
    lines += ["", "## Images", ""]
    for sc in res["scenes"]:
        for key in ("static_png", "orbit_png", "curves_png"):
            if sc.get(key):
                lines.append(f"![{sc['scene']} {key[:-4]}]({sc[key]})")
    errs = [(sc["scene"], m, e) for sc in res["scenes"] for m, e in sc.get("errors", {}).items()]
    if errs:
        lines += ["", "## Failures", ""] + [f"- {a}, {m}: {e}" for a, m, e in errs]
    return "\n".join(lines) + "\n"


def _lagtext(lags: dict, m: str) -> str:
    if m not in lags:
        return "-"
    return "never" if lags[m] is None else str(lags[m])


def write_report(res: dict, out: Path) -> None:
    for sc in res["scenes"]:
        if sc.get("skipped") or "static" not in sc:
            continue
        for key in ("light", "orbit"):
            if key in sc:
                add_lags(sc[key], res["settings"])
        for kind in ("static", "orbit"):
            npz = arrays_folder(res["settings"], out, create=False) / f"{_file(sc['scene'])}_{kind}.npz"
            if npz.is_file():
                sc[f"{kind}_png"] = side_by_side(sc, kind, npz, out, res["settings"])
        sc["curves_png"] = curves(sc, out, res["settings"])
    save_json(res, out)
    (out / "report.md").write_text(markdown(res))


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    if a.from_json:
        path = Path(a.from_json)
        res = json.loads(path.read_text())
        if a.arrays:
            res["settings"]["arrays"] = a.arrays
        out = Path(a.out) if a.out else path.parent
        out.mkdir(parents=True, exist_ok=True)
        write_report(res, out)
        print(f"wrote {out / 'report.md'}")
        return 0
    try:
        s = settings_from(a)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    missing = missing_packages(s["modes"]) if s["quality"] or "oidn" in s["modes"] else []
    if missing:
        extras = "bench,oidn" if "pyoidn" in missing else "bench"
        print(f"error: the denoising evaluation needs {', '.join(missing)}: pip install 'pyclpt[{extras}]'"
              + (" (or leave out mode oidn: --modes none blend svgf)" if "pyoidn" in missing else ""),
              file=sys.stderr)
        return 2
    out = Path(a.out or "denoise-eval")
    res = run(s, out, log=(lambda m: None) if a.no_progress else (lambda m: print(m, flush=True)))
    write_report(res, out)
    print(f"wrote {out / 'report.md'} and {out / 'results.json'} ({res['seconds']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
