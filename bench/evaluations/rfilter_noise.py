"""Reconstruction filters against Mitsuba 3: agreement and noise at equal spp (docs/architecture.md, "Pixel
filters"). Two halves, one per Python:

    # Mitsuba's side (its own environment): renders tests/data/rfilter.xml per filter and seed
    python -m bench.evaluations.rfilter_noise --mitsuba /tmp/rfilter-mitsuba.npz [--spp 64 --seeds 8]
    # pyclpt's side: the same renders, then the table
    python -m bench.evaluations.rfilter_noise /tmp/rfilter-mitsuba.npz [--spp 64 --seeds 8]

pyclpt renders the tent and the gaussian with both estimators (ReconstructionFilter.estimator:
"importance", filter importance sampling, and "splat", the splatting film). Noise is the per-pixel variance
across seeds (relative: its mean over the mean squared pixel), so the two renderers' path sampling (pyclpt
picks lights by power, Mitsuba uniformly) is compared through the box filter's ratio, and the filter's own
effect is the ratio of ratios. relMSE: each seed's image against Mitsuba's 16384-spp reference
(tests/data/rfilter-*-mitsuba.npy), the mean over the seeds, pyclpt's over Mitsuba's; and of the mean of
the seeds. Last line: Mitsuba's own sample_border = false render against the reference (edge pixels only
differ; pyclpt's splatting film has no samples beyond the image, as sample_border = false).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "tests" / "data"
FILTERS = ("box", "tent", "gaussian")


def mitsuba_side(out: Path, spp: int, seeds: int) -> None:
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    results = {}
    for f in FILTERS:
        scene = mi.load_file(str(DATA / "rfilter.xml"), filter=f)
        results[f] = np.stack([np.array(mi.render(scene, spp=spp, seed=s))[..., :3] for s in range(1, seeds + 1)])
    text = (DATA / "rfilter.xml").read_text().replace('name="sample_border" value="true"',
                                                      'name="sample_border" value="false"')
    scene = mi.load_string(text)  # the file's default filter: gaussian
    results["gaussian-no-border"] = np.array(mi.render(scene, spp=4096, seed=1))[..., :3]
    np.savez(out, **results)


def rel_var(stack: np.ndarray) -> float:
    return float(stack.var(axis=0, ddof=1).mean() / np.mean(stack.mean(axis=0) ** 2))


def rel_mse(img: np.ndarray, ref: np.ndarray) -> float:
    return float(np.mean((img - ref) ** 2) / np.mean(ref ** 2))


RUNS = (("box", "importance"), ("tent", "importance"), ("tent", "splat"), ("gaussian", "importance"),
        ("gaussian", "splat"))


def pyclpt_side(mitsuba: Path, spp: int, seeds: int) -> None:
    import pyclpt

    mi = np.load(mitsuba)
    ours = {}
    for f, est in RUNS:
        scene = pyclpt.load(DATA / "rfilter.xml", filter=f)
        scene.film.rfilter = pyclpt.ReconstructionFilter(f, estimator=est) if f != "box" else scene.film.rfilter
        ours[f, est] = np.stack([pyclpt.render(scene, spp=spp, seed=s, progress=False)
                                 for s in range(1, seeds + 1)])
    print(f"{spp} spp, {seeds} seeds, 64x48: relative per-pixel variance | relMSE vs Mitsuba 16384 spp")
    print("filter   estimator   pyclpt     Mitsuba    ratio (of box's) | per image: pyclpt   Mitsuba   ratio | "
          "seeds' mean: pyclpt, Mitsuba; mean")
    base = rel_var(ours["box", "importance"]) / rel_var(mi["box"])
    for f, est in RUNS:
        img = ours[f, est]
        ratio = rel_var(img) / rel_var(mi[f])
        ref_path = DATA / f"rfilter-{f}-mitsuba.npy"
        agree = ""
        if ref_path.exists():
            ref = np.load(ref_path)
            ours_mse = np.mean([rel_mse(x, ref) for x in img])
            mi_mse = np.mean([rel_mse(x, ref) for x in mi[f]])
            agree = (f"{ours_mse:.3e}  {mi_mse:.3e}  {ours_mse / mi_mse:.2f} | {rel_mse(img.mean(0), ref):.2e}, "
                     f"{rel_mse(mi[f].mean(0), ref):.2e}; {img.mean() / ref.mean() - 1:+.2%}")
        print(f"{f:8s} {est:10s}  {rel_var(img):.3e}  {rel_var(mi[f]):.3e}  {ratio:.2f} ({ratio / base:.2f})   | "
              f"{agree}")
    ref = np.load(DATA / "rfilter-gaussian-mitsuba.npy")
    nb = mi["gaussian-no-border"]
    edge = np.zeros(ref.shape[:2], bool)
    edge[:2], edge[-2:], edge[:, :2], edge[:, -2:] = True, True, True, True
    print(f"Mitsuba gaussian sample_border=false (4096 spp) vs true: relMSE {rel_mse(nb, ref):.2e}; "
          f"interior {rel_mse(nb[~edge], ref[~edge]):.2e}, 2-pixel edge {rel_mse(nb[edge], ref[edge]):.2e}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("mitsuba_results", type=Path, nargs="?", help="the npz of Mitsuba's side (pyclpt's side)")
    p.add_argument("--mitsuba", type=Path, help="run Mitsuba's side, writing this npz")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--seeds", type=int, default=8)
    a = p.parse_args()
    if a.mitsuba is not None:
        mitsuba_side(a.mitsuba, a.spp, a.seeds)
    elif a.mitsuba_results is not None:
        pyclpt_side(a.mitsuba_results, a.spp, a.seeds)
    else:
        p.error("give the npz of Mitsuba's side, or --mitsuba OUT to make it")


if __name__ == "__main__":
    main()
