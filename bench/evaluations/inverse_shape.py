"""Shape from images by the boundary term of primary visibility (pyclpt.gradients.edges): a sphere mesh
deformed into a target (an ellipsoid, turned) from its images in five views, with Adam on large-steps
coordinates (Nicolet, Jacobson and Jakob 2021: u = (I + lambda L) x with L the mesh's uniform Laplacian,
the gradient in u the gradient in x smoothed by (I + lambda L)^-1). The object emits over a constant
background, so the images change only at its silhouettes: what the views' silhouettes determine (its visual
hull) is what can be recovered, which for a convex target is the shape.

    python -m bench.evaluations.inverse_shape [--out FOLDER] [--steps N]

Writes shape.png (the loss and the distance to the target's surface per step; a view of the target, start and final) and
shape.json."""
from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import pyclpt
from bench.evaluations.inverse_pose import finish_figure
from pyclpt.gradients.edges import primary_boundary
from pyclpt.scene import transform as tf
from pyclpt.scene.shapes import sphere

#: Camera positions of the five views (all look at the origin).
VIEWS = [(0.0, 0.5, 4.0), (4.0, 0.5, 0.0), (0.0, 0.5, -4.0), (-4.0, 0.5, 0.0), (0.3, 4.0, 0.3)]
TARGET = tf.rotate([0, 1, 0], 30) @ tf.scale([1.25, 0.75, 0.95])


def laplacian(n: int, faces: np.ndarray):
    """The uniform graph Laplacian (D - A) of a triangle mesh, sparse (n, n)."""
    from scipy import sparse

    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    a = sparse.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n))
    a = a.tocsr()
    a.data[:] = 1.0
    return sparse.diags(np.asarray(a.sum(1)).ravel()) - a


def setup(width: int, height: int, rings: int, segments: int) -> tuple[pyclpt.Scene, np.ndarray, np.ndarray]:
    s = sphere(rings=rings, segments=segments)
    used = np.unique(s.indices)  # the generator may leave a vertex unused: drop it
    remap = np.full(len(s.positions), -1)
    remap[used] = np.arange(len(used))
    pos, faces = s.positions[used].astype(np.float64), remap[s.indices]
    mesh = pyclpt.Mesh("shape", pos.astype(np.float32), faces.astype(np.int32), 0, emission=(1.0, 0.85, 0.6))
    scene = pyclpt.Scene([mesh], [pyclpt.Diffuse((0.0, 0.0, 0.0))], pyclpt.Camera(tf.look_at(VIEWS[0], [0, 0, 0])),
                         pyclpt.Film(width, height, pyclpt.ReconstructionFilter("box")), environment=(0.1, 0.1, 0.1),
                         name="inverse-shape")
    return scene, pos, faces


def ellipsoid_error(x: np.ndarray) -> float:
    """How far points are from the target's surface: the mean of | |A^-1 x| - 1 | (A the target's 3x3; 0 on
    the surface, a relative radial deviation off it). Silhouettes fix the surface, not where a vertex sits
    on it, so this, not the distance to the corresponding target vertex, measures the recovery."""
    return float(np.abs(np.linalg.norm(x @ np.linalg.inv(TARGET[:3, :3]).T, axis=1) - 1.0).mean())


def views_and_targets(scene: pyclpt.Scene, params: pyclpt.SceneParameters, views, truth: np.ndarray, **render
                      ) -> tuple[Callable[[np.ndarray], None], Callable[[int], None], list[np.ndarray]]:
    """set_shape(x) (the mesh "shape"'s vertices), view(k) (the camera at ``views[k]``, looking at the origin) and
    the target images of the shape ``truth`` from each view (64 spp; ``render``: more of pyclpt.render's)."""
    cams = [tf.look_at(v, [0, 0, 0], [0, 0, 1] if abs(v[1]) > 1 else [0, 1, 0]) for v in views]

    def set_shape(x: np.ndarray) -> None:
        params.update({"shape.vertex_positions": x.reshape(-1)})

    def view(k: int) -> None:
        params.update({"sensor.to_world": cams[k]})

    set_shape(truth)
    targets = []
    for k in range(len(views)):
        view(k)
        targets.append(pyclpt.render(scene, spp=64, seed=1000 + k, **render))
    return set_shape, view, targets


def recover(steps: int = 150, width: int = 40, height: int = 40, spp: int = 8, samples: int = 8192,
            rings: int = 12, segments: int = 24, lam: float = 20.0, lr: float = 0.02) -> dict:
    from scipy.sparse import identity
    from scipy.sparse.linalg import splu

    scene, start_pos, faces = setup(width, height, rings, segments)
    truth = tf.apply_points(TARGET, start_pos).astype(np.float64)
    params = pyclpt.traverse(scene)
    set_shape, view, targets = views_and_targets(scene, params, VIEWS, truth)
    m = (identity(len(start_pos)) + lam * laplacian(len(start_pos), faces)).tocsc()
    solve = splu(m)
    u = m @ start_pos
    opt = pyclpt.optim.Adam(lr=lr, beta_1=0.8, beta_2=0.95, params={"u": u})
    h = {"losses": [], "vertex_error": [], "seconds": 0.0}
    begin = time.perf_counter()
    for step in range(steps):
        x = solve.solve(opt["u"].astype(np.float64))
        set_shape(x)
        h["vertex_error"].append(ellipsoid_error(x))
        gx, loss = np.zeros_like(x), 0.0
        for k in range(len(VIEWS)):
            view(k)
            image = pyclpt.render(scene, spp=spp, seed=2 * (step * len(VIEWS) + k))
            loss += float(np.mean((image - targets[k]) ** 2))
            grad = (2 * (image - targets[k]) / image.size).astype(np.float32)
            g = primary_boundary(scene, grad, ["shape.vertex_positions"], samples=samples,
                                 seed=2 * (step * len(VIEWS) + k) + 1, parameters=params)
            gx += g["shape.vertex_positions"].reshape(-1, 3)
        h["losses"].append(loss)
        opt.step({"u": solve.solve(gx).astype(np.float32)})  # (I + lambda L) is symmetric
    h["seconds"] = time.perf_counter() - begin
    x = solve.solve(opt["u"].astype(np.float64))
    h["vertex_error"].append(ellipsoid_error(x))
    h["images"] = {}
    view(0)
    h["images"]["target"] = targets[0]
    set_shape(start_pos)
    h["images"]["start"] = pyclpt.render(scene, spp=spp, seed=0)
    set_shape(x)
    h["images"]["final"] = pyclpt.render(scene, spp=spp, seed=0)
    h["final"] = x
    h["truth"] = truth
    return h


def plot(h: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 5, figsize=(17, 3.4))
    ax[0].semilogy(h["losses"])
    ax[0].set(title="image MSE (5 views)", xlabel="Adam step")
    ax[1].plot(h["vertex_error"])
    ax[1].set(title="distance to the target surface", xlabel="Adam step")
    finish_figure(fig, ax[2:], h["images"], path, " (view 1)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("inverse-shape"), help="folder for shape.png and shape.json")
    ap.add_argument("--steps", type=int, default=150)
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    h = recover(steps=args.steps)
    plot(h, args.out / "shape.png")
    summary = {"steps": args.steps, "seconds": round(h["seconds"], 2), "vertex_error_first": h["vertex_error"][0],
               "vertex_error_last": h["vertex_error"][-1], "loss_first": h["losses"][0], "loss_last": h["losses"][-1],
               "device": pyclpt.default_device().name}
    (args.out / "shape.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
