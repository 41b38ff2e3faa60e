"""Mitsuba 3's side of ``bench/evaluations/gradients.py``: run by the Python of a separate Mitsuba environment (never
imported by pyclpt; imports mitsuba, drjit and bench/report/mitsuba_driver.py), from the repository's root:

    python -m bench.peers.mitsuba_gradients --scene cornell-box.json --param red.reflectance.value
                                --spp 16 --max-depth 8 --width 256 --height 256 [--seeds 4] [--repeats 3]

Loads the scene as ``mitsuba_driver.py`` does (integrator ``prb`` with ``--max-depth`` and rr_depth 3,
box filter) and prints one JSON object:
  * with ``--translate SHAPE`` instead: only ``timing``, of the gradient with respect to SHAPE's translation
    along x (its vertex positions moved by a differentiable offset; the scene loaded without Mitsuba's shape
    merging, so that SHAPE stays its own mesh) by ``prb_projective`` (the interior term and the boundary terms
    of visibility), and the primal render without gradients, for issue 25's speed figure beside pyclpt's;
  * ``forward``: for each of ``--seeds`` seeds, the per-channel sums of the forward-mode gradient
    image with respect to ``--param`` along (1, 1, 1) (``dr.forward``);
  * ``timing``: medians over ``--repeats`` of the primal render (``mi.render`` and evaluation), the
    backward pass of an L2 loss (``dr.backward`` and evaluation of the parameter's gradient) and the
    whole step, in seconds, after one untimed round (Dr.Jit's kernel compilation).
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", type=Path, required=True)
    ap.add_argument("--param", default="red.reflectance.value")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--max-depth", type=int, default=8)
    ap.add_argument("--rr-depth", type=int, default=3)
    ap.add_argument("--width", type=int, default=256)
    ap.add_argument("--height", type=int, default=256)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--translate", default=None, metavar="SHAPE", help="time the gradient of SHAPE's translation")
    a = ap.parse_args(argv)
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(a.variant)
    from bench.report import mitsuba_driver

    if a.translate:
        print(json.dumps(translation_timing(mi, dr, mitsuba_driver, a)))
        return 0

    scene = mitsuba_driver.load_json(mi, a.scene, a)
    integrator = mi.load_dict({"type": "prb", "max_depth": a.max_depth, "rr_depth": a.rr_depth})
    params = mi.traverse(scene)
    out: dict = {"mitsuba_version": mi.__version__, "variant": a.variant, "forward": []}
    for seed in range(a.seeds):
        dr.enable_grad(params[a.param])
        params.update()
        image = mi.render(scene, params, spp=a.spp, seed=1000 + seed, integrator=integrator)
        dr.forward(params[a.param])
        grad = dr.grad(image)
        flat, n = grad.array, a.width * a.height
        channels = grad.shape[2]
        out["forward"].append([float(dr.sum(dr.gather(mi.Float, flat, dr.arange(mi.UInt32, n) * channels + c))[0])
                               for c in range(3)])
        dr.disable_grad(params[a.param])
        params.update()
    reference = mi.render(scene, spp=a.spp, seed=99, integrator=integrator)
    dr.eval(reference)
    times: dict[str, list[float]] = {"primal_s": [], "backward_s": [], "step_s": []}
    for k in range(a.repeats + 1):
        dr.enable_grad(params[a.param])
        params.update()
        t0 = time.perf_counter()
        image = mi.render(scene, params, spp=a.spp, seed=2 * k, seed_grad=2 * k + 1, integrator=integrator)
        dr.eval(image)
        dr.sync_thread()  # the LLVM backend runs kernels asynchronously
        t1 = time.perf_counter()
        loss = dr.mean(dr.square(image - reference), axis=None)
        dr.backward(loss)
        g = dr.grad(params[a.param])
        dr.eval(g)
        dr.sync_thread()
        t2 = time.perf_counter()
        dr.disable_grad(params[a.param])
        params.update()
        if k:  # the first round compiles
            times["primal_s"].append(t1 - t0)
            times["backward_s"].append(t2 - t1)
            times["step_s"].append(t2 - t0)
    out["timing"] = {k: statistics.median(v) for k, v in times.items()}
    print(json.dumps(out))
    return 0


def translation_timing(mi, dr, mitsuba_driver, a: argparse.Namespace) -> dict:
    """Primal, backward and step times of an L2 loss's gradient with respect to a shape's x translation,
    ``prb_projective`` (medians over ``--repeats`` after one untimed round)."""
    scene = mitsuba_driver.load_json(mi, a.scene, a, optimize=False)
    integrator = mi.load_dict({"type": "prb_projective", "max_depth": a.max_depth, "rr_depth": a.rr_depth})
    params = mi.traverse(scene)
    key = f"{a.translate}.vertex_positions"
    base = mi.Point3f(dr.unravel(mi.Point3f, params[key]))
    reference = mi.render(scene, spp=a.spp, seed=99, integrator=integrator)
    dr.eval(reference)
    times: dict[str, list[float]] = {"primal_s": [], "backward_s": [], "step_s": []}
    for k in range(a.repeats + 1):
        offset = mi.Float(0.01)
        dr.enable_grad(offset)
        params[key] = dr.ravel(base + mi.Vector3f(offset, 0.0, 0.0))
        params.update()
        t0 = time.perf_counter()
        image = mi.render(scene, params, spp=a.spp, seed=2 * k, seed_grad=2 * k + 1, integrator=integrator)
        dr.eval(image)
        dr.sync_thread()
        t1 = time.perf_counter()
        loss = dr.mean(dr.square(image - reference), axis=None)
        dr.backward(loss)
        g = dr.grad(offset)
        dr.eval(g)
        dr.sync_thread()
        t2 = time.perf_counter()
        if k:
            times["primal_s"].append(t1 - t0)
            times["backward_s"].append(t2 - t1)
            times["step_s"].append(t2 - t0)
    params[key] = dr.ravel(base)
    params.update()
    primal = mi.render(scene, spp=a.spp, seed=7, integrator=mi.load_dict({"type": "path", "max_depth": a.max_depth,
                                                                           "rr_depth": a.rr_depth}))
    dr.eval(primal)
    plain: list[float] = []
    for k in range(a.repeats):
        t0 = time.perf_counter()
        dr.eval(mi.render(scene, spp=a.spp, seed=10 + k, integrator=integrator))
        dr.sync_thread()
        plain.append(time.perf_counter() - t0)
    out = {k: statistics.median(v) for k, v in times.items()}
    out["primal_no_grad_s"] = statistics.median(plain)
    return {"mitsuba_version": mi.__version__, "variant": a.variant, "integrator": "prb_projective",
            "param": f"{a.translate} translation x", "timing": out}


if __name__ == "__main__":
    raise SystemExit(main())
