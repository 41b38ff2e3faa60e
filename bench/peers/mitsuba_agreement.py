"""How closely pyclpt's images agree with Mitsuba 3's, scene by scene: channel means and the pixels'
relative MSE.

    python -m bench.peers.mitsuba_agreement [--spp 256] [--resolution 128x128] [--scenes ...] [-o DIR]

- **Shared scenes** (``$PYCLPT_SCENES``: cornell-box, classroom, living-room, staircase, staircase2):
  both renderers at the same spp, resolution and max depth 8, box filter, Russian roulette from
  bounce 3; Mitsuba 3 (``llvm_ad_rgb``) through ``bench/report/mitsuba_driver.py`` in its own environment
  (``--mitsuba-python`` or ``$PYCLPT_MITSUBA_PYTHON``), which edits the file as docs/benchmarks.md
  says. The relative MSE of two equal-spp renders holds the noise of both.
- **Test scenes** (``tests/data/NAME.xml`` with a stored ``NAME-mitsuba.npy``, Mitsuba 3 at 16384
  spp, made by ``tests/data/make_plugin_reference.py``): pyclpt at ``--test-spp`` against that
  reference, as the file says (its filter, depth and size).

relMSE = mean((pyclpt - mitsuba)^2) / mean(mitsuba^2) over all pixels and channels. Written:
``agreement.md`` and ``agreement.json`` in the output folder, with the CPU model.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from bench.report.machine import cpu_model
from bench.report.versus import DRIVER

DATA = Path(__file__).resolve().parents[2] / "tests" / "data"
SHARED = ["cornell-box", "classroom", "living-room", "staircase", "staircase2"]
#: tests/data references that are variants of one file: name -> (file, loader parameters)
VARIANTS = {"rfilter-tent": ("rfilter", {"filter": "tent"}), "rfilter-gaussian": ("rfilter", {"filter": "gaussian"}),
            "anisotropy-swapped": ("anisotropy", {"au": 0.35, "av": 0.04})}


def compare(img: np.ndarray, ref: np.ndarray) -> dict:
    img, ref = np.asarray(img, np.float64)[..., :3], np.asarray(ref, np.float64)[..., :3]
    return {"pyclpt_mean": img.mean((0, 1)).tolist(), "mitsuba_mean": ref.mean((0, 1)).tolist(),
            "relmse": float(np.mean((img - ref) ** 2) / np.mean(ref**2))}


def shared_scene(name: str, root: Path, python: str, spp: int, width: int, height: int, seed: int) -> dict:
    import pyclpt

    file = root / name / "scene.xml"
    scene = pyclpt.load(file)
    scene.film.rfilter = pyclpt.ReconstructionFilter("box")  # as the driver makes Mitsuba's
    img = pyclpt.render(scene, spp=spp, seed=seed, width=width, height=height, max_depth=8)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "mitsuba.npy"
        cmd = [python, str(DRIVER), "--scene", str(file), "--spp", str(spp), "--max-depth", "8",
               "--width", str(width), "--height", str(height), "--warmup", "0", "--repeats", "1", "--save", str(out)]
        run = subprocess.run(cmd, capture_output=True, text=True)
        if run.returncode != 0 or not out.is_file():
            raise RuntimeError(f"{name}: Mitsuba's render failed: {run.stdout[-2000:]} {run.stderr[-2000:]}")
        ref = np.load(out)
    return {"scene": f"shared/{name}", "spp": f"{spp} / {spp}", **compare(img, ref)}


def test_scene(name: str, spp: int, seed: int) -> dict:
    import pyclpt

    file, params = VARIANTS.get(name, (name, {}))
    img = pyclpt.render(pyclpt.load(DATA / f"{file}.xml", **params), spp=spp, seed=seed)
    ref = np.load(DATA / f"{name}-mitsuba.npy")
    return {"scene": f"tests/data/{name}", "spp": f"{spp} / 16384", **compare(img, ref)}


def to_markdown(rows: list[dict], settings: dict) -> str:
    lines = [f"CPU: {settings['cpu']}; `python -m bench.peers.mitsuba_agreement --spp {settings['spp']} --resolution "
             f"{settings['resolution']} --test-spp {settings['test_spp']}`", "",
             "| scene | spp pyclpt / Mitsuba | mean RGB pyclpt | mean RGB Mitsuba 3 | ratio | relMSE |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        p, m = r["pyclpt_mean"], r["mitsuba_mean"]
        ratio = " / ".join(f"{a / b:.3f}" if b > 0 else "-" for a, b in zip(p, m))
        lines.append(f"| {r['scene']} | {r['spp']} | {' '.join(f'{x:.4f}' for x in p)} | "
                     f"{' '.join(f'{x:.4f}' for x in m)} | {ratio} | {r['relmse']:.2e} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from pyclpt.common import env
    from pyclpt.scene.library import scenes_root

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--spp", type=int, default=256, help="spp of both renderers on the shared scenes")
    p.add_argument("--test-spp", type=int, default=1024, help="pyclpt's spp on the test scenes")
    p.add_argument("--resolution", default="128x128", help="WIDTHxHEIGHT of the shared scenes")
    p.add_argument("--scenes", nargs="+", default=None, help="shared scene folders and tests/data names")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--mitsuba-python", default=None)
    p.add_argument("-o", "--output", default="bench-agreement")
    a = p.parse_args(argv)
    width, height = (int(x) for x in a.resolution.lower().split("x"))
    tests = sorted(f.name[:-len("-mitsuba.npy")] for f in DATA.glob("*-mitsuba.npy"))
    names = a.scenes or [*SHARED, *tests]
    python = a.mitsuba_python or (str(env.path("PYCLPT_MITSUBA_PYTHON")) if env.get("PYCLPT_MITSUBA_PYTHON") else None)
    root = scenes_root()
    rows = []
    for name in names:
        if name in SHARED:
            if python is None or root is None:
                print(f"{name}: skipped (needs PYCLPT_MITSUBA_PYTHON and the shared scenes)", file=sys.stderr)
                continue
            rows.append(shared_scene(name, root, python, a.spp, width, height, a.seed))
        else:
            rows.append(test_scene(name, a.test_spp, a.seed))
        print(to_markdown(rows[-1:], {"cpu": "", "spp": a.spp, "resolution": a.resolution,
                                      "test_spp": a.test_spp}).splitlines()[-1], flush=True)
    settings = {"cpu": cpu_model(), "spp": a.spp, "resolution": a.resolution, "test_spp": a.test_spp}
    out = Path(a.output)
    out.mkdir(parents=True, exist_ok=True)
    (out / "agreement.json").write_text(json.dumps({"settings": settings, "rows": rows}, indent=1))
    (out / "agreement.md").write_text(to_markdown(rows, settings))
    print(to_markdown(rows, settings))
    return 0


if __name__ == "__main__":
    sys.exit(main())
