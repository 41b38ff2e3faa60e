"""Differentiable rendering's figures (docs/differentiable.md): speed of the backward pass against the
primal render, memory against spp, and a cross-check of the forward gradient with Mitsuba 3's ``prb``.

    python -m bench.evaluations.gradients [--out docs/differentiable] [--repeats 5] [--mitsuba-python PATH]

* **timing** (the issue's setting: the built-in cornell-box, 256x256, 16 spp, max_depth 8, the gradient
  with respect to one reflectance, ``red.reflectance.value``): the primal render (``Renderer.render``,
  megakernel), the backward pass (``render_backward``) and a full step (both), medians over
  ``--repeats`` rounds after a warm-up (compilation is reported apart), and their ratios; the same with
  every differentiable appearance parameter of the scene; and the small box's pose (``small-box.to_world``: the
  interior term of moving geometry alone, then with the boundary terms of visibility);
* **memory**: the device bytes the gradient renderer holds (scene, film batch, gradient buffers) and the
  peak resident memory of a process that runs one backward pass (on a CPU device the device memory is
  host memory), for spp 16, 64 and 256;
* **Mitsuba 3** (when its Python is given: ``--mitsuba-python`` or ``$PYCLPT_MITSUBA_PYTHON``, with
  ``DRJIT_LIBLLVM_PATH`` set): per-channel sums of the forward gradient image with respect to the red
  wall's reflectance along (1, 1, 1), over ``--seeds`` seeds on each side, and Mitsuba's own primal /
  backward / step times in the same run (bench/peers/mitsuba_gradients.py).
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import pyclpt
from pyclpt.common import env

REPO = Path(__file__).resolve().parents[2]  # Mitsuba's side runs as bench.peers.mitsuba_gradients from here
PARAM = "red.reflectance.value"
GEOMETRY = "small-box.to_world"
SETTING = {"scene": "cornell-box", "width": 256, "height": 256, "spp": 16, "max_depth": 8}


def _median_times(fn, repeats: int) -> float:
    times = []
    for k in range(repeats):
        t = time.perf_counter()
        fn(k)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def timing(repeats: int, device: str | None, params: list[str] | None, label: str = "", **options) -> dict:
    """Primal, backward and step times (medians) in the issue's setting, for ``params`` (None: all);
    ``options``: render_backward's (the boundary terms' for geometry)."""
    scene = pyclpt.load(SETTING["scene"])
    w, h, spp, depth = SETTING["width"], SETTING["height"], SETTING["spp"], SETTING["max_depth"]
    t0 = time.perf_counter()
    renderer = pyclpt.Renderer(scene, width=w, height=h, max_depth=depth, device=device)
    grad = np.full((h, w, 3), 1.0 / (w * h * 3), np.float32)
    pyclpt.render_backward(scene, grad, spp=1, seed=1, max_depth=depth, width=w, height=h, device=device,
                           params=params, **options)
    compile_s = time.perf_counter() - t0
    primal = _median_times(lambda k: renderer.render(spp, seed=2 * k), repeats)
    backward = _median_times(lambda k: pyclpt.render_backward(
        scene, grad, spp=spp, seed=2 * k + 1, max_depth=depth, width=w, height=h, device=device, params=params,
        **options), repeats)

    def step(k: int) -> None:
        image = renderer.render(spp, seed=2 * k)
        pyclpt.render_backward(scene, 2 * image / image.size, spp=spp, seed=2 * k + 1, max_depth=depth, width=w,
                               height=h, device=device, params=params, **options)

    full = _median_times(step, repeats)
    return {"params": params or "all", "label": label or ("every parameter" if params is None else "one reflectance"),
            "primal_s": primal, "backward_s": backward, "step_s": full,
            "backward_over_primal": backward / primal, "step_over_primal": full / primal,
            "setup_and_compile_s": compile_s}


def _peak_rss_child(spp: int, device: str | None) -> dict:
    """One backward pass in a fresh process: its peak resident memory and the renderer's device bytes."""
    code = f"""
import json, resource, numpy as np, pyclpt
from pyclpt.gradients.differentiate import replay_for
s = pyclpt.load({SETTING['scene']!r})
kw = dict(width={SETTING['width']}, height={SETTING['height']}, max_depth={SETTING['max_depth']}, device={device!r})
g = np.ones(({SETTING['height']}, {SETTING['width']}, 3), np.float32)
pyclpt.render_backward(s, g, spp={spp}, seed=1, params=[{PARAM!r}], **kw)
print(json.dumps({{"peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "device_bytes": replay_for(s, **kw).device_bytes}}))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def memory(device: str | None, spps=(16, 64, 256)) -> list[dict]:
    return [{"spp": spp, **_peak_rss_child(spp, device)} for spp in spps]


def pyclpt_forward_sums(seeds: int, device: str | None) -> list[list[float]]:
    scene = pyclpt.load(SETTING["scene"])
    out = []
    for seed in range(seeds):
        g = pyclpt.render_forward(scene, PARAM, 1.0, spp=SETTING["spp"], seed=1000 + seed,
                                  max_depth=SETTING["max_depth"], width=SETTING["width"], height=SETTING["height"],
                                  device=device)
        out.append([float(x) for x in g.sum(axis=(0, 1), dtype=np.float64)])
    return out


def mitsuba(python: str, seeds: int, repeats: int) -> dict:
    from pyclpt.scene.library import builtin_dir

    cmd = [python, "-m", "bench.peers.mitsuba_gradients", "--scene", str(builtin_dir() / f"{SETTING['scene']}.json"),
           "--param", PARAM, "--spp", str(SETTING["spp"]), "--max-depth", str(SETTING["max_depth"]),
           "--width", str(SETTING["width"]), "--height", str(SETTING["height"]), "--seeds", str(seeds),
           "--repeats", str(repeats)]
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO)
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("{")]
    if done.returncode or not lines:
        raise RuntimeError(f"{' '.join(cmd)} failed: {(done.stdout + done.stderr)[-800:]}")
    return json.loads(lines[-1])


def agreement(a: list[list[float]], b: list[list[float]]) -> list[dict]:
    """Per channel: the means of both sides, their difference and its standard error."""
    out = []
    for c in range(3):
        xa, xb = [r[c] for r in a], [r[c] for r in b]
        se = (statistics.variance(xa) / len(xa) + statistics.variance(xb) / len(xb)) ** 0.5
        diff = statistics.mean(xa) - statistics.mean(xb)
        out.append({"channel": "rgb"[c], "pyclpt": statistics.mean(xa), "mitsuba": statistics.mean(xb),
                    "difference": diff, "standard_error": se, "sigmas": abs(diff) / se if se > 0 else float("inf")})
    return out


def report(results: dict) -> str:
    m = results["machine"]
    lines = ["# Differentiable rendering: measured figures", "",  # the title of its page in the docs site
             f"Machine: {m['cpu']}; device: {m['device']}.", "",
             "| setting | primal | backward | step | backward / primal | step / primal |", "|---|---|---|---|---|---|"]
    for t in results["timing"]:
        label = t.get("label") or ("one reflectance" if t["params"] != "all" else "every parameter")
        lines.append(f"| pyclpt, {label} | {t['primal_s']:.3f} s | {t['backward_s']:.3f} s | {t['step_s']:.3f} s | "
                     f"{t['backward_over_primal']:.2f} | {t['step_over_primal']:.2f} |")
    mi = results.get("mitsuba")
    if mi:
        t = mi["timing"]
        b, st, pr = t["backward_s"], t["step_s"], t["primal_s"]
        lines.append(f"| Mitsuba {mi['mitsuba_version']} prb ({mi['variant']}), one reflectance | {pr:.3f} s | "
                     f"{b:.3f} s | {st:.3f} s | {b / pr:.2f} | {st / pr:.2f} |")
    lines += ["", "| spp | device bytes held | peak resident memory |", "|---|---|---|"]
    for r in results["memory"]:
        lines.append(f"| {r['spp']} | {r['device_bytes'] / 2**20:.2f} MiB | {r['peak_rss_mib']:.0f} MiB |")
    if results.get("agreement"):
        lines += ["", "| channel | pyclpt | Mitsuba prb | difference | standard error |", "|---|---|---|---|---|"]
        for a in results["agreement"]:
            lines.append(f"| {a['channel']} | {a['pyclpt']:.1f} | {a['mitsuba']:.1f} | {a['difference']:+.1f} | "
                         f"{a['standard_error']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=None, help="folder for results.json and report.md")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seeds", type=int, default=4, help="seeds of the forward-gradient cross-check")
    ap.add_argument("--device", default=None)
    ap.add_argument("--mitsuba-python", default=None, help="default: $PYCLPT_MITSUBA_PYTHON (none: no Mitsuba)")
    a = ap.parse_args(argv)
    if a.mitsuba_python is None and env.get("PYCLPT_MITSUBA_PYTHON"):
        a.mitsuba_python = str(env.path("PYCLPT_MITSUBA_PYTHON"))
    from bench.report.machine import cpu_model
    results: dict = {"setting": SETTING, "param": PARAM,
                     "machine": {"cpu": cpu_model(), "device": pyclpt.get_device(a.device).name}}
    results["timing"] = [timing(a.repeats, a.device, [PARAM]), timing(a.repeats, a.device, None),
                         # where a box is (issue 25): the interior term alone, then with the boundary terms
                         timing(a.repeats, a.device, [GEOMETRY], "the small box's pose, interior term",
                                boundary=False),
                         timing(a.repeats, a.device, [GEOMETRY], "the small box's pose, both terms (edge_spp 1)",
                                edge_spp=1),
                         timing(a.repeats, a.device, [GEOMETRY], "the small box's pose, both terms (edge_spp 4)")]
    results["memory"] = memory(a.device)
    if a.mitsuba_python:
        results["mitsuba"] = mitsuba(a.mitsuba_python, a.seeds, a.repeats)
        results["pyclpt_forward"] = pyclpt_forward_sums(a.seeds, a.device)
        results["agreement"] = agreement(results["pyclpt_forward"], results["mitsuba"]["forward"])
    text = report(results)
    print(text)
    if a.out:
        a.out.mkdir(parents=True, exist_ok=True)
        (a.out / "results.json").write_text(json.dumps(results, indent=1) + "\n")
        (a.out / "report.md").write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
