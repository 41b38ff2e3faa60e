"""The ``pyclpt`` command line: render, devices, scenes."""
from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from collections.abc import Sequence
from pathlib import Path


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


_positive = _int_in(1, None)
_depth = _int_in(-1, None, " (-1 = unlimited)")
_seed = _int_in(0, 2**32)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pyclpt", description="OpenCL wavefront path tracer")
    p.add_argument("-v", "--verbose", action="store_true", help="log compile times and progress details")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a scene to an image file")
    r.add_argument("scene", help="built-in scene name (see `pyclpt scenes`) or scene file")
    r.add_argument("-o", "--output", default=None, help="output image (.exr linear; .png/.jpg sRGB); "
                                                        "default SCENE.png")
    r.add_argument("--spp", type=_positive, default=None, help="samples per pixel (default: the scene's)")
    r.add_argument("--max-depth", type=_depth, default=None, help="Mitsuba's max_depth; -1 = unlimited")
    r.add_argument("--width", type=_positive, default=None)
    r.add_argument("--height", type=_positive, default=None)
    r.add_argument("--seed", type=_seed, default=0)
    r.add_argument("--integrator", choices=("megakernel", "wavefront"), default="megakernel")
    r.add_argument("--layout", choices=("soa", "aos"), default="soa", help="wavefront path-state layout")
    r.add_argument("--device", default=None, help="OpenCL device: pocl, gpu, cpu, P:D or a name substring")
    r.add_argument("--exposure", type=float, default=0.0, help="exposure in stops for PNG/JPEG output")
    r.add_argument("--stats", action="store_true", help="print per-kernel and per-bounce statistics")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    sub.add_parser("devices", help="list OpenCL platforms and devices")
    sub.add_parser("scenes", help="list built-in scenes")
    return p


def _cmd_render(a: argparse.Namespace) -> int:
    from .image_io import write_image
    from .renderer import Renderer
    from .scene_library import load

    scene = load(a.scene)
    out = a.output or f"{scene.name}.png"
    # Fail before a possibly long render rather than when writing its result.
    if not Path(out).suffix:
        raise ValueError(f"{out}: no file extension to choose the image format from (.exr, .png, .jpg)")
    if not Path(out).resolve().parent.is_dir():
        raise OSError(f"{out}: the output folder {Path(out).resolve().parent} does not exist")
    t0 = time.perf_counter()
    r = Renderer(scene, integrator=a.integrator, layout=a.layout, max_depth=a.max_depth,
                 width=a.width, height=a.height, device=a.device)
    spp = a.spp or scene.spp
    image = r.render(spp, seed=a.seed, progress=False if a.quiet else None)
    write_image(out, image, exposure=a.exposure)
    st = r.stats
    print(f"{out}: {r.width}x{r.height}, {spp} spp, max depth {r.max_depth}, {a.integrator}"
          f"{'/' + a.layout if a.integrator == 'wavefront' else ''} on {r.device.name}: "
          f"render {st.seconds:.2f} s, compile {st.compile_seconds:.2f} s, setup {st.setup_seconds:.2f} s, "
          f"total {time.perf_counter() - t0:.2f} s")
    if st.dropped_samples:
        print(f"dropped {st.dropped_samples} NaN/inf samples")
    if a.stats:
        print(json.dumps({"kernels": st.kernels, "bounces": st.bounces, "memory": st.memory,
                          "dropped_samples": st.dropped_samples}, indent=1))
    return 0


def _cmd_devices() -> int:
    from .device import list_devices

    for pi, di, d in list_devices():
        print(f"{pi}:{di}  {d.platform.name.strip()} / {d.name.strip()}  ({d.version.strip()}, "
              f"{d.max_compute_units} CUs, {d.global_mem_size // 2**20} MiB)")
    return 0


def _cmd_scenes() -> int:
    from .scene_library import builtin_scenes

    for name, desc in builtin_scenes().items():
        print(f"{name:16s} {desc}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    a = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING, format="%(name)s: %(message)s")
    try:
        if a.command == "render":
            return _cmd_render(a)
        if a.command == "devices":
            return _cmd_devices()
        return _cmd_scenes()
    except (OSError, ValueError, RuntimeError, MemoryError) as exc:
        print(f"pyclpt: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
