"""The SVGF denoiser's passes: device time per pass at 1280x720, and the quality measurements behind
the defaults of :class:`pyclpt.denoise.DenoiserSettings` (docs/denoising-passes.md).

    python -m bench.evaluations.denoise_passes time [--devices pocl intel] [--size 1280x720] [--frames 9]
    python -m bench.evaluations.denoise_passes quality [--device pocl] [--seeds 3] [--set feedback_tap=-1,0,1 ...]
    python -m bench.evaluations.denoise_passes lighting [--set clip_gamma=-1,1,2,3 ...]

``time``: a static synthetic frame (noisy colour, a G-buffer with two materials and sub-pixel motion,
so every pass does its steady-state work), a few warm-up frames, then the median over ``--frames``
frames of each pass's OpenCL profiling time (the a-trous iterations summed).

``quality``: the static synthetic scene of :func:`scene` (a smooth illumination with a shadow edge
inside one surface, an albedo checker, a nearer box of another material), frames = truth x
Gamma(0.5, 2) noise (mean 1, relative variance 2; one draw per pixel, as a path's throughput is),
relMSE against the truth after 1, 2, 4, 8, 16, 32 frames, beside the plain average of the same frames;
each ``--set NAME=V1,V2`` row varies one setting from the defaults.

``lighting``: the same scene converged for 24 frames, then its illumination scaled by 0.25 (a light
switched off): relMSE of the frames after the change, which the fast-history clipping shortens.
"""
from __future__ import annotations

import argparse
import dataclasses
import statistics
from collections.abc import Sequence

import numpy as np

import pyclpt
from pyclpt.denoise import Denoiser, DenoiserSettings
from pyclpt.denoise.gbuffer import build_aovs
from pyclpt.denoise.svgf import Svgf
from pyclpt.device.context import upload

FRAMES = (1, 2, 4, 8, 16, 32)


def scene(width: int, height: int) -> dict[str, np.ndarray]:
    """The synthetic static scene: truth colour and its G-buffer (numpy, float32)."""
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    u, v = xx / width, yy / height
    box = (u > 0.55) & (u < 0.85) & (v > 0.25) & (v < 0.75)
    illum = 0.25 + 0.75 * np.exp(-((u - 0.3) ** 2 + (v - 0.4) ** 2) / 0.08)
    illum = np.where((u < 0.5) & (v > 0.6), illum * 0.3, illum)  # a hard shadow edge on the floor
    illum = np.where(box, 0.6 + 0.3 * v, illum)
    tint = np.stack([np.ones_like(u), 0.9 + 0.1 * u, 0.8 + 0.2 * v], axis=-1)
    checker = ((xx // 6 + yy // 6) % 2)[..., None]
    albedo = np.where(checker == 0, [0.8, 0.6, 0.4], [0.3, 0.5, 0.7]).astype(np.float32)
    albedo = np.where(box[..., None], [0.7, 0.7, 0.7], albedo).astype(np.float32)
    truth = (illum[..., None] * tint * albedo).astype(np.float32)
    depth = np.where(box, 4.0, 10.0 + 2.0 * v).astype(np.float32)
    normal = np.zeros((height, width, 3), np.float32)
    normal[..., 1] = 1.0
    normal[box] = [0.0, 0.0, -1.0]
    material = np.where(box, 1, 0).astype(np.int32)
    return {"truth": truth, "albedo": albedo, "normal": normal, "depth": depth, "material_id": material}


def rel_mse(x: np.ndarray, ref: np.ndarray) -> float:
    return float(np.mean((x.astype(np.float64) - ref) ** 2 / (ref.astype(np.float64) ** 2 + 1e-2)))


def noisy(truth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return (truth * rng.gamma(0.5, 2.0, size=truth.shape[:2] + (1,))).astype(np.float32)


def converge(device, settings: DenoiserSettings, width: int, height: int, seed: int,
             frames: Sequence[int] = FRAMES) -> tuple[dict[int, float], dict[int, float]]:
    """relMSE of the denoised frame and of the plain average after each count in ``frames``."""
    sc = scene(width, height)
    rng = np.random.default_rng(seed)
    d = Denoiser(device, width, height, settings=settings)
    total = np.zeros_like(sc["truth"], dtype=np.float64)
    den, avg = {}, {}
    for k in range(1, max(frames) + 1):
        frame = noisy(sc["truth"], rng)
        total += frame
        out = d.denoise(frame, sc["albedo"], sc["normal"], sc["depth"], material_id=sc["material_id"])
        if k in frames:
            den[k] = rel_mse(out, sc["truth"])
            avg[k] = rel_mse(total / k, sc["truth"])
    return den, avg


def _parse_sets(items: Sequence[str]) -> list[tuple[str, object]]:
    rows: list[tuple[str, object]] = []
    kinds = {f.name: f.type for f in dataclasses.fields(DenoiserSettings)}
    for item in items:
        name, _, values = item.partition("=")
        if name not in kinds:
            raise SystemExit(f"unknown setting {name!r}; settings: {', '.join(kinds)}")
        for text in values.split(","):
            t = str(kinds[name])
            value: object = (text.lower() in ("1", "true", "yes")) if "bool" in t else \
                int(text) if "int" in t else float(text)
            rows.append((name, value))
    return rows


def quality(args: argparse.Namespace) -> None:
    device = pyclpt.get_device(args.device)
    w, h = (int(x) for x in args.size.split("x"))
    rows = [("defaults", None)] + _parse_sets(args.set)
    print(f"relMSE x 1e3 after N frames, {w}x{h}, mean of {args.seeds} seeds")
    print(f"{'setting':28s} " + " ".join(f"N={n:<6d}" for n in FRAMES))
    shown_avg = False
    for name, value in rows:
        settings = DenoiserSettings() if value is None else dataclasses.replace(DenoiserSettings(), **{name: value})
        runs = [converge(device, settings, w, h, seed) for seed in range(args.seeds)]
        den = {n: statistics.mean(r[0][n] for r in runs) for n in FRAMES}
        if not shown_avg:
            avg = {n: statistics.mean(r[1][n] for r in runs) for n in FRAMES}
            print(f"{'plain average':28s} " + " ".join(f"{1e3 * avg[n]:<8.2f}" for n in FRAMES))
            shown_avg = True
        label = "defaults" if value is None else f"{name}={value}"
        print(f"{label:28s} " + " ".join(f"{1e3 * den[n]:<8.2f}" for n in FRAMES), flush=True)


def lighting(args: argparse.Namespace) -> None:
    device = pyclpt.get_device(args.device)
    w, h = (int(x) for x in args.size.split("x"))
    rows = [("defaults", None)] + _parse_sets(args.set)
    after = (1, 2, 4, 8, 16)
    print(f"relMSE x 1e3 k frames after the illumination drops to 0.25x (24 frames converged), {w}x{h}")
    print(f"{'setting':28s} " + " ".join(f"k={k:<6d}" for k in after))
    for name, value in rows:
        settings = DenoiserSettings() if value is None else dataclasses.replace(DenoiserSettings(), **{name: value})
        res = {k: [] for k in after}
        for seed in range(args.seeds):
            sc = scene(w, h)
            rng = np.random.default_rng(seed)
            d = Denoiser(device, w, h, settings=settings)
            gb = (sc["albedo"], sc["normal"], sc["depth"])
            for _ in range(24):
                d.denoise(noisy(sc["truth"], rng), *gb, material_id=sc["material_id"])
            dark = sc["truth"] * 0.25
            for k in range(1, max(after) + 1):
                out = d.denoise(noisy(dark, rng), *gb, material_id=sc["material_id"])
                if k in after:
                    res[k].append(rel_mse(out, dark))
        label = "defaults" if value is None else f"{name}={value}"
        print(f"{label:28s} " + " ".join(f"{1e3 * statistics.mean(res[k]):<8.2f}" for k in after), flush=True)


def time_passes(args: argparse.Namespace) -> None:
    w, h = (int(x) for x in args.size.split("x"))
    for name in args.devices:
        device = pyclpt.get_device(name)
        sc = scene(w, h)
        rng = np.random.default_rng(0)
        motion = rng.uniform(-0.3, 0.3, (h, w, 2)).astype(np.float32)
        aovs = upload(device, build_aovs(sc["albedo"], sc["normal"], sc["depth"], motion, sc["material_id"]),
                      "bench AOVs")
        color = upload(device, noisy(sc["truth"], rng), "bench colour")
        svgf = Svgf(device, w, h)
        for _ in range(args.warmup):
            svgf.run(color, aovs)
        device.queue.finish()
        svgf.profile.clear()
        for _ in range(args.frames):
            svgf.run(color, aovs)
        device.queue.finish()
        per: dict[str, float] = {}
        for kernel, events in svgf.profile.events.items():
            ms = [(e.profile.end - e.profile.start) * 1e-6 for e in events]
            k = len(ms) // args.frames
            per[kernel] = statistics.median(sum(ms[i:i + k]) for i in range(0, len(ms), k))
        total = sum(per.values())
        print(f"{device.name}, {w}x{h}, median of {args.frames} frames (ms): "
              + ", ".join(f"{k} {v:.1f}" for k, v in per.items()) + f"; total {total:.1f}", flush=True)


def main(argv: Sequence[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="python -m bench.evaluations.denoise_passes", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    t = sub.add_parser("time", help="device time per pass")
    t.add_argument("--devices", nargs="+", default=["pocl", "intel"])
    t.add_argument("--size", default="1280x720")
    t.add_argument("--frames", type=int, default=9)
    t.add_argument("--warmup", type=int, default=4)
    for name, fn in (("quality", quality), ("lighting", lighting)):
        q = sub.add_parser(name, help=f"{name} sweeps on the synthetic scene")
        q.add_argument("--device", default="pocl")
        q.add_argument("--size", default="96x64")
        q.add_argument("--seeds", type=int, default=3)
        q.add_argument("--set", nargs="*", default=[], help="NAME=V1,V2: a row per value")
        q.set_defaults(fn=fn)
    t.set_defaults(fn=time_passes)
    args = p.parse_args(argv)
    args.fn(args)


if __name__ == "__main__":
    main()
