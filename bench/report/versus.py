"""``pyclpt bench --versus mitsuba``: pyclpt and Mitsuba 3 (``llvm_ad_rgb``) on the same scene files.

    pyclpt bench --versus mitsuba [--mitsuba-python PATH] [-o bench-versus] [--scenes ...]
                 [--resolution 128x128] [--spp 16] [--depths 8 65] [--repeats 3] [--quick]
                 [--reference-factor 64] [--fresh-references]

pyclpt renders in this process (``pyclpt.Renderer``: megakernel and wavefront SoA); Mitsuba in a
subprocess of the Python of its own environment (``--mitsuba-python``, else ``$PYCLPT_MITSUBA_PYTHON``),
which runs ``bench/report/mitsuba_driver.py`` and answers one render per request. Both sides render the
same file with the same spp, max depth, resolution, a box reconstruction filter and Russian
roulette from bounce 3 (the driver's docstring says how Mitsuba's scene is edited; each side keeps its own
survival probability: docs/architecture.md, "Russian roulette"). Compilation is
excluded on both sides (pyclpt when the renderer is made, Mitsuba by a warm-up render); then
``--repeats`` rounds alternate one render of every pyclpt integrator and one of Mitsuba, rotating
the order. Reported: median seconds, Msamples/s (pixels x spp / s), pyclpt / Mitsuba and the image
means per channel side by side with their relative difference. Written: ``versus.md`` and
``versus.json`` in the output folder.

Time to a clean image: every configuration also gets a converged reference per engine (``--reference-factor``
x spp samples: pyclpt's first integrator in one render, Mitsuba in passes of spp through the driver's
``reference`` command; cached under the pyclpt cache folder, kind ``versus-reference``, keyed by the engine,
its version (for pyclpt: the contents of its Python and OpenCL sources), the scene file's bytes and its
folder's listing, and the settings). Each timed render's relMSE (:func:`relmse`, eps
:data:`RELMSE_EPS`) against its own engine's reference measures its noise; against the other engine's it
adds the bias between the two. The work-normalised variance relMSE x median seconds (relMSE the mean over
the rounds, own reference) of Mitsuba over pyclpt's is how much sooner pyclpt reaches the same relMSE
(:func:`time_ratio`).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import logging
import math
import os
import re
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from functools import cache
from pathlib import Path

import numpy as np

from pyclpt.common import env

log = logging.getLogger(__name__)

DRIVER = Path(__file__).resolve().parent / "mitsuba_driver.py"
SHARED = ["cornell-box", "classroom", "living-room", "staircase", "staircase2"]
DEFAULTS = {"scenes": ["builtin/cornell-box", *SHARED], "resolution": "128x128", "spp": 16, "depths": [8, 65],
            "cornell_resolution": "256x256", "cornell_spp": 64, "cornell_depth": 8, "repeats": 3,
            "methods": ["megakernel", "wavefront-soa"], "rr_depth": 3, "reference_factor": 64}
QUICK = {"resolution": "32x32", "spp": 2, "depths": [8], "cornell_resolution": "32x32", "cornell_spp": 2,
         "repeats": 1, "reference_factor": 4}
REFERENCE_SEED = 1_000_000  # the references' seeds (Mitsuba's passes: this, this + 1, ...); timed renders use 1, 2, ...
CACHE_KIND = "versus-reference"


class MitsubaError(RuntimeError):
    """The Mitsuba side could not be started or failed (the message names the option and variable)."""


def build_parser() -> argparse.ArgumentParser:
    from .options import positive as _positive
    from .options import resolution as _resolution

    p = argparse.ArgumentParser(prog="pyclpt bench --versus mitsuba",
                                description="pyclpt against Mitsuba 3 llvm_ad_rgb on the same scene files "
                                "(docs/benchmarks.md, 'Versus Mitsuba 3').")
    p.add_argument("--versus", choices=("mitsuba",), required=True)
    p.add_argument("--mitsuba-python", default=None, metavar="PATH",
                   help="the python of an environment with mitsuba installed (default $PYCLPT_MITSUBA_PYTHON)")
    p.add_argument("-o", "--output", default="bench-versus", help="report folder (default bench-versus)")
    p.add_argument("--quick", action="store_true", help="tiny images, 2 spp, depth 8, one repeat")
    p.add_argument("--scenes", nargs="+", default=None,
                   help="builtin/cornell-box (pyclpt's built-in scene, JSON) and shared scene folders "
                        f"({', '.join(SHARED)}) or .xml/.json files")
    p.add_argument("--resolution", type=_resolution, default=None, help="WIDTHxHEIGHT of the shared scenes")
    p.add_argument("--spp", type=_positive, default=None, help="samples per pixel of the shared scenes")
    p.add_argument("--depths", nargs="+", type=_positive, default=None, help="max depths of the shared scenes")
    p.add_argument("--cornell-resolution", type=_resolution, default=None)
    p.add_argument("--cornell-spp", type=_positive, default=None)
    p.add_argument("--cornell-depth", type=_positive, default=None)
    p.add_argument("--repeats", type=_positive, default=None, help="timed rounds (medians over them)")
    p.add_argument("--methods", nargs="+", choices=("megakernel", "wavefront-aos", "wavefront-soa"), default=None)
    p.add_argument("--device", default=None, help="pyclpt's OpenCL device")
    p.add_argument("--reference-factor", type=_positive, default=None,
                   help="the converged references have this many times the timed spp (default 64, --quick 4)")
    p.add_argument("--fresh-references", action="store_true",
                   help="render the references again instead of reading the cached ones")
    return p


# -- time to a clean image ------------------------------------------------------------------------
#: relMSE's eps, as in the denoising evaluation (bench/denoise_metrics.py, which the report does not import).
RELMSE_EPS = 1e-2


def relmse(x: np.ndarray, ref: np.ndarray) -> float:
    """relMSE of an image against a reference: mean over pixels and channels of (x - ref)^2 / (ref^2 + eps),
    eps = :data:`RELMSE_EPS`, on the linear (H, W, 3) images."""
    x, ref = np.asarray(x, np.float64)[..., :3], np.asarray(ref, np.float64)[..., :3]
    if x.shape != ref.shape:
        raise ValueError(f"relMSE of images of different shapes: {x.shape} and {ref.shape}")
    return float(np.mean((x - ref) ** 2 / (ref * ref + RELMSE_EPS)))


def time_ratio(pyclpt_relmse: float | None, pyclpt_s: float, mitsuba_relmse: float | None,
               mitsuba_s: float) -> float | None:
    """Time to equal relMSE, Mitsuba's over pyclpt's: relMSE falls as 1 / spp, so the time to reach a relMSE
    is proportional to relMSE x seconds at equal spp; > 1 means pyclpt gets there sooner. None when a relMSE is
    missing, either work-normalised figure is 0 (an image identical to its reference: a black scene) or not
    finite."""
    if pyclpt_relmse is None or mitsuba_relmse is None:
        return None
    p, m = pyclpt_relmse * pyclpt_s, mitsuba_relmse * mitsuba_s
    if not (math.isfinite(p) and math.isfinite(m)) or p <= 0 or m <= 0:
        return None
    return m / p


def geometric_mean(values: Sequence[float]) -> float | None:
    return math.exp(statistics.fmean(math.log(v) for v in values)) if values else None


@cache
def pyclpt_source_key() -> str:
    """SHA-1 of pyclpt's Python and OpenCL sources (a changed renderer never reuses a stale reference)."""
    import pyclpt
    from pyclpt.device.program import cl_dir

    h = hashlib.sha1(pyclpt.__version__.encode())
    for root, pattern in ((Path(pyclpt.__file__).resolve().parent, "*.py"), (cl_dir(), "*")):
        for f in sorted(root.rglob(pattern)):
            if f.is_file() and "__pycache__" not in f.parts:
                h.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


def scene_key(file: str) -> str:
    """SHA-1 of a scene file's bytes and (an .xml) the names and sizes of the files in its folder."""
    path = Path(file)
    h = hashlib.sha1(path.read_bytes())
    if path.suffix == ".xml":
        for f in sorted(path.parent.rglob("*")):
            if f.is_file():
                h.update(f"{f.relative_to(path.parent)}\0{f.stat().st_size}\0".encode())
    return h.hexdigest()


def reference_key(engine: str, version: str, case: dict, s: dict) -> str:
    from pyclpt.common.cache import content_key

    return content_key(CACHE_KIND, engine, version, scene_key(case["file"]), case["width"], case["height"],
                       case["spp"], case["depth"], s["rr_depth"], s["reference_factor"], "box", REFERENCE_SEED)


def reference(engine: str, version: str, case: dict, s: dict,
              render: Callable[[], tuple[np.ndarray, float]]) -> tuple[np.ndarray, dict]:
    """One engine's converged image of a configuration, (H, W, 3) float32, and what it was: from the cache
    unless ``--fresh-references`` (then ``render()``: the image and its seconds, stored)."""
    from pyclpt.common.cache import cache_path, save_npz

    path = cache_path(CACHE_KIND, reference_key(engine, version, case, s))
    info = {"spp": case["spp"] * s["reference_factor"], "cached": False}
    if path is not None and path.is_file() and not s.get("fresh_references"):
        try:
            with np.load(path) as z:
                image, seconds = z["image"], float(z["seconds"])
            log.info("%s's reference of %s depth %d: %s", engine, case["scene"], case["depth"], path)
            return image, dict(info, cached=True, seconds=seconds, mean=_means(image), file=str(path))
        except (OSError, KeyError, ValueError) as exc:
            log.info("%s: unreadable (%s); rendering the reference again", path, exc)
    log.info("rendering %s's reference of %s depth %d (%d spp)", engine, case["scene"], case["depth"], info["spp"])
    image, seconds = render()
    image = np.asarray(image, np.float32)[..., :3]
    if path is not None:
        save_npz(path, image=image, seconds=np.float64(seconds))
    return image, dict(info, seconds=seconds, mean=_means(image), file=str(path) if path else None)


def _means(image: np.ndarray) -> list[float]:
    return [float(x) for x in np.asarray(image, np.float64)[..., :3].reshape(-1, 3).mean(axis=0)]


def mitsuba_python(option: str | None) -> str:
    """The Mitsuba environment's python: the option, else the variable; a clear error when neither works."""
    how = ("give --mitsuba-python PATH or set PYCLPT_MITSUBA_PYTHON to the python of a virtual environment "
           "with mitsuba installed (docs/benchmarks.md, 'Versus Mitsuba 3')")
    value = option or (str(env.path("PYCLPT_MITSUBA_PYTHON")) if env.get("PYCLPT_MITSUBA_PYTHON") else None)
    if not value:
        raise MitsubaError(f"no Mitsuba python: {how}")
    source = "--mitsuba-python" if option else "PYCLPT_MITSUBA_PYTHON"
    path = Path(value).expanduser()
    if not path.is_file() or not os.access(path, os.X_OK):
        raise MitsubaError(f"{source}={value!r}: not an executable file; {how}")
    return str(path)


def _json_in(line: str) -> object:
    """The JSON object on a driver's output line (after any colour codes Mitsuba's log left), else None."""
    text = re.sub(r"\x1b\[[0-9;]*m", "", line)
    start = text.find("{")
    try:
        return json.loads(text[start:]) if start >= 0 else None
    except json.JSONDecodeError:
        return None


def probe(python: str) -> dict:
    """Check that ``python`` runs the driver with Mitsuba (its version and variant), else MitsubaError."""
    cmd = [python, str(DRIVER), "--probe"]
    try:
        done = subprocess.run(cmd, input="", capture_output=True, text=True, timeout=300)
    except (OSError, subprocess.SubprocessError) as exc:
        raise MitsubaError(f"cannot run the Mitsuba python {python!r} ({exc}); check --mitsuba-python / "
                           "PYCLPT_MITSUBA_PYTHON") from None
    for line in done.stdout.splitlines():
        msg = _json_in(line)
        if isinstance(msg, dict) and msg.get("event") == "ready":
            return msg
        if isinstance(msg, dict) and msg.get("event") == "error":
            break
    detail = (done.stdout.strip() + " " + done.stderr.strip()).strip()[-600:] or f"exit status {done.returncode}"
    raise MitsubaError(f"{shlex.join(cmd)} failed: {detail}; --mitsuba-python / PYCLPT_MITSUBA_PYTHON must be the "
                       "python of an environment with mitsuba 3 (and DRJIT_LIBLLVM_PATH set for its LLVM backend)")


def cases(s: dict) -> list[dict]:
    """(label, file, width, height, spp, depth) of every configuration asked for."""
    from pyclpt.scene.library import builtin_dir, scenes_root

    def wh(text: str) -> tuple[int, int]:
        w, h = (int(x) for x in text.split("x"))
        return w, h

    out = []
    root = scenes_root()
    for name in s["scenes"]:
        if name.startswith("builtin/"):
            path = builtin_dir() / f"{name.removeprefix('builtin/')}.json"
            w, h = wh(s["cornell_resolution"])
            out.append({"scene": name, "file": str(path), "width": w, "height": h, "spp": s["cornell_spp"],
                        "depth": s["cornell_depth"]})
            continue
        path = Path(name)
        if not path.suffix:
            if root is None:
                raise ValueError(f"{name}: the shared scene folder (PYCLPT_SCENES) was not found")
            path = root / name / "scene.xml"
        if not path.is_file():
            raise ValueError(f"{name}: {path} does not exist")
        w, h = wh(s["resolution"])
        for depth in s["depths"]:
            out.append({"scene": name, "file": str(path), "width": w, "height": h, "spp": s["spp"], "depth": depth})
    return out


class MitsubaSide:
    """The driver subprocess for one configuration: started (scene loaded, warm-up render done), then
    one render per :meth:`render`."""

    def __init__(self, python: str, case: dict, rr_depth: int) -> None:
        self.cmd = [python, str(DRIVER), "--scene", case["file"], "--spp", str(case["spp"]), "--max-depth",
                    str(case["depth"]), "--width", str(case["width"]), "--height", str(case["height"]),
                    "--rr-depth", str(rr_depth)]
        try:
            self.proc = subprocess.Popen(self.cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                         stderr=subprocess.PIPE, text=True, bufsize=1)
        except OSError as exc:
            raise MitsubaError(f"cannot run the Mitsuba python {python!r} ({exc}); check --mitsuba-python / "
                               "PYCLPT_MITSUBA_PYTHON") from None
        self.log: list[str] = []
        self.ready = self._answer("ready")

    def _answer(self, event: str) -> dict:
        msg, line = None, ""
        while self.proc.stdout:  # Mitsuba logs to stdout too: pass its lines on, up to the next JSON answer
            line = self.proc.stdout.readline()
            if not line:
                break
            msg = _json_in(line)
            if isinstance(msg, dict) and "event" in msg:
                break
            print(f"mitsuba: {line.rstrip()}", file=sys.stderr)
            self.log.append(line.rstrip())
        if not isinstance(msg, dict) or msg.get("event") != event:
            self.proc.kill()
            err = self.proc.stderr.read() if self.proc.stderr else ""
            detail = msg.get("message") if isinstance(msg, dict) and msg.get("event") == "error" else \
                (line.strip() or err.strip()[-600:] or f"exit status {self.proc.wait()}")
            raise MitsubaError(f"Mitsuba failed on {self.cmd[3]}: {detail}")
        return msg

    def render(self, seed: int, save: Path | None = None) -> dict:
        """One timed render; with ``save``, its image (read from the .npy the driver writes) as ``"image"``
        (None when the driver wrote none)."""
        assert self.proc.stdin is not None
        if save is not None:
            save.unlink(missing_ok=True)  # never an earlier round's image
        self.proc.stdin.write(f"render {seed}" + (f" {save}" if save else "") + "\n")
        self.proc.stdin.flush()
        answer = self._answer("render")
        if save is not None:
            answer["image"] = np.load(save) if save.is_file() else None
        return answer

    def reference(self, passes: int, seed: int, save: Path) -> tuple[np.ndarray, float]:
        """The average of ``passes`` renders (seeds ``seed``, ``seed + 1``, ...) and its seconds."""
        assert self.proc.stdin is not None
        self.proc.stdin.write(f"reference {passes} {seed} {save}\n")
        self.proc.stdin.flush()
        answer = self._answer("reference")
        return np.load(save), float(answer["seconds"])

    def close(self) -> None:
        try:
            if self.proc.stdin:
                self.proc.stdin.write("quit\n")
                self.proc.stdin.close()
            self.proc.wait(timeout=30)
        except (OSError, subprocess.TimeoutExpired):
            self.proc.kill()


def _pyclpt_render(renderer, spp: int, seed: int) -> dict:
    t = time.perf_counter()
    image = renderer.render(spp, seed=seed, progress=False)
    renderer.device.queue.finish()
    seconds = time.perf_counter() - t
    return {"seconds": seconds, "mean": [float(x) for x in image.reshape(-1, image.shape[-1])[:, :3].mean(axis=0)],
            "image": image[..., :3]}


def _pyclpt_reference(renderer, spp: int) -> tuple[np.ndarray, float]:
    t = time.perf_counter()
    image = renderer.render(spp, seed=REFERENCE_SEED, progress=False)
    return image, time.perf_counter() - t


def noise_figures(runs: Sequence[dict], own: np.ndarray, other: np.ndarray, median_s: float) -> dict:
    """relMSE of each timed render against its engine's reference (noise) and the other engine's (noise and
    bias), their means over the rounds and the work-normalised relMSE x median seconds; None where a render
    brought no image."""
    images = [r.get("image") for r in runs]
    if any(im is None for im in images):
        return {"relmse": None, "relmse_mean": None, "relmse_x_s": None, "relmse_cross": None,
                "relmse_cross_mean": None}
    errs = [relmse(im, own) for im in images]
    cross = [relmse(im, other) for im in images]
    mean = statistics.fmean(errs)
    return {"relmse": errs, "relmse_mean": mean, "relmse_x_s": mean * median_s, "relmse_cross": cross,
            "relmse_cross_mean": statistics.fmean(cross)}


def measure(case: dict, s: dict, python: str, device) -> dict:
    """One configuration: pyclpt's renderers and Mitsuba warmed up, then alternating timed rounds."""
    import pyclpt

    from .runner import make_renderer

    scene = pyclpt.load(case["file"])
    scene.film.rfilter = pyclpt.ReconstructionFilter("box")  # as the driver makes Mitsuba's (the shared scenes: tent)
    renderers, info = {}, {}
    for m in s["methods"]:
        r = make_renderer(scene, m, case["depth"], case["width"], case["height"], device)
        r.render(1, seed=0, progress=False)  # warm-up (first launches)
        renderers[m] = r
        info[m] = {"compile_s": r.stats.compile_seconds, "setup_s": r.stats.setup_seconds}
    mitsuba = MitsubaSide(python, case, s["rr_depth"])
    names = [*s["methods"], "mitsuba"]
    runs: dict[str, list[dict]] = {n: [] for n in names}
    refs: dict[str, tuple[np.ndarray, dict]] = {}
    try:
        with tempfile.TemporaryDirectory(prefix="pyclpt-versus-") as tmp:
            first = s["methods"][0]
            refs["pyclpt"] = reference("pyclpt", pyclpt_source_key(), case, s, lambda: _pyclpt_reference(
                renderers[first], case["spp"] * s["reference_factor"]))
            refs["pyclpt"][1]["method"] = first
            refs["mitsuba"] = reference("mitsuba", f"{mitsuba.ready.get('mitsuba_version')} "
                                        f"{mitsuba.ready.get('variant')}", case, s, lambda: mitsuba.reference(
                                            s["reference_factor"], REFERENCE_SEED, Path(tmp) / "reference.npy"))
            for i in range(s["repeats"]):
                k = i % len(names)
                for n in names[k:] + names[:k]:
                    runs[n].append(mitsuba.render(1 + i, Path(tmp) / "render.npy") if n == "mitsuba" else
                                   _pyclpt_render(renderers[n], case["spp"], 1 + i))
    finally:
        mitsuba.close()
    samples = case["width"] * case["height"] * case["spp"]
    out = dict(case, samples=samples, methods={})
    for n in names:
        secs = [r["seconds"] for r in runs[n]]
        med = statistics.median(secs)
        mean = [statistics.fmean(r["mean"][c] for r in runs[n]) for c in range(3)]
        own, other = (refs["mitsuba"][0], refs["pyclpt"][0]) if n == "mitsuba" else \
            (refs["pyclpt"][0], refs["mitsuba"][0])
        out["methods"][n] = {"seconds": secs, "median_s": med, "msamples_per_s": samples / med / 1e6,
                             "mean": mean, **info.get(n, {}), **noise_figures(runs[n], own, other, med)}
    ms = out["methods"]["mitsuba"]
    for n in s["methods"]:
        m = out["methods"][n]
        m["time_to_equal_relmse"] = time_ratio(m["relmse_mean"], m["median_s"], ms["relmse_mean"], ms["median_s"])
    out["references"] = {e: info_ for e, (_, info_) in refs.items()}
    out["references"]["relmse_pyclpt_vs_mitsuba"] = relmse(refs["pyclpt"][0], refs["mitsuba"][0])
    out["mitsuba"] = {k: v for k, v in mitsuba.ready.items() if k != "event"}
    return out


# -- report -----------------------------------------------------------------------------------------
def _rel(a: float, b: float) -> float | None:
    """(a - b) / |b|; None when b is 0 (and a is not)."""
    if b == 0:
        return 0.0 if a == 0 else None
    return (a - b) / abs(b)


def rows(res: dict) -> list[list[str]]:
    from .document import number as _n

    table = []
    for c in res["cases"]:
        if "error" in c:
            table.append([c["scene"], str(c.get("depth", "-")), "-", "-", "-", "-", "-", "-", "-", c["error"],
                          "-", "-", "-", "-"])
            continue
        ms = c["methods"]["mitsuba"]
        best = max((n for n in c["methods"] if n != "mitsuba"), key=lambda n: c["methods"][n]["msamples_per_s"])
        for n, m in c["methods"].items():
            if n == "mitsuba":
                continue
            ratio = m["msamples_per_s"] / ms["msamples_per_s"]
            rels = [_rel(m["mean"][k], ms["mean"][k]) for k in range(3)]
            diff = "Mitsuba's image is black" if None in rels else f"{100 * max(abs(r) for r in rels):.1f}%"
            refs = c.get("references", {})
            between = refs.get("relmse_pyclpt_vs_mitsuba")
            table.append([c["scene"], str(c["depth"]), f"{c['width']}x{c['height']}, {c['spp']} spp",
                          n + (" (fastest)" if n == best else ""), _n(m["median_s"]), _n(ms["median_s"]),
                          _n(m["msamples_per_s"]), _n(ms["msamples_per_s"]), f"{ratio:.2f}x",
                          f"{' '.join(f'{x:.4f}' for x in m['mean'])} / "
                          f"{' '.join(f'{x:.4f}' for x in ms['mean'])} ({diff})",
                          f"{_e(m.get('relmse_mean'))} / {_e(ms.get('relmse_mean'))}",
                          f"{_e(m.get('relmse_x_s'))} / {_e(ms.get('relmse_x_s'))}",
                          _x(m.get("time_to_equal_relmse")),
                          f"{_e(m.get('relmse_cross_mean'))} / {_e(ms.get('relmse_cross_mean'))} "
                          f"({_e(between)})"])
    return table


def _e(x: float | None) -> str:
    """A relMSE: three significant digits in exponent form; '-' for None or not finite."""
    return "-" if x is None or not math.isfinite(x) else f"{x:.3g}"


def _x(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}x"


def summary(res: dict) -> dict[str, dict[str, float | None]]:
    """Per pyclpt integrator, the geometric mean of the time-to-equal-relMSE ratio over every configuration
    (``all``) and over the shared scenes (``shared``), and its smallest value on a shared scene (``min_shared``);
    configurations without a ratio are left out."""
    out: dict[str, dict[str, float | None]] = {}
    for n in res["settings"]["methods"]:
        every = [(c["scene"], c["methods"][n].get("time_to_equal_relmse")) for c in res["cases"]
                 if n in c.get("methods", {})]
        every = [(scene, r) for scene, r in every if r is not None]
        shared = [r for scene, r in every if not scene.startswith("builtin/")]
        out[n] = {"all": geometric_mean([r for _, r in every]), "shared": geometric_mean(shared),
                  "min_shared": min(shared) if shared else None}
    return out


HEADER = ["scene", "depth", "setting", "pyclpt", "pyclpt s", "Mitsuba s", "pyclpt Msamples/s",
          "Mitsuba Msamples/s", "pyclpt / Mitsuba", "image mean RGB pyclpt / Mitsuba (max rel. diff.)",
          "relMSE pyclpt / Mitsuba", "relMSE x s pyclpt / Mitsuba", "time to equal relMSE, Mitsuba / pyclpt",
          "relMSE vs the other's reference pyclpt / Mitsuba (references' relMSE)"]


def to_markdown(res: dict) -> str:
    meta, st = res["meta"], res["settings"]
    lines = ["# pyclpt versus Mitsuba 3", "",
             f"- date: {meta.get('date', '-')}",
             f"- CPU: {meta['cpu']} ({meta['cores']} cores); load average at start {meta.get('load_average')}"
             + (f", at the end {meta['load_average_end']}" if meta.get("load_average_end") else ""),
             f"- pyclpt device: {meta['device']}",
             f"- Mitsuba {meta.get('mitsuba_version')}, variant {meta.get('variant')}",
             f"- command: `{meta['command']}`",
             f"- {st['repeats']} alternating rounds per configuration (pyclpt integrators and Mitsuba, order "
             "rotating), medians; compile excluded on both sides; box filter, Russian roulette from bounce "
             f"{st['rr_depth']} on both sides; elapsed {meta.get('elapsed_s', 0):.0f} s",
             "- Msamples/s = width x height x spp / median seconds; the ratio > 1 means pyclpt is faster",
             f"- relMSE = mean over pixels and channels of (x - ref)^2 / (ref^2 + {RELMSE_EPS:g}) of each timed "
             "render against its own engine's converged reference (pyclpt's: its first integrator), the mean over "
             f"the rounds; references of {st.get('reference_factor')} x spp samples, cached; the time to equal "
             "relMSE is Mitsuba's relMSE x s over pyclpt's (> 1: pyclpt reaches the same relMSE sooner); the last "
             "column measures against the other engine's reference (noise and bias) and, in brackets, pyclpt's "
             "reference against Mitsuba's"]
    for n, g in summary(res).items():
        lines.append(f"- time to equal relMSE, {n}: geometric mean {_x(g['all'])} over every configuration, "
                     f"{_x(g['shared'])} over the shared scenes (smallest {_x(g['min_shared'])})")
    lines += ["", "| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    lines += ["| " + " | ".join(r) + " |" for r in rows(res)]
    return "\n".join(lines) + "\n"


def settings_from(a: argparse.Namespace) -> dict:
    s = dict(DEFAULTS)
    if a.quick:
        s.update(QUICK)
    s["fresh_references"] = a.fresh_references
    for key in ("scenes", "resolution", "spp", "depths", "cornell_resolution", "cornell_spp", "cornell_depth",
                "repeats", "methods", "reference_factor"):
        v = getattr(a, key)
        if v is not None:
            s[key] = v
    for key in ("resolution", "cornell_resolution"):
        if s[key] == "scene":
            raise ValueError(f"--{key.replace('_', '-')} needs WIDTHxHEIGHT here (both sides get the same)")
    return s


def main(argv: Sequence[str]) -> int:
    a = build_parser().parse_args(list(argv))
    try:
        import pyclpt

        from . import machine

        python = mitsuba_python(a.mitsuba_python)
        s = settings_from(a)
        version = probe(python)
        todo = cases(s)
        out_dir = Path(a.output)
        out_dir.mkdir(parents=True, exist_ok=True)
        device = pyclpt.get_device(a.device)
        t0 = time.perf_counter()
        res = {"settings": s, "meta": {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                                       "cpu": machine.cpu_model(), "cores": os.cpu_count(),
                                       "load_average": machine.load_average(),
                                       "device": str(device.describe().get("device", device)),
                                       "command": "pyclpt bench " + shlex.join(list(argv)),
                                       "mitsuba_version": version.get("mitsuba_version"),
                                       "variant": version.get("variant")},
               "cases": []}
        for case in todo:
            print(f"{case['scene']} depth {case['depth']} {case['width']}x{case['height']} {case['spp']} spp ...",
                  file=sys.stderr, flush=True)
            try:
                c = measure(case, s, python, device)
            except Exception as exc:  # noqa: BLE001 - a scene one side cannot render is a row, not the end
                from .scenes import reason

                c = dict(case, error=reason(exc))
            if "mitsuba" in c:
                res["meta"].update(mitsuba_version=c["mitsuba"].get("mitsuba_version"),
                                   variant=c["mitsuba"].get("variant"))
            res["cases"].append(c)
            res["meta"]["elapsed_s"] = time.perf_counter() - t0
            (out_dir / "versus.json").write_text(json.dumps(res, indent=1))
        res["meta"]["load_average_end"] = machine.load_average()
        res["summary"] = summary(res)
        (out_dir / "versus.json").write_text(json.dumps(res, indent=1))
        md = to_markdown(res)
        (out_dir / "versus.md").write_text(md)
        print(md)
        if not any("methods" in c for c in res["cases"]):
            print("pyclpt bench: error: nothing was measured (every configuration failed)", file=sys.stderr)
            return 1
        return 0
    except (OSError, ValueError, RuntimeError) as exc:
        print(f"pyclpt bench --versus mitsuba: error: {exc}", file=sys.stderr)
        return 1
