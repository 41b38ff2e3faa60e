"""Where does a GPU's frame time go? (docs/gpu.md, "Measured on an NVIDIA H200").

Three measurements for a GPU machine (run beside ``.gpu/check.sh`` of ../shared/gpu, whose environment
registers NVIDIA's OpenCL driver), also runnable on any OpenCL device:

- ``launch``: the host cost of OpenCL calls through pyopencl (an enqueue, a kernel call that sets its
  arguments, a blocking 4-byte read, a fill), on a profiling and a plain queue. On an H200 with NVIDIA's
  driver 580: 9-15 us an enqueue, 14-21 us a blocking read, against 1.3-1.8 us and 46-62 us on PoCL.
- ``variants SCENE...``: ms per 1-spp frame (wall and device time) of the megakernel and the wavefront
  with several tail and wave sizes, at --size (default 1280x720).
- ``regcap SCENE...``: the same frames with NVIDIA's register cap (``-cl-nv-maxrregcount``) on the shading
  stages (``process_hit``, ``sample_bsdf``) or on the megakernel and ``finish_paths``: whether fewer registers
  (more resident warps, some spilling) make them faster on the GPU; the images must not change.
- ``ptx SCENE...``: the PTX NVIDIA's OpenCL compiler makes of each kernel (clGetProgramInfo's binaries),
  written to --out, with ``ptxas -arch=sm_90 -v``'s registers and stack per kernel where ptxas is on the
  PATH (or run it later where it is: ``ptxas -arch=sm_90 -v K.ptx -o /dev/null``).

Usage: python -m bench.gpu.diagnostics {launch,variants,regcap,ptx} [SCENE ...] [--size WxH] [--out DIR]."""
from __future__ import annotations

import argparse
import contextlib
import re
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

import pyclpt
from pyclpt.device.context import fill_buffer

TRIVIAL = "__kernel void k(__global int *a, int n) { int i = get_global_id(0); if (i < n) a[i] += 1; }"


def launch_costs(device: pyclpt.Device, n: int = 2000) -> dict[str, dict[str, float]]:
    """Microseconds per OpenCL call (host wall clock) on a profiling queue and on a plain one."""
    ctx = device.context
    prg = cl.Program(ctx, TRIVIAL).build()
    buf = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, 4 << 20)
    out = np.zeros(1, np.int32)
    result = {}
    for label, props in (("profiling", cl.command_queue_properties.PROFILING_ENABLE), ("plain", 0)):
        q = cl.CommandQueue(ctx, device.device, properties=props)
        k = cl.Kernel(prg, "k")
        k.set_args(buf, np.int32(64))
        for _ in range(50):
            cl.enqueue_nd_range_kernel(q, k, (64,), (64,))
        q.finish()
        row = {}
        t = time.perf_counter()
        for _ in range(n):
            cl.enqueue_nd_range_kernel(q, k, (64,), (64,))
        row["enqueue"] = (time.perf_counter() - t) / n
        q.finish()
        t = time.perf_counter()
        for _ in range(n):
            k(q, (64,), (64,), buf, np.int32(64))
        q.finish()
        row["kernel call (sets 2 arguments)"] = (time.perf_counter() - t) / n
        t = time.perf_counter()
        for _ in range(n // 10):
            cl.enqueue_copy(q, out, buf)
        row["blocking 4-byte read"] = (time.perf_counter() - t) / (n // 10)
        t = time.perf_counter()
        for _ in range(n // 10):
            fill_buffer(q, buf, np.int32(0), 0, 256)
        q.finish()
        row["fill 256 bytes"] = (time.perf_counter() - t) / (n // 10)
        result[label] = {what: 1e6 * s for what, s in row.items()}
    return result


def _frame_times(r: pyclpt.Renderer, frames: int) -> dict[str, float]:
    """Median wall-clock and device ms of ``frames`` 1-spp frames of renderer r (seeds 10, 11, ...)."""
    walls, devices = [], []
    for i in range(frames):
        r.integrator.profile.clear()
        t = time.perf_counter()
        r.render(1, seed=10 + i, progress=False)
        r.device.queue.finish()
        walls.append(time.perf_counter() - t)
        devices.append(sum(row["total_ms"] for row in r.integrator.profile.table()))
    return {"wall_ms": 1e3 * float(np.median(walls)), "device_ms": float(np.median(devices))}


VARIANTS = (("megakernel", {}), ("wavefront", {}), ("wavefront", {"schedule": "pipelined"}),
            ("wavefront", {"tail_paths": 1 << 16}),
            ("wavefront", {"tail_paths": 1 << 13}), ("wavefront", {"tail_paths": 0}),
            ("wavefront", {"layout": "aos"}), ("wavefront", {"wave_size": 1 << 18}))


def variants(scene_name: str, width: int, height: int, depths=(3, 64), frames: int = 5) -> list[dict]:
    """Median wall and device ms per 1-spp frame of each of VARIANTS."""
    scene = pyclpt.load(scene_name)
    rows = []
    for depth in depths:
        for integrator, options in VARIANTS:
            r = pyclpt.Renderer(scene, integrator=integrator, max_depth=depth, width=width, height=height, **options)
            r.render(1, seed=1, progress=False)
            rows.append({"scene": scene_name, "depth": depth, "integrator": integrator, "options": options,
                         "wave": getattr(r.integrator, "capacity", None), **_frame_times(r, frames)})
    return rows


#: (label, register cap, the programs it applies to: a substring of their first cl/ file)
REGCAPS = (("as built", 0, ()), ("shading stages <= 64", 64, ("process_hit", "sample_bsdf")),
           ("shading stages <= 80", 80, ("process_hit", "sample_bsdf")),
           ("megakernel, finish_paths <= 96", 96, ("megakernel", "finish_paths")),
           ("megakernel, finish_paths <= 64", 64, ("megakernel", "finish_paths")))


@contextlib.contextmanager
def _register_cap(cap: int, targets: tuple[str, ...]):
    """Add ``-cl-nv-maxrregcount=cap`` to the builds of the integrators' programs whose first file names one of
    ``targets`` (0: no cap), for the renderers made inside the block."""
    from pyclpt.integrators import megakernel, wavefront

    real = megakernel.build_program

    def capped(device, files=(), **kw):
        if cap and any(t in (files[0] if files else "") for t in targets):
            kw["options"] = (*kw.get("options", ()), f"-cl-nv-maxrregcount={cap}")
        return real(device, files, **kw)

    megakernel.build_program = wavefront.build_program = capped
    try:
        yield
    finally:
        megakernel.build_program = wavefront.build_program = real


def register_caps(scene_name: str, width: int, height: int, depths=(3, 64), frames: int = 5) -> list[dict]:
    """Median wall and device ms per 1-spp frame of the megakernel and the wavefront SoA under each of REGCAPS,
    and whether the image equals the uncapped one."""
    scene = pyclpt.load(scene_name)
    rows, images = [], {}
    for label, cap, targets in REGCAPS:
        for depth in depths:
            for integrator in ("megakernel", "wavefront"):
                try:
                    with _register_cap(cap, targets):
                        r = pyclpt.Renderer(scene, integrator=integrator, max_depth=depth, width=width,
                                            height=height)
                except pyclpt.KernelBuildError as exc:  # a driver without cl_nv_compiler_options
                    rows.append({"scene": scene_name, "cap": label, "depth": depth, "integrator": integrator,
                                 "error": str(exc).splitlines()[0]})
                    continue
                first = r.render(1, seed=1, progress=False)
                same = images.setdefault((depth, integrator), first)
                rows.append({"scene": scene_name, "cap": label, "depth": depth, "integrator": integrator,
                             **_frame_times(r, frames), "same_image": bool(np.array_equal(same, first))})
    return rows


PTXAS_LINE = re.compile(r"Used (\d+) registers|(\d+) bytes stack frame, (\d+) bytes spill stores")


def driver_ptx(scene_name: str, out: Path) -> list[dict]:
    """Write the driver's PTX of the megakernel and the wavefront's stages for the scene; registers and
    stack from ptxas -v where it is installed."""
    scene = pyclpt.load(scene_name)
    folder = out / re.sub(r"[^A-Za-z0-9_.-]+", "_", scene_name).strip("._")
    folder.mkdir(parents=True, exist_ok=True)
    mk = pyclpt.Renderer(scene, integrator="megakernel", max_depth=8, width=64, height=64)
    wf = pyclpt.Renderer(scene, integrator="wavefront", max_depth=8, width=64, height=64)
    ptxas = shutil.which("ptxas")
    rows = []
    for name, kernel in {"megakernel": mk.integrator.kernel, **wf.integrator.kernels}.items():
        binary = kernel.get_info(cl.kernel_info.PROGRAM).get_info(cl.program_info.BINARIES)[0]
        path = folder / f"{name}.ptx"
        path.write_bytes(binary.rstrip(b"\0"))  # NVIDIA's binary ends in NULs, which ptxas refuses
        row = {"scene": scene_name, "kernel": name, "ptx_bytes": len(binary)}
        if ptxas and binary.lstrip().startswith(b"//"):
            log = subprocess.run([ptxas, "-arch=sm_90", "-v", str(path), "-o", "/dev/null"], capture_output=True,
                                 text=True).stderr
            for m in PTXAS_LINE.finditer(log):
                if m.group(1):
                    row["registers"] = int(m.group(1))
                else:
                    row["stack_bytes"], row["spill_bytes"] = int(m.group(2)), int(m.group(3))
        rows.append(row)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("launch", "variants", "regcap", "ptx"))
    ap.add_argument("scenes", nargs="*", default=["cornell-box"])
    ap.add_argument("--size", default="1280x720", help="WxH of the variants' frames")
    ap.add_argument("--out", default="gpu-ptx", help="folder for the PTX files")
    args = ap.parse_args()
    device = pyclpt.get_device(None)
    print(f"device: {device.name}")
    if args.what == "launch":
        for queue, row in launch_costs(device).items():
            print(f"{queue} queue: " + ", ".join(f"{what} {us:.1f} us" for what, us in row.items()))
    elif args.what == "variants":
        width, height = (int(v) for v in args.size.lower().split("x"))
        for name in args.scenes:
            base = None
            for row in variants(name, width, height):
                base = row["wall_ms"] if row["integrator"] == "megakernel" else base
                print(f"{name} depth {row['depth']} {row['integrator']} {row['options']} (wave {row['wave']}): "
                      f"wall {row['wall_ms']:.2f} ms, device {row['device_ms']:.2f} ms, "
                      f"speed-up {base / row['wall_ms']:.2f}x")
    elif args.what == "regcap":
        width, height = (int(v) for v in args.size.lower().split("x"))
        for name in args.scenes:
            for row in register_caps(name, width, height):
                if "error" in row:
                    print(f"{name} depth {row['depth']} {row['integrator']} [{row['cap']}]: {row['error']}")
                    continue
                print(f"{name} depth {row['depth']} {row['integrator']} [{row['cap']}]: wall {row['wall_ms']:.2f} ms, "
                      f"device {row['device_ms']:.2f} ms, same image {row['same_image']}", flush=True)
    else:
        for name in args.scenes:
            for row in driver_ptx(name, Path(args.out)):
                print(row)


if __name__ == "__main__":
    main()
