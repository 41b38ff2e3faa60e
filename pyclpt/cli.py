"""The ``pyclpt`` command line: render, view, devices, scenes, warmup, bench."""
from __future__ import annotations

import argparse
import json
import logging
import math
import re
import signal
import sys
import threading
import time
import warnings
from collections.abc import Sequence
from pathlib import Path

from pyclpt.common.image_limits import LINEAR_EXTENSIONS, MAX_EXPOSURE

log = logging.getLogger("pyclpt.cli")

# Exit status of a command stopped by Ctrl-C (128 + SIGINT), as shells report it.
EXIT_INTERRUPTED = 130
# Exit status of a command stopped by SIGTERM (128 + SIGTERM).
EXIT_TERMINATED = 143


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread like Ctrl-C's KeyboardInterrupt, so that what Ctrl-C cleans
    up (an image write in progress removes its temporary file) is cleaned up on SIGTERM too."""


def _raise_terminated(signum, frame) -> None:
    raise Terminated()


def _catch_sigterm():
    """Turn SIGTERM into :class:`Terminated` for this command; returns the handler to restore (None
    where signals cannot be handled here: not the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        return None
    try:
        return signal.signal(signal.SIGTERM, _raise_terminated)
    except (ValueError, OSError, AttributeError):  # no SIGTERM, or not settable here
        return None


def _int_in(lo: int, hi: int | None, note: str = ""):
    """An argparse type: an integer in [lo, hi) (hi None: no upper bound); argparse names the option."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if v < lo or (hi is not None and v >= hi):
            bound = f">= {lo}" if hi is None else f"in [{lo}, {hi})"
            raise argparse.ArgumentTypeError(f"must be {bound}{note}, got {v}")
        return v

    return parse


def _define(text: str) -> tuple[str, str]:
    """An argparse type: Mitsuba's ``-D NAME=VALUE`` scene parameter."""
    name, sep, value = text.partition("=")
    if not sep or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE (NAME a letter or _ then letters, digits, _), "
                                         f"got {text!r}")
    return name, value


def _drop_linear_exposure(a: argparse.Namespace, out: str, aovs: object) -> None:
    """--exposure scales PNG/JPEG output only: for a linear output (EXR, --aov layers) warn once and
    drop it, rather than scale the radiance or warn for every frame."""
    ext = Path(out).suffix.lower()
    if a.exposure != 0.0 and (aovs or ext in LINEAR_EXTENSIONS):
        what = "--aov layers" if aovs else f"a linear {ext} file"
        log.warning("--exposure %g applies to PNG/JPEG output only; ignored for %s (%s)", a.exposure, what, out)
        a.exposure = 0.0


def _exposure(text: str) -> float:
    """An argparse type: exposure in stops, a finite number in [-MAX_EXPOSURE, MAX_EXPOSURE]."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of stops, got {text!r}") from None
    if not math.isfinite(v) or abs(v) > MAX_EXPOSURE:
        raise argparse.ArgumentTypeError(f"must be a finite number of stops in [-{MAX_EXPOSURE:g}, "
                                         f"{MAX_EXPOSURE:g}], got {text!r}")
    return v


def _degrees(text: str) -> float:
    """An argparse type: an orbit angle in degrees, a finite number."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of degrees, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be a finite number of degrees, got {text!r}")
    return v


def sequence_path(pattern: str, frame: int) -> str:
    """The file of frame ``frame`` of a --sequence: the last run of # in ``pattern`` replaced by the
    frame number, zero-padded to its length (``out_####.exr`` -> ``out_0007.exr``); a name without #
    gets ``_####`` before its extension."""
    runs = list(re.finditer(r"#+", pattern))
    if not runs:
        p = Path(pattern)
        return str(p.with_name(f"{p.stem}_{frame:04d}{p.suffix}"))
    m = runs[-1]
    return f"{pattern[:m.start()]}{frame:0{len(m.group())}d}{pattern[m.end():]}"


# The most samples (frames) one render takes: the 32-bit sample counter (pyclpt.render's limit).
MAX_SPP = 2**32


def _check_spp(a: argparse.Namespace, spp: int) -> int:
    """The render's sample count, refused up front (before any rendering) above MAX_SPP, naming where it
    came from: --frames, --spp or the scene's own (a Mitsuba ``sample_count``)."""
    from pyclpt.common.checks import check_int

    name = "--frames" if a.frames else "--spp" if a.spp else f"spp (the scene's sample count, {a.scene})"
    return check_int(spp, name, lo=1, hi=MAX_SPP)


def _version() -> str:
    from pyclpt import __version__

    return f"pyclpt {__version__}"


_positive = _int_in(1, None)


def _tile(text: str) -> tuple[int, int] | str | None:
    """An argparse type: a tile size, N or WxH pixels, 0 for no tiles, or auto."""
    if text == "auto":
        return text
    w, x, h = text.lower().partition("x")
    try:
        if x and not h:  # "3x": a side is missing, not a square
            raise ValueError(text)
        size = (int(w), int(h or w))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected N or WxH pixels (0: no tiles), got {text!r}") from None
    if size == (0, 0):
        return None
    if min(size) < 1:
        raise argparse.ArgumentTypeError(f"tile sides must be >= 1 pixel (0: no tiles), got {text!r}")
    return size
_depth = _int_in(-1, None, " (-1 = unlimited)")
_seed = _int_in(0, 2**32)


DEVICE_HELP = ("OpenCL device: pocl, intel (Intel's CPU runtime), gpu, cpu, P:D (`pyclpt devices`) or a "
               "platform/device name substring; default: PYCLPT_DEVICE, else the fastest installed (a GPU, else "
               "intel, else pocl)")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pyclpt", description="OpenCL wavefront path tracer")
    p.add_argument("--version", action="version", version=_version())
    p.add_argument("-v", "--verbose", action="store_true",
                   help="log the device chosen, compile times, progress details and every ignored scene setting")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND",
                           help="what to do (`pyclpt COMMAND --help` lists its options)")
    r = sub.add_parser("render", help="render a scene to an image file")
    r.add_argument("scene", help="built-in scene name (see `pyclpt scenes`) or scene file "
                                 "(.json, Mitsuba .xml)")
    r.add_argument("-o", "--output", default=None, help="output image (.exr linear; .png/.jpg sRGB); "
                                                        "default SCENE.png")
    r.add_argument("-D", "--define", type=_define, action="append", default=[], metavar="NAME=VALUE",
                   help="set a Mitsuba XML scene parameter ($NAME / <default name=NAME>); repeatable")
    r.add_argument("--spp", type=_positive, default=None, help="samples per pixel (default: the scene's)")
    r.add_argument("--frames", type=_positive, default=None,
                   help="frames to render, one sample per pixel each (default: --spp or the scene's spp)")
    r.add_argument("--precision", choices=("single", "compensated", "double"), default="double",
                   help="how frames are summed on the device (default double; docs/accumulation.md)")
    r.add_argument("--max-frames", type=_int_in(0, 2**32, " (0 = unlimited)"), default=0,
                   help="accumulate at most this many frames, then apply --overflow (0 = unlimited)")
    r.add_argument("--overflow", choices=("stop", "reset", "ema"), default="stop",
                   help="at --max-frames: stop (keep the image), reset (start over), ema (moving average)")
    r.add_argument("--max-depth", type=_depth, default=None, help="Mitsuba's max_depth; -1 = unlimited")
    r.add_argument("--width", type=_positive, default=None, help="image width in pixels (default: the scene's)")
    r.add_argument("--height", type=_positive, default=None, help="image height in pixels (default: the scene's)")
    r.add_argument("--seed", type=_seed, default=0,
                   help="random seed, 0 to 2^32-1 (default 0): the same seed gives the same image")
    r.add_argument("--integrator", choices=("megakernel", "wavefront"), default="megakernel",
                   help="megakernel: one kernel runs each path (default); wavefront: one kernel per stage "
                        "(docs/wavefront.md)")
    r.add_argument("--layout", choices=("soa", "aos"), default="soa",
                   help="wavefront path-state layout: soa (default) or aos")
    r.add_argument("--device", default=None, help=DEVICE_HELP)
    r.add_argument("--exposure", type=_exposure, default=0.0,
                   help=f"exposure in stops for PNG/JPEG output, within +-{MAX_EXPOSURE:g} (default 0); "
                        f"ignored, with a warning, for EXR and --aov output")
    r.add_argument("--aov", default=None, metavar="NAMES",
                   help="comma-separated AOVs written beside R,G,B into one multi-layer .exr (albedo.R, normal.X, "
                        "depth.Z, motion.X, ...): albedo, normal, roughness, depth, hitdist, motion, emission, "
                        "prim_id, mesh_id, material_id")
    r.add_argument("--denoise", nargs="?", const="svgf", default=None, choices=("svgf", "blend", "oidn"),
                   help="denoise every frame (default svgf; blend: the 70/30 history blend; oidn: Intel Open "
                        "Image Denoise, the [oidn] extra); the output is the denoised last frame")
    r.add_argument("--orbit", type=_degrees, default=None, metavar="DEGREES",
                   help="the camera orbits its look-at target by this many degrees over --frames")
    r.add_argument("--sequence", action="store_true",
                   help="write every frame: -o out_####.exr (#### is the frame number; added before the "
                        "extension when the name has no #)")
    r.add_argument("--workers", type=_positive, default=None, metavar="N",
                   help="render on a local Dask cluster of N worker processes (the [distributed] extra; "
                        "docs/distributed.md)")
    r.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="render on the Dask cluster whose scheduler is at ADDRESS (tcp://host:8786); the workers "
                        "open SCENE at the same path")
    r.add_argument("--task-spp", type=_positive, default=None, metavar="SPP",
                   help="with --workers/--scheduler: samples per task (default: about 4 tasks a worker)")
    r.add_argument("--tile", type=_tile, default="auto", metavar="N|WxH",
                   help="with --workers/--scheduler: tasks render tiles of N x N or W x H pixels (0: the whole "
                        "image; default: 512-pixel tiles for images over 2 Mpixels)")
    r.add_argument("--tev", nargs="?", const="127.0.0.1:14158", default=None, metavar="HOST:PORT",
                   help="show the image in tev (the HDR viewer) as it converges, a few times a second and the last "
                        "one, over tev's IPC protocol (the [tev] extra; default address 127.0.0.1:14158)")
    r.add_argument("--stats", action="store_true",
                   help="print a table of the paths alive per bounce and the time per kernel")
    r.add_argument("--stats-json", default=None, metavar="FILE",
                   help="write the raw statistics (kernels, bounces, memory, accumulation, denoiser) as JSON to "
                        "FILE (- for stdout)")
    r.add_argument("--quiet", action="store_true", help="no progress bar (shown on renders longer than a "
                                                       "couple of seconds otherwise) and no compile message")
    sub.add_parser("devices", help="list OpenCL platforms and devices")
    sub.add_parser("scenes", help="list built-in scenes")
    w = sub.add_parser("warmup", help="compile the kernels of the built-in scenes now, so that their first renders "
                                      "find them in the drivers' disk caches",
                       description="Render one sample per pixel of each built-in scene (at its own resolution, "
                                   "nothing written), so that the OpenCL drivers' disk caches (PoCL's kernel cache, "
                                   "pyopencl's binary cache) hold every program a first `pyclpt render` of it "
                                   "builds; prints each scene's compile time.")
    w.add_argument("--scenes", nargs="+", default=None, metavar="SCENE",
                   help="built-in scene names or scene files (default: every built-in scene; those whose meshes "
                        "are missing are skipped)")
    w.add_argument("--device", default=None, help=DEVICE_HELP)
    wv = w.add_mutually_exclusive_group()
    wv.add_argument("--wavefront", action="store_true",
                    help="the wavefront integrator too (default: the megakernel only, what render uses by default)")
    wv.add_argument("--all", action="store_true", dest="all_variants",
                    help="the megakernel and the wavefront, each also with the G-buffer and the SVGF denoiser "
                         "(what --aov and --denoise build)")
    g = sub.add_parser("gpu-isa", help="compile every kernel for NVIDIA sm_90 and AMD gfx1030/gfx90a without a GPU: "
                                       "registers, stack, spills, occupancy (docs/gpu.md)")
    g.add_argument("scenes", nargs="*", help="scenes whose programs to check (default: the built-ins at hand and "
                                             "the shared scenes)")
    g.add_argument("-o", "--output", default="gpu-isa", help="folder for isa.json, isa.md and isa.png "
                                                             "(default gpu-isa)")
    g.add_argument("--targets", nargs="+", choices=("sm_90", "gfx1030", "gfx90a"), default=None,
                   help="the GPU targets to compile for (default: all three)")
    g.add_argument("--quick", action="store_true", help="after the first scene, only the variants that hold "
                                                        "the most code (with the G-buffer, SoA, one precision)")
    g.add_argument("--device", default=None, help="the CPU OpenCL device that assembles the programs "
                                                  "(nothing is compiled for it): pocl, intel, cpu, P:D or a name "
                                                  "substring (default: the default device)")
    v = sub.add_parser("view", help="render a scene live in the browser, with camera controls (the [viewer] "
                                    "extra; docs/viewer.md)")
    v.add_argument("scene", help="built-in scene name (see `pyclpt scenes`) or scene file (.json, Mitsuba .xml)")
    v.add_argument("-D", "--define", type=_define, action="append", default=[], metavar="NAME=VALUE",
                   help="set a Mitsuba XML scene parameter ($NAME / <default name=NAME>); repeatable")
    v.add_argument("--port", type=_int_in(0, 65536), default=0,
                   help="the port on 127.0.0.1 to serve the page on (default 0: a free one)")
    v.add_argument("--no-browser", action="store_true", help="print the page's address instead of opening it")
    v.add_argument("--width", type=_positive, default=None,
                   help="a fixed frame width in pixels (default: the frame follows the page's window, the scene's "
                        "aspect kept, up to --max-size)")
    v.add_argument("--height", type=_positive, default=None,
                   help="a fixed frame height in pixels (default: from --width and the scene's aspect)")
    v.add_argument("--max-size", type=_int_in(8, 8193), default=640, metavar="PIXELS",
                   help="the longer side of a frame that follows the window, at most (8 to 8192, default 640)")
    v.add_argument("--spp-per-frame", type=_int_in(1, 65), default=1,
                   help="samples per pixel rendered between two pictures shown, 1 to 64 (default 1)")
    v.add_argument("--max-depth", type=_depth, default=None, help="Mitsuba's max_depth; -1 = unlimited")
    v.add_argument("--denoiser", choices=("off", "blend", "svgf"), default="svgf",
                   help="svgf (default): camera moves keep the reprojected history; blend: the 70/30 history "
                        "blend; off: the plain average, which a camera move restarts")
    v.add_argument("--view", choices=("color", "denoised", "albedo", "normal", "depth", "motion", "samples"),
                   default=None,
                   help="what to show first (default denoised with a denoiser, else color)")
    v.add_argument("--integrator", choices=("megakernel", "wavefront"), default="megakernel",
                   help="megakernel (default) or wavefront (docs/wavefront.md)")
    v.add_argument("--layout", choices=("soa", "aos"), default="soa",
                   help="wavefront path-state layout: soa (default) or aos")
    v.add_argument("--device", default=None, help=DEVICE_HELP)
    v.add_argument("--seed", type=_seed, default=0, help="random seed, 0 to 2^32-1 (default 0)")
    v.add_argument("--exposure", type=_exposure, default=0.0,
                   help=f"exposure in stops of what is shown, within +-{MAX_EXPOSURE:g} (default 0)")
    v.add_argument("--output-dir", default=".", metavar="DIR",
                   help="where the page's Save and Camera buttons write (default: the current folder)")
    # Everything after `bench` goes to the report generator's own parser (`pyclpt bench --help`).
    sub.add_parser("bench", add_help=False, help="timing report: megakernel vs wavefront AoS/SoA "
                                                 "(`pyclpt bench --help`)")
    return p


def _cmd_render(a: argparse.Namespace) -> int:
    from pyclpt.common.image_io import check_output_path, write_image, write_layers
    from pyclpt.film.aovs import AOV_CHANNELS, check_aovs
    from pyclpt.rendering.progressive import ProgressiveRenderer
    from pyclpt.scene.camera_path import CameraPath
    from pyclpt.scene.library import load

    if a.frames and a.spp and a.frames != a.spp:
        raise ValueError(f"--frames {a.frames} and --spp {a.spp} disagree (a frame is one sample per pixel)")
    if a.overflow != "stop" and not a.max_frames:
        raise ValueError(f"--overflow {a.overflow} acts once --max-frames frames are accumulated; "
                         f"give --max-frames > 0")
    aovs = check_aovs(a.aov.split(",") if a.aov is not None else None)
    # Fail before loading and rendering (possibly long) rather than when writing the result.
    if a.output:
        check_output_path(sequence_path(a.output, 0) if a.sequence else a.output)
    if a.stats_json not in (None, "-") and not Path(a.stats_json).resolve().parent.is_dir():
        raise ValueError(f"--stats-json {a.stats_json}: the folder {Path(a.stats_json).resolve().parent} does not "
                         f"exist")
    if aovs and a.output and not a.output.lower().endswith(".exr"):
        raise ValueError(f"--aov writes its layers into a multi-layer OpenEXR file: give -o NAME.exr, not {a.output}")
    if a.workers is not None or a.scheduler is not None:
        return _render_distributed(a)
    if a.task_spp is not None or a.tile != "auto":
        what = "--task-spp" if a.task_spp is not None else "--tile"
        raise ValueError(f"{what} splits a render over a cluster: give --workers N or --scheduler ADDRESS")
    t0 = time.perf_counter()
    scene = load(a.scene, **dict(a.define))
    load_seconds = time.perf_counter() - t0
    out = a.output or f"{scene.name}.{'exr' if aovs else 'png'}"
    _drop_linear_exposure(a, out, aovs)
    if not a.output:
        check_output_path(out)
    tev = _open_tev(a, Path(out).name)  # before compiling: a tev that is not running is said at once
    size = {"width": a.width or scene.film.width, "height": a.height or scene.film.height}
    frames = _check_spp(a, a.frames or a.spp or scene.spp)
    path = CameraPath.orbit(scene, a.orbit, frames) if a.orbit is not None else None
    pr = ProgressiveRenderer(scene, seed=a.seed, integrator=a.integrator, layout=a.layout, max_depth=a.max_depth,
                             device=a.device, precision=a.precision, max_frame_count=a.max_frames,
                             overflow=a.overflow, aovs=aovs or None, denoiser=a.denoise, camera_path=path, **size)

    def write(target: str, image) -> None:
        if aovs:
            layers = pr.aovs(aovs)
            write_layers(target, image, {n: (layers[n], AOV_CHANNELS[n]) for n in aovs})
        else:
            write_image(target, image, exposure=a.exposure)
        a.written = target

    written: list[int] = []  # the frames of a --sequence really written (--max-frames may stop it early)

    def write_frame(k: int) -> None:
        write(sequence_path(out, k), pr.denoised() if pr.denoiser is not None else pr.image())
        written.append(k)

    def on_frame(k: int) -> None:
        if a.sequence:
            write_frame(k)
        if tev is not None and tev.due():
            tev.send(pr.denoised() if pr.denoiser is not None else pr.image())

    log.info("rendering %d frame(s) of %dx%d into %s", frames, pr.width, pr.height, out)
    try:
        image = pr.run(frames, progress=not a.quiet, on_frame=on_frame if a.sequence or tev is not None else None)
    except BaseException:
        if tev is not None:
            tev.close()
        raise
    tev_line = _finish_tev(tev, image)
    if not a.sequence:
        write(out, image)
    total = time.perf_counter() - a.started  # from the command's start to the written file
    r, st = pr.renderer, pr.stats
    acc = st.accumulation
    print(f"{out}: {r.width}x{r.height}, {_samples(a, pr, frames)}, max depth {r.max_depth}, {a.integrator}"
          f"{'/' + a.layout if a.integrator == 'wavefront' else ''} on {r.device.name}: "
          f"load {load_seconds + st.setup_seconds:.2f} s, compile {st.compile_seconds:.2f} s, "
          f"render {st.seconds:.2f} s, total {total:.2f} s")
    if st.dropped_samples:
        print(f"dropped {st.dropped_samples} NaN/inf samples")
    if acc.get("overflowed_samples"):
        print(f"{acc['overflowed_samples']} pixel samples not added: the {a.precision} sum would overflow float")
    if a.sequence:
        n = len(written)
        stopped = f" of {frames}" if n < frames else ""  # why: the summary line says it
        print(f"wrote {n} frame{'s' if n != 1 else ''}{stopped}" +
              (f": {sequence_path(out, written[0])} .. {sequence_path(out, written[-1])}" if written else ""))
    if pr.denoiser is not None:
        print(f"denoised ({a.denoise}): {sum(row['total_ms'] for row in st.denoise) / 1000:.3f} s on the device"
              + (f", {pr.reprojections} camera moves reprojected" if pr.reprojections else ""))
    if tev_line:
        print(tev_line)
    if a.stats:
        print(stats_table(st), end="")
    if a.stats_json:
        _write_stats_json(a.stats_json, {"kernels": st.kernels, "bounces": st.bounces, "tail_alive": st.tail_alive,
                                         "memory": st.memory, "dropped_samples": st.dropped_samples,
                                         "accumulation": acc, "denoise": st.denoise})
    return 0


def _open_tev(a: argparse.Namespace, name: str):
    """``--tev HOST:PORT``: the connection to tev (pyclpt.viewer.tev), or None without --tev."""
    if a.tev is None:
        return None
    from pyclpt.viewer.tev import TevStream

    return TevStream(a.tev, name)


def _finish_tev(tev, image) -> str | None:
    """Send the render's last image to tev and close the connection; the line that says so (None without
    --tev; a tev that went away has been warned about)."""
    if tev is None:
        return None
    try:
        tev.send(image, force=True)
    finally:
        tev.close()
    if tev.failed is not None:
        return None
    return f"sent {tev.sent} image{'s' if tev.sent != 1 else ''} to tev at {tev.host}:{tev.port} as {tev.name!r}"


def _samples(a: argparse.Namespace, pr, frames: int) -> str:
    """What the image holds, said once: ``N spp``, or with --max-frames what the accumulation made of the
    frames rendered (stopped early, restarted, or a moving average)."""
    done, acc = pr.sample_index, pr.accumulator
    if not a.max_frames or done <= a.max_frames and a.overflow != "stop":
        return f"{done} spp"
    if a.overflow == "stop":
        return f"{done} spp" if done >= frames else (f"{done} spp of the {frames} asked (--max-frames "
                                                     f"{a.max_frames} stopped the accumulation)")
    if a.overflow == "reset":
        return (f"{done} frames rendered, the image averages the last {acc.divisor} (--overflow reset starts "
                f"over every {a.max_frames})")
    return (f"{done} frames rendered, the image their exponential moving average over a window of "
            f"{a.max_frames} frames (--overflow ema)")


def _ms(value: float) -> str:
    return f"{value:.3f}" if value < 10 else f"{value:,.1f}"


def _table(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    """Lines of an aligned table: the first column left-aligned, the others right-aligned."""
    widths = [max(len(str(c)) for c in col) for col in zip(headers, *rows)]
    return ["  ".join(str(c).ljust(w) if i == 0 else str(c).rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
            .rstrip() for r in (headers, *rows)]


#: --stats' bounce table: its columns and the RenderStats.bounces keys they show (paths alive: the stages' rays
#: plus the tail's paths alive at the bounce, RenderStats.tail_alive).
BOUNCE_COLUMNS = (("bounce", "bounce"), ("paths alive", "alive"), ("in the tail", "tail_alive"), ("hits", "hits"),
                  ("misses", "misses"), ("shadow rays", "shadow_rays"), ("unoccluded", "unoccluded"),
                  ("taken by the tail", "tail"))


def bounce_rows(st) -> list[dict]:
    """The rows of ``st.bounces`` with ``alive`` (paths alive: the stages' rays plus the tail's paths at
    the bounce) and ``tail_alive``, continued past the stages' last bounce for the paths the tail
    (finish_paths) ran on; the stages' queues are 0 there."""
    tail = list(getattr(st, "tail_alive", None) or [])
    rows = []
    for b in range(max(len(st.bounces), len(tail))):
        row = dict(st.bounces[b]) if b < len(st.bounces) else {"bounce": b, "rays": 0, "hits": 0, "misses": 0,
                                                                 "shadow_rays": 0, "unoccluded": 0, "tail": 0}
        row["tail_alive"] = tail[b] if b < len(tail) else 0
        row["alive"] = row["rays"] + row["tail_alive"]
        rows.append(row)
    return rows


def stats_table(st) -> str:
    """``--stats``: the paths alive at each bounce (the wavefront integrator counts them, those its tail runs
    on included: :func:`bounce_rows`) and the time of each kernel, as short aligned tables; ``--stats-json``
    writes the raw rows."""
    lines = []
    if st.bounces:
        rows = [[f"{row[key]:,}" if key != "bounce" else str(row[key]) for _, key in BOUNCE_COLUMNS]
                for row in bounce_rows(st)]
        lines += _table([h for h, _ in BOUNCE_COLUMNS], rows)
        if any(row["tail"] for row in st.bounces):
            lines.append("(the tail: once few paths are left, one kernel, finish_paths, runs each to its end; "
                         "hits, misses and shadow rays count the other stages' queues only)")
    else:
        lines.append("paths per bounce: counted by the wavefront integrator only (--integrator wavefront)")
    lines.append("")
    kernels = sorted(st.kernels, key=lambda k: -k["total_ms"])
    rows = [[k["kernel"], f"{k['launches']:,}", _ms(k["total_ms"]), _ms(k["mean_ms"]), f"{k['share']:.0%}"]
            for k in kernels]
    rows.append(["all kernels", f"{sum(k['launches'] for k in kernels):,}",
                 _ms(sum(k["total_ms"] for k in kernels)), "", ""])
    lines += _table(["kernel", "launches", "total ms", "mean ms", "share"], rows)
    if st.memory:
        lines.append(f"wave of {st.memory['wave_size']:,} paths, {st.memory['bytes_per_path']} bytes each: "
                     f"{st.memory['path_state_bytes'] / 2**20:.1f} MiB of path state")
    return "\n".join(lines) + "\n"


def _write_stats_json(target: str, data: dict) -> None:
    """``--stats-json FILE``: the raw statistics as JSON (``-``: stdout)."""
    text = json.dumps(data, indent=1) + "\n"
    if target == "-":
        print(text, end="")
        return
    Path(target).write_text(text)


def _render_distributed(a: argparse.Namespace) -> int:
    """``render`` on a Dask cluster (pyclpt.distributed): the samples split into tasks, or the frames of a
    --sequence one task each (--orbit: independent views) or split by sample range (the running average)."""
    from pyclpt.common.image_io import check_output_path, write_image
    from pyclpt.distributed import DistributedRenderer, connect
    from pyclpt.distributed.cluster import import_distributed
    from pyclpt.scene.camera_path import CameraPath
    from pyclpt.scene.library import load

    if a.workers is not None and a.scheduler is not None:
        raise ValueError("give --workers N (a local cluster) or --scheduler ADDRESS (an existing one), not both")
    refused = {"--device": a.device is not None, "--aov": a.aov is not None, "--denoise oidn": a.denoise == "oidn",
               "--max-frames": bool(a.max_frames), "--stats": a.stats or a.stats_json is not None}
    bad = [k for k, v in refused.items() if v]
    if bad:
        why = {"--device": "each worker picks its own device (PYCLPT_DEVICE in its environment)",
               "--denoise oidn": "it denoises the running average on one machine (svgf and blend denoise "
                                 "the frames rendered on the cluster)",
               "--aov": "AOVs are rendered on one machine", "--max-frames": "it limits one accumulation",
               "--stats": "the statistics are per device"}
        raise ValueError(f"{bad[0]} does not combine with --workers/--scheduler: {why[bad[0]]}")
    if a.orbit is not None and not a.sequence and not a.denoise:
        raise ValueError("--orbit with --workers/--scheduler needs --sequence (every frame is its own view) "
                         "or --denoise")
    import_distributed()  # ImportError naming the extra; and Dask sets up its loggers on import
    if not a.verbose:  # Dask's own INFO lines (scheduler, nannies) only with -v
        logging.getLogger("distributed").setLevel(logging.ERROR)
    needs_scene = a.orbit is not None or a.spp is None and a.frames is None
    scene = load(a.scene, **dict(a.define)) if needs_scene else None
    name = scene.name if scene is not None else Path(a.scene).stem
    out = a.output or f"{name}.png"
    check_output_path(sequence_path(out, 0) if a.sequence else out)
    _drop_linear_exposure(a, out, None)
    spp = _check_spp(a, a.frames or a.spp or scene.spp)
    tev = _open_tev(a, Path(out).name)  # the final image only: the tasks' partial sums are not an image
    with connect(a.scheduler, a.workers) as client:
        t1 = time.perf_counter()
        workers = len(client.nthreads())
        dr = DistributedRenderer(client, a.scene, defines=dict(a.define), integrator=a.integrator, layout=a.layout,
                                 max_depth=a.max_depth, width=a.width, height=a.height, precision=a.precision)
        path = CameraPath.orbit(scene, a.orbit, spp) if a.orbit is not None else None
        if a.denoise:  # a frame a task, denoised here in frame order as they arrive
            images = []

            def denoised(k: int, image) -> None:
                if a.sequence:
                    write_image(sequence_path(out, k), image, exposure=a.exposure)
                    a.written = sequence_path(out, k)
                images[:] = [image]

            dr.render_denoised(spp, a.seed, camera_path=path, denoiser=a.denoise, on_frame=denoised,
                               progress=not a.quiet)
        elif a.sequence and path is not None:  # independent views: a frame a task
            images = dr.render_frames([path.camera(k) for k in range(spp)], 1, a.seed, progress=not a.quiet)
        elif a.sequence:  # the running average after every sample: sample ranges, added and written in order here
            images = []

            def averaged(k: int, image) -> None:
                write_image(sequence_path(out, k), image, exposure=a.exposure)
                a.written = sequence_path(out, k)
                images[:] = [image]

            dr.render_progressive(spp, a.seed, task_spp=a.task_spp, progress=not a.quiet, on_frame=averaged)
        else:
            images = [dr.render(spp, a.seed, task_spp=a.task_spp, tile=a.tile, progress=not a.quiet)]
        seconds = time.perf_counter() - t1
        dr.close()
    if a.sequence:
        # denoised and running-average frames are written as they come; independent views here
        for k, image in enumerate(images if path is not None and not a.denoise else []):
            write_image(sequence_path(out, k), image, exposure=a.exposure)
            a.written = sequence_path(out, k)
    else:
        write_image(out, images[0], exposure=a.exposure)
        a.written = out
    tev_line = _finish_tev(tev, images[-1])
    h, w = images[0].shape[:2]
    where = f"{workers} workers at {a.scheduler}" if a.scheduler else f"a local cluster of {workers} workers"
    print(f"{out}: {w}x{h}, {spp} {'frames' if a.sequence else 'spp'}, {a.integrator} on {where}: "
          f"{len(dr.parts)} tasks, render {seconds:.2f} s, total {time.perf_counter() - a.started:.2f} s")
    if a.sequence:
        print(f"wrote {spp} frames: {sequence_path(out, 0)} .. {sequence_path(out, spp - 1)}")
    if tev_line:
        print(tev_line)
    return 0


def _cmd_devices() -> int:
    from pyclpt.device.context import default_choice, list_devices

    devices = list_devices()
    chosen, why = default_choice(devices)
    for pi, di, d in devices:
        mark = "  [default]" if d == chosen else ""
        print(f"{pi}:{di}  {d.platform.name.strip()} / {d.name.strip()}  ({d.version.strip()}, "
              f"{d.max_compute_units} CUs, {d.global_mem_size // 2**20} MiB){mark}")
    print(f"default: {chosen.platform.name.strip()} / {chosen.name.strip()}: {why} (--device or PYCLPT_DEVICE "
          f"picks another)")
    return 0


def _cmd_warmup(a: argparse.Namespace) -> int:
    from pyclpt.common.logs import NOTICE_LOGGER
    from pyclpt.device.context import get_device
    from pyclpt.rendering.warmup import Skipped, variants, warm_up

    logging.getLogger(NOTICE_LOGGER).setLevel(logging.WARNING)  # each line below says what was compiled
    device = get_device(a.device)
    print(f"warming up on {device.name.strip()}", flush=True)
    compiled = []

    def show(item) -> None:
        if isinstance(item, Skipped):
            print(f"  {item.scene}: skipped ({item.reason})", flush=True)
            return
        compiled.append(item)
        print(f"  {item.scene} {item.variant}: {item.programs} programs ({item.built} new), compile "
              f"{item.compile_seconds:.2f} s, 1 spp render {item.render_seconds:.2f} s, total {item.seconds:.2f} s",
              flush=True)

    warm_up(a.scenes, device=device, variant_names=variants(a.wavefront, a.all_variants), on_result=show)
    print(f"warmed up {len(compiled)} scene variant{'s' if len(compiled) != 1 else ''} in "
          f"{time.perf_counter() - a.started:.2f} s: their first renders load the kernels from the drivers' caches")
    return 0


def _cmd_scenes() -> int:
    from pyclpt.scene.library import builtin_scenes

    for name, desc in builtin_scenes().items():
        print(f"{name:16s} {desc}")
    return 0


#: What ``pyclpt bench`` needs beyond pyclpt's own dependencies, and how to get it.
BENCH_HINT = 'pip install "pyclpt[bench]"'


def _require_bench_extra() -> None:
    """ImportError naming the ``bench`` extra where matplotlib (the report's plots) is missing: said at
    once, before a run of minutes that could not write its report."""
    try:
        import matplotlib  # noqa: F401
    except ImportError as exc:
        raise ImportError(f"pyclpt bench draws its plots with matplotlib, which is not installed here "
                          f"({exc}): {BENCH_HINT}") from None


def _cmd_bench(argv: list[str]) -> int:
    _require_bench_extra()
    try:
        from .bench.report import main as bench_main
    except ModuleNotFoundError as exc:
        if exc.name != f"{__package__}.bench":
            raise
        # a source checkout: bench/report/ sits beside pyclpt/ (installed: the subpackage pyclpt.bench.report)
        root = str(Path(__file__).resolve().parent.parent)
        if root not in sys.path:
            sys.path.insert(0, root)
        from bench.report import main as bench_main
    return bench_main(argv)


def _cmd_view(a: argparse.Namespace) -> int:
    from pyclpt.viewer import require_server

    require_server()  # before loading or compiling anything: says `pip install "pyclpt[viewer]"`
    from pyclpt.scene.library import load
    from pyclpt.viewer.server import Viewer, frame_size
    from pyclpt.viewer.session import RenderSession

    scene = load(a.scene, **dict(a.define))
    follow = a.width is None and a.height is None  # the frame follows the page's window, up to --max-size
    width, height = frame_size(scene, a.width, a.height, a.max_size)
    session = RenderSession(scene, width=width, height=height, spp_per_frame=a.spp_per_frame, max_depth=a.max_depth,
                            denoiser=a.denoiser, integrator=a.integrator, layout=a.layout, device=a.device,
                            seed=a.seed, exposure=a.exposure, view=a.view, output_dir=a.output_dir,
                            max_size=a.max_size if follow else None)
    viewer = Viewer(session, port=a.port).start()
    try:
        print(f"pyclpt view: {scene.name}, {width}x{height} on {session.pr.device.name.strip()}: {viewer.url} "
              f"(Ctrl-C stops)", flush=True)
        if not a.no_browser and not viewer.open_browser():
            print(f"pyclpt view: no browser could be opened here; open {viewer.url}", file=sys.stderr, flush=True)
        viewer.wait()
    finally:
        viewer.close()
    return 0


def _cmd_gpu_isa(a: argparse.Namespace) -> int:
    from pyclpt.gpu.report import default_scenes, markdown, run

    report = run(a.scenes or default_scenes(), a.output, targets=a.targets, every_variant=not a.quick,
                 device=a.device)
    print(markdown(report), end="")
    print(f"{a.output}: isa.json, isa.md, isa.png")
    return 1 if report.failures else 0


def _user_errors() -> tuple[type[BaseException], ...]:
    """What bad input (arguments, scene files, output paths, devices, memory) raises: reported in one
    line with exit status 1. Anything else is a bug in pyclpt and keeps its traceback."""
    import pyopencl as cl

    # ImportError: an optional extra that is not installed (--denoise oidn without pyoidn)
    return (OSError, ValueError, RuntimeError, MemoryError, OverflowError, ImportError, cl.Error)


def _message(exc: BaseException) -> str:
    """The exception's own message (pyclpt's errors name the file, element or setting), with the type's
    name where the message alone says too little (``math range error``)."""
    text = str(exc)
    if isinstance(exc, (OSError, ValueError, RuntimeError, MemoryError, ImportError)) and text:
        return text
    if type(exc).__module__.startswith("pyopencl"):
        return f"OpenCL: {text}"
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


#: A scene loader's list of ignored settings: at most this many lines without -v.
IGNORED_LINES = 12
#: One of those lines at most this long without -v.
IGNORED_WIDTH = 110


class LogFormatter(logging.Formatter):
    """The command line's log lines: ``pyclpt: message`` for pyclpt's loggers (``name: message`` for other
    libraries'); a scene loader's warning that carries the list of what it ignored (a record's
    ``ignored`` and ``origin``, pyclpt.scene.mitsuba_dict) as a heading and one short line per setting."""

    def __init__(self, verbose: bool = False) -> None:
        super().__init__()
        self.verbose = verbose

    def format(self, record: logging.LogRecord) -> str:
        name = "pyclpt" if record.name.split(".")[0] == "pyclpt" else record.name
        ignored = getattr(record, "ignored", None)
        if ignored:
            origin = str(getattr(record, "origin", "") or "")
            shown = list(ignored) if self.verbose else list(ignored)[:IGNORED_LINES]
            lines = [f"{name}: {origin or 'the scene'}: {len(ignored)} setting{'s' if len(ignored) != 1 else ''} "
                     f"not used by pyclpt:"]
            lines += [f"  {self._short(str(note), origin)}" for note in shown]
            if len(shown) < len(ignored):
                lines.append(f"  ... and {len(ignored) - len(shown)} more (-v lists them all)")
            return "\n".join(lines)
        text = record.getMessage()
        if record.exc_info:
            text = f"{text}\n{self.formatException(record.exc_info)}"
        return f"{name}: {text}"

    def _short(self, note: str, origin: str) -> str:
        if origin:
            note = note.replace(f"({origin}:", "(line ")
        if not self.verbose and len(note) > IGNORED_WIDTH:
            note = note[:IGNORED_WIDTH - 1] + "…"
        return note


def _setup_logging(a: argparse.Namespace) -> None:
    """Log lines on stderr as ``pyclpt: message``: warnings, the compile message (unless --quiet), and with
    -v everything at INFO (the device chosen, compile times, progress details)."""
    from pyclpt.common.logs import NOTICE_LOGGER

    a.notice_level = logging.getLogger(NOTICE_LOGGER).level  # restored when the command ends
    handler = logging.StreamHandler()
    handler.setFormatter(LogFormatter(verbose=a.verbose))
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING, handlers=[handler])
    if not getattr(a, "quiet", False):
        logging.getLogger(NOTICE_LOGGER).setLevel(logging.INFO)
    if not a.verbose:  # the OpenCL compilers' remarks (Intel's runtime reports some for every build)
        warnings.filterwarnings("ignore", message="Non-empty compiler output")


def main(argv: Sequence[str] | None = None) -> int:
    started = time.perf_counter()
    parser = build_parser()
    a, rest = parser.parse_known_args(argv)
    if rest and a.command != "bench":
        parser.error(f"unrecognized arguments: {' '.join(rest)}")
    _setup_logging(a)
    a.started = started
    a.written = None
    previous = _catch_sigterm()
    try:
        if a.command == "bench":
            return _cmd_bench(rest)
        if a.command == "render":
            return _cmd_render(a)
        if a.command == "devices":
            return _cmd_devices()
        if a.command == "gpu-isa":
            return _cmd_gpu_isa(a)
        if a.command == "warmup":
            return _cmd_warmup(a)
        if a.command == "view":
            return _cmd_view(a)
        return _cmd_scenes()
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM (Terminated)
        what = "terminated" if isinstance(exc, Terminated) else "interrupted"
        done = f"{a.written} was written" if a.written else "nothing written"
        print(f"pyclpt: {what}; {done}" if a.command == "render" else f"pyclpt: {what}", file=sys.stderr)
        return EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED
    except _user_errors() as exc:
        print(f"pyclpt: error: {_message(exc)}", file=sys.stderr)
        return 1
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        logging.getLogger("pyclpt.notice").setLevel(a.notice_level)


if __name__ == "__main__":
    sys.exit(main())
