"""Noise at equal spp against Mitsuba 3 on the test scenes with several emitters (docs/architecture.md, "Light
selection"). Two halves, one per Python:

    # Mitsuba's side (its own environment): each scene at --spp, one render per seed
    python -m bench.evaluations.light_noise --mitsuba /tmp/light-noise-mitsuba.npz [--spp 256 --seeds 4]
    # pyclpt's side: the same renders, then the table
    python -m bench.evaluations.light_noise /tmp/light-noise-mitsuba.npz [--spp 256 --seeds 4]

relMSE of each seed's image against Mitsuba's 16384-spp reference of the file (tests/data/NAME-mitsuba.npy,
tests/data/make_plugin_reference.py), the mean over the seeds; the table gives pyclpt's, Mitsuba's and their
ratio, whole image and over the pixels where the reference is brightest (the top decile of luminance: a
spot's footprint, the lit side of a shape). ``--rules`` renders pyclpt once per listed light selection rule
(pyclpt.buffers.lights.SELECTIONS: distant-uniform, the default, power and uniform).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "tests" / "data"
SCENES = ("delta-emitters", "emitter-textures", "instances", "uv-shapes", "uv-transforms", "rfilter")


def mitsuba_side(out: Path, spp: int, seeds: int) -> None:
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    results = {}
    for name in SCENES:
        scene = mi.load_file(str(DATA / f"{name}.xml"))
        results[name] = np.stack([np.array(mi.render(scene, spp=spp, seed=s))[..., :3] for s in range(1, seeds + 1)])
    np.savez(out, **results)


def rel_mse(img: np.ndarray, ref: np.ndarray, mask: np.ndarray | None = None) -> float:
    if mask is not None:
        img, ref = img[mask], ref[mask]
    return float(np.mean((img - ref) ** 2) / np.mean(ref ** 2))


def reference(name: str) -> np.ndarray:
    path = DATA / f"{name}-mitsuba.npy"
    if name == "rfilter":
        path = DATA / "rfilter-gaussian-mitsuba.npy"
    return np.load(path).astype(np.float64)


def pyclpt_side(mitsuba: Path, spp: int, seeds: int, rules: list[str]) -> None:
    import pyclpt
    from pyclpt.buffers import lights

    mi = np.load(mitsuba)
    default = lights.SELECTION
    print(f"relMSE against Mitsuba's 16384-spp reference at {spp} spp, mean of {seeds} seeds; "
          f"light selection {', '.join(rules)}")
    print("| scene | selection | pyclpt | Mitsuba | ratio | brightest decile: ratio |")
    print("|---|---|---|---|---|---|")
    try:
        for name in SCENES:
            ref = reference(name)
            lum = ref @ np.array([0.2126, 0.7152, 0.0722])
            mask = lum >= np.quantile(lum, 0.9)
            m_all = np.mean([rel_mse(x, ref) for x in mi[name]])
            m_top = np.mean([rel_mse(x, ref, mask) for x in mi[name]])
            for a in rules:
                lights.SELECTION = a
                scene = pyclpt.load(DATA / f"{name}.xml")
                imgs = [np.asarray(pyclpt.render(scene, spp=spp, seed=s), np.float64)[..., :3]
                        for s in range(1, seeds + 1)]
                p_all = np.mean([rel_mse(x, ref) for x in imgs])
                p_top = np.mean([rel_mse(x, ref, mask) for x in imgs])
                print(f"| {name} | {a} | {p_all:.3e} | {m_all:.3e} | {p_all / m_all:.2f} | {p_top / m_top:.2f} |",
                      flush=True)
    finally:
        lights.SELECTION = default


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("npz", type=Path, nargs="?", help="Mitsuba's renders (pyclpt's side)")
    ap.add_argument("--mitsuba", type=Path, help="render Mitsuba's side into this file")
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--rules", default=None, help="comma-separated light selection rules (default: pyclpt's)")
    a = ap.parse_args()
    if a.mitsuba:
        mitsuba_side(a.mitsuba, a.spp, a.seeds)
        return
    if a.npz is None:
        ap.error("give Mitsuba's renders (the npz of --mitsuba)")
    from pyclpt.buffers import lights

    pyclpt_side(a.npz, a.spp, a.seeds, a.rules.split(",") if a.rules else [lights.SELECTION])


if __name__ == "__main__":
    main()
