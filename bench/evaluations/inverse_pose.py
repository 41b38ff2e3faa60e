"""Pose from images by the boundary term of primary visibility (pyclpt.gradients.edges): an emitting
L-shaped plate's pose (translation x, y and rotation about the view axis) and the camera's translation
recovered from a target image with Adam (a fixed marker square tells the two apart). The objects are
emitters over a constant background, so the image changes only at silhouettes and the boundary term is the
whole derivative.

    python -m bench.evaluations.inverse_pose [--out FOLDER] [--steps N]

Writes pose.png (the loss and the pose error per step; the target, start and final images) and pose.json."""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import pyclpt
from pyclpt.gradients.edges import primary_boundary
from pyclpt.scene import transform as tf

#: An L of two rectangles (world units), its corner at the origin.
PLATE = [tf.translate([0.3, -0.45, 0.0]) @ tf.scale([0.9, 0.15, 1.0]),
         tf.translate([-0.45, 0.15, 0.0]) @ tf.scale([0.15, 0.75, 1.0])]
TARGET_POSE = (0.35, -0.2, 25.0)  # x, y, degrees about z
TARGET_CAMERA = (0.3, 0.15)  # the camera's x, y offset


def scene(width: int, height: int) -> pyclpt.Scene:
    emit = {"bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}},
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1.0, 0.8, 0.5]}}}
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": 45, "to_world": tf.look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}}},
         "env": {"type": "constant", "radiance": {"type": "rgb", "value": [0.1, 0.15, 0.2]}}}
    for k, m in enumerate(PLATE):
        d[f"plate{k}"] = {"type": "rectangle", "to_world": m, **emit}
    # a fixed marker: without it the camera's and the plate's translations are the same image change
    d["marker"] = {"type": "rectangle", "to_world": tf.translate([-1.1, -0.9, 0.0]) @ tf.scale(0.2),
                   **{**emit, "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [0.3, 0.9, 0.4]}}}}
    return pyclpt.load_dict(d)


def pose_matrix(v: np.ndarray) -> np.ndarray:
    """The plate's pose from (x, y, degrees / 50): the rotation scaled so that one Adam step moves the
    three alike."""
    return tf.pose(translate=[v[0], v[1], 0.0], rotate=[0.0, 0.0, 50.0 * v[2]])


def chain(g_m: np.ndarray, v: np.ndarray, f) -> np.ndarray:
    """dLoss/dv from dLoss/dM (4x4) for M = f(v), by central differences of f (a closed form)."""
    out = np.zeros(len(v))
    for k in range(len(v)):
        d = np.zeros(len(v))
        d[k] = 1e-6
        out[k] = float((g_m * (f(v + d) - f(v - d)) / 2e-6).sum())
    return out


def recover(steps: int = 60, width: int = 48, height: int = 48, spp: int = 16, samples: int = 8192,
            lr: float = 0.03) -> dict:
    """Adam on the plate's pose and the camera's translation from a target rendered with both moved."""
    sc = scene(width, height)
    params = pyclpt.traverse(sc)
    cam0 = np.asarray(params["sensor.to_world"], np.float64)

    def camera(c: np.ndarray) -> np.ndarray:
        return tf.translate([c[0], c[1], 0.0]) @ cam0

    def apply(v: np.ndarray, c: np.ndarray) -> None:
        m = pose_matrix(v)
        params.update({"plate0.to_world": m, "plate1.to_world": m, "sensor.to_world": camera(c)})

    truth_v = np.array([TARGET_POSE[0], TARGET_POSE[1], TARGET_POSE[2] / 50.0])
    truth_c = np.array(TARGET_CAMERA, np.float64)
    apply(truth_v, truth_c)
    target = pyclpt.render(sc, spp=256, seed=1000)
    v, c = np.zeros(3), np.zeros(2)
    apply(v, c)
    opt = pyclpt.optim.Adam(lr=lr, beta_1=0.8, beta_2=0.95, params={"v": v, "c": c})
    history = {"losses": [], "pose_error": [], "camera_error": [], "start": pyclpt.render(sc, spp=spp, seed=0)}
    start = time.perf_counter()
    for k in range(steps):
        v, c = opt["v"].astype(np.float64), opt["c"].astype(np.float64)
        apply(v, c)
        image = pyclpt.render(sc, spp=spp, seed=2 * k)
        history["losses"].append(float(np.mean((image - target) ** 2)))
        history["pose_error"].append(np.abs(v - truth_v).tolist())
        history["camera_error"].append(np.abs(c - truth_c).tolist())
        grad = (2 * (image - target) / image.size).astype(np.float32)
        g = primary_boundary(sc, grad, ["plate0.to_world", "plate1.to_world", "sensor.to_world"],
                             samples=samples, seed=2 * k + 1, parameters=params)
        gm = g["plate0.to_world"] + g["plate1.to_world"]
        opt.step({"v": chain(gm, v, pose_matrix).astype(np.float32),
                  "c": chain(g["sensor.to_world"], c, camera).astype(np.float32)})
    history["seconds"] = time.perf_counter() - start
    v, c = opt["v"].astype(np.float64), opt["c"].astype(np.float64)
    apply(v, c)
    history.update(final=pyclpt.render(sc, spp=spp, seed=0), target=target, pose=v.tolist(), camera=c.tolist(),
                   truth_pose=truth_v.tolist(), truth_camera=truth_c.tolist())
    return history


def plot(h: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 5, figsize=(17, 3.4))
    ax[0].semilogy(h["losses"])
    ax[0].set(title="image MSE", xlabel="Adam step")
    err = np.asarray(h["pose_error"])
    cam = np.asarray(h["camera_error"])
    for k, name in enumerate(("plate x", "plate y", "plate angle / 50 deg")):
        ax[1].semilogy(err[:, k] + 1e-6, label=name)
    for k, name in enumerate(("camera x", "camera y")):
        ax[1].semilogy(cam[:, k] + 1e-6, "--", label=name)
    ax[1].set(title="parameter error", xlabel="Adam step")
    ax[1].legend(fontsize=7)
    finish_figure(fig, ax[2:], h, path)


def finish_figure(fig, axes, images: dict, path: Path, suffix: str = "") -> None:
    """The target, start and final images (linear, shown with gamma 2.2) in ``axes``, titled with ``suffix``, then
    the figure saved to ``path`` and closed (the examples' figures share this)."""
    import matplotlib.pyplot as plt

    for a, key in zip(axes, ("target", "start", "final")):
        a.imshow(np.clip(images[key], 0, 1) ** (1 / 2.2))
        a.set_title(f"{key}{suffix}")
        a.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("inverse-pose"), help="folder for pose.png and pose.json")
    ap.add_argument("--steps", type=int, default=60)
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    h = recover(steps=args.steps)
    plot(h, args.out / "pose.png")
    summary = {"steps": args.steps, "seconds": round(h["seconds"], 2), "pose": h["pose"], "truth_pose": h["truth_pose"],
               "camera": h["camera"], "truth_camera": h["truth_camera"], "loss_first": h["losses"][0],
               "loss_last": h["losses"][-1], "device": pyclpt.default_device().name}
    (args.out / "pose.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
