"""Inverse rendering with pyclpt's gradients: the example of docs/differentiable.md.

Two problems, each from a target image rendered with the true value:
  * the cornell box's red wall reflectance, from (0.01, 0.2, 0.9), 128x128, 4 spp per step, 50 Adam
    steps (Mitsuba 3's tutorial problem);
  * a 4x4 bitmap texture on a quad, from grey.

Each step renders the image (seed 2k), takes the gradient of the mean squared error with respect to
it, and back-propagates it with render_backward on another seed (2k + 1): the same seed would make
the gradient biased. ``python -m bench.evaluations.inverse_rendering --out docs/differentiable`` writes
``curves.png`` (loss and parameter error per step, matplotlib) and ``inverse-rendering.json``.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import pyclpt

RED = "red.reflectance.value"
RED_TRUTH = np.array([0.570068, 0.0430135, 0.0443706], np.float32)
RED_START = (0.01, 0.2, 0.9)


def step_lr(lr: float, step: int, hold: int, decay: float) -> float:
    """The learning rate of a step: ``lr`` for ``hold`` steps, then times ``decay`` each step."""
    return lr * decay ** max(0, step - hold)


def optimise(scene: pyclpt.Scene, target: np.ndarray, name: str, steps: int, spp: int, *, lr: float,
             beta_1: float, hold: int, decay: float, beta_2: float = 0.999, lo: float = 1e-3, hi: float = 1.0,
             max_depth: int = 8, seed: int = 0) -> dict:
    """Adam on parameter ``name`` of ``scene`` towards ``target``; the history of losses and values."""
    params = pyclpt.traverse(scene)
    opt = pyclpt.optim.Adam(lr=lr, beta_1=beta_1, beta_2=beta_2)
    opt[name] = params[name]
    height, width = target.shape[:2]
    opts = dict(width=width, height=height, max_depth=max_depth)
    losses, values = [], [params[name]]
    start = time.perf_counter()
    for k in range(steps):
        image = pyclpt.render(scene, spp=spp, seed=seed + 2 * k, **opts)
        losses.append(float(np.mean((image - target) ** 2)))
        image_grad = 2.0 * (image - target) / image.size  # d mean((I - T)^2) / dI
        grads = pyclpt.render_backward(scene, image_grad, spp=spp, seed=seed + 2 * k + 1, loss_seed=seed + 2 * k,
                                       params=[name], **opts)
        opt.lr = step_lr(lr, k, hold, decay)
        opt.step(grads)
        opt[name] = np.clip(opt[name], lo, hi)
        params.update(opt)
        values.append(params[name])
    return {"losses": losses, "values": values, "seconds": time.perf_counter() - start}


def recover_red_wall(steps: int = 50, size: int = 128, spp: int = 4, seed: int = 0) -> dict:
    """The red wall from RED_START against a 1024-spp target (a noisy target moves the optimum: with 64
    spp, by up to 0.004). Adam with lr 0.12, beta_1 0.5 (little overshoot) and beta_2 0.9 (the step
    follows the gradient's scale as it shrinks near the optimum), lr held 12 steps, then x0.88 a step."""
    scene = pyclpt.load("cornell-box")
    target = pyclpt.render(scene, spp=1024, seed=100_000 + seed, width=size, height=size, max_depth=8)
    pyclpt.traverse(scene).update({RED: RED_START})
    return optimise(scene, target, RED, steps, spp, lr=0.12, beta_1=0.5, beta_2=0.9, hold=12, decay=0.88, seed=seed)


def textured_quad(texels: np.ndarray, size: int = 32) -> pyclpt.Scene:
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 25.0, "film": {"width": size, "height": size},
                   "to_world": [{"look_at": {"origin": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0]}}]},
        "sky": {"type": "constant", "radiance": 1.0},
        "quad": {"type": "rectangle", "bsdf": {"type": "diffuse", "id": "tex", "reflectance": {
            "type": "bitmap", "data": texels}}},
    }, name="textured-quad")


def recover_texture(steps: int = 40, spp: int = 4, seed: int = 0) -> dict:
    """A 4x4 texture (random, in [0.1, 0.9]) from grey: Adam (lr 0.05)."""
    truth = np.random.default_rng(9).random((4, 4, 3)).astype(np.float32) * 0.8 + 0.1
    target = pyclpt.render(textured_quad(truth), spp=64, seed=100_000 + seed, max_depth=2)
    scene = textured_quad(np.full((4, 4, 3), 0.5, np.float32))
    out = optimise(scene, target, "tex.reflectance.data", steps, spp, lr=0.05, beta_1=0.9, hold=steps, decay=1.0,
                   lo=0.0, max_depth=2, seed=seed)
    out["truth"] = truth
    return out


def plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for (label, r, truth), color in zip((("red wall", results["red_wall"], RED_TRUTH),
                                         ("texture", results["texture"], results["texture"]["truth"])), ("C0", "C1")):
        losses = np.asarray(r["losses"])
        smooth = np.convolve(losses, np.ones(5) / 5, mode="valid")
        axes[0].semilogy(losses, color=color, alpha=0.35, lw=0.8)
        axes[0].semilogy(np.arange(2, 2 + len(smooth)), smooth, color=color, label=f"{label} (mean of 5)")
        axes[1].semilogy([float(np.abs(v - truth).max()) for v in r["values"]], color=color, label=label)
    axes[0].set(title="loss: MSE of the 4-spp image against the target", xlabel="Adam step")
    axes[1].axhline(0.005, color="grey", lw=0.8, ls="--")
    axes[1].set(title="parameter error (max abs)", xlabel="Adam step")
    for ax in axes:
        ax.legend()
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("inverse-rendering"),
                    help="folder for curves.png and inverse-rendering.json")
    ap.add_argument("--steps", type=int, default=50, help="Adam steps of the red wall")
    ap.add_argument("--size", type=int, default=128, help="the red wall's image, SIZE x SIZE pixels")
    ap.add_argument("--texture-steps", type=int, default=40, help="Adam steps of the texture")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    results = {"red_wall": recover_red_wall(steps=args.steps, size=args.size),
               "texture": recover_texture(steps=args.texture_steps)}
    plot(results, args.out / "curves.png")
    summary = {
        "device": pyclpt.default_device().name,
        "red_wall": {"steps": args.steps, "size": args.size, "final": results["red_wall"]["values"][-1].tolist(),
                     "error": float(np.abs(results["red_wall"]["values"][-1] - RED_TRUTH).max()),
                     "seconds": results["red_wall"]["seconds"]},
        "texture": {"steps": len(results["texture"]["losses"]),
                    "error": float(np.abs(results["texture"]["values"][-1] - results["texture"]["truth"]).max()),
                    "seconds": results["texture"]["seconds"]},
    }
    (args.out / "inverse-rendering.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
