"""Pose and shape from SHADED images, with both terms of the derivative (pyclpt.render_backward: the interior term by
path replay plus the boundary terms of camera silhouettes and soft shadows).

    python -m bench.evaluations.inverse_shaded [--out FOLDER] [--steps N] [--which pose|shape|both]

Question: bench/evaluations/inverse_pose.py and inverse_shape.py recover a pose, the camera and a shape from images of
emitting objects, where only silhouettes change; can the same be done for diffuse objects lit by an area light,
whose images change inside (shading, soft shadows) as much as at their outlines, and does the shading help?

Method. Pose: a diffuse box resting just above a diffuse floor (a rectangle whose edges are out of view), lit by a
rectangle area light and a dim constant environment. The target is rendered with the box moved (x, z) and turned
about the vertical axis and the camera translated (x, y); Adam recovers the five from the start pose with the loss's
gradient from ``render_backward(params=["box.to_world", "sensor.to_world"])``, chained through the pose's
parameterisation (render_backward's ``box.to_world`` is a pose relative to where the box is now, so the chain is
through M(w) M(v)^-1). Shape: a flat-shaded sphere mesh (``normals = None``), diffuse grey, under two area lights
and a grey environment (0.4), deformed towards inverse_shape.py's target (an ellipsoid, turned) from its five views with
Adam on large-steps coordinates (u = (I + lambda L) x, inverse_shape.py's Laplacian), the gradient of
``SHAPE.vertex_positions`` from render_backward; its distance to the target's surface per step against
inverse_shape.py's silhouette-only run at the same size, spp, edge samples and steps.

Answer (measured on a 2-core AMD EPYC VM, PoCL; docs/differentiable/shaded.json). Pose: yes, and the shading is
needed. At 48x48, 16 spp, 16,384 edge samples, 150 steps (34 s), from errors of 0.3 / 0.25 / 30 degrees (box x, z,
angle) and 0.25 / 0.2 (camera x, y), the box ends within 0.024 / 0.008 / 0.2 degrees and the camera within 0.015 /
0.001; with inverse_pose.py's gradient (camera silhouettes alone) the box's x and the camera's x drift together
(errors 0.29 and 0.26: with no outline but the box's in view, the silhouettes cannot tell them apart; the lit floor
and the shadow can). On a small floor whose edges are in view (``floor=1.8``) silhouettes alone suffice too, and
both terms reach 0.008 / 0.9 degrees / 0.006 in 100 steps. The pose needed gradient clipping (see :func:`clip`):
the soft-shadow boundary term is heavy-tailed, and without it a single outlying step undid the convergence.
Shape: the shaded run converges (clipping changed nothing there), but the shading does not help on this convex
target: the distance to the target falls from 0.095 to 0.019 in 150 steps
(40x40, 8 spp, five views, lambda 8; 31 s), against 0.018 (lambda 20, inverse_shape.py's own setting) and 0.014
(lambda 8) for the silhouettes of the emitting sphere at the same size, spp, edge samples and steps, whose gradients
are far less noisy (the silhouettes of a convex object determine it already). Under a dim environment (0.12, the
unlit side as dark as the background; lambda 20) it stalled at 0.047: the silhouettes carry the shape here, not
the shading.

Writes shaded-pose.png and shaded-shape.png (the loss and the parameter errors per step; target, start and final
images) and shaded.json."""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import pyclpt
from bench.evaluations import inverse_shape
from bench.evaluations.inverse_pose import chain, finish_figure
from bench.evaluations.inverse_shape import TARGET, VIEWS, ellipsoid_error, laplacian
from pyclpt.gradients.edges import primary_boundary
from pyclpt.gradients.parameters import SceneParameters
from pyclpt.scene import transform as tf
from pyclpt.scene.shapes import rectangle, sphere

#: The box's target pose: x, z (world units) and degrees about the vertical (y) axis; the camera's x, y offset.
TARGET_POSE = (0.3, -0.25, 30.0)
TARGET_CAMERA = (0.25, 0.2)
#: One Adam step moves the angle by this many degrees per unit of its coordinate (the rotation is scaled so that
#: the three move alike, as in inverse_pose.py).
DEGREES = 50.0


def schedule(lr: float, step: int, steps: int, final: float) -> float:
    """The learning rate at ``step``: ``lr`` over the first half, then down geometrically to ``final`` x ``lr`` at the
    last step (the gradients of the shaded images are noisy: a constant rate settles at a noise floor)."""
    half = steps / 2
    return lr * final ** (max(0.0, step - half) / max(half, 1.0))


def clip(g: np.ndarray, norms: list[float], factor: float = 5.0) -> np.ndarray:
    """``g`` scaled down to ``factor`` x the median norm of the last 20 gradients (``norms``, appended to) when
    larger: the soft-shadow boundary term is heavy-tailed (one step in 20-50 gives a gradient 30-200x the median,
    measured at the target pose), and one such step kicks Adam's parameters by several learning rates."""
    n = float(np.linalg.norm(g))
    cap = factor * float(np.median(norms[-20:])) if len(norms) >= 5 else np.inf
    norms.append(min(n, cap))
    return g * (cap / n) if n > cap else g


def _diffuse(rgb) -> dict:
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rgb)}}


def pose_scene(width: int, height: int, floor: float = 20.0) -> pyclpt.Scene:
    """The box above the floor (``floor``: its half-width; at 20 its edges are out of view) under an area light (y up),
    the camera looking down at it from the front."""
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": 40, "to_world": tf.look_at([0, 2.4, 4.2], [0, 0.2, 0], [0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}}},
         "env": {"type": "constant", "radiance": {"type": "rgb", "value": [0.04, 0.05, 0.07]}},
         "floor": {"type": "rectangle", "to_world": tf.rotate([1, 0, 0], -90) @ tf.scale(floor),
                   "bsdf": _diffuse([0.6, 0.6, 0.6])},
         "box": {"type": "cube", "to_world": tf.translate([0, 0.3, 0]) @ tf.scale([0.5, 0.25, 0.28]),
                 "bsdf": _diffuse([0.75, 0.35, 0.15])},
         "light": {"type": "rectangle", "to_world": tf.look_at([-1.6, 3.0, 1.2], [0, 0, 0], [0, 1, 0]) @ tf.scale(0.4),
                   "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [30.0] * 3}}}}
    return pyclpt.load_dict(d)


def box_pose(v: np.ndarray) -> np.ndarray:
    """The box's pose from (x, z, degrees / DEGREES about y)."""
    return tf.pose(translate=[v[0], 0.0, v[1]], rotate=[0.0, DEGREES * v[2], 0.0])


def recover_pose(steps: int = 150, width: int = 48, height: int = 48, spp: int = 16, edge_samples: int = 16384,
                 edge_spp: int = 4, max_depth: int = 3, lr: float = 0.05, target_spp: int = 256,
                 final_lr: float = 0.1, clip_factor: float | None = 5.0, floor: float = 20.0,
                 silhouettes_only: bool = False) -> dict:
    """Adam on the box's pose and the camera's translation from a target rendered with both moved (each gradient
    clipped by :func:`clip` unless ``clip_factor`` is None). ``silhouettes_only``: the gradient of inverse_pose.py,
    the boundary term of camera silhouettes alone (pyclpt.gradients.edges.primary_boundary), for comparison."""
    sc = pose_scene(width, height, floor)
    params = pyclpt.traverse(sc)
    cam0 = np.asarray(params["sensor.to_world"], np.float64)

    def camera(c: np.ndarray) -> np.ndarray:
        return tf.translate([c[0], c[1], 0.0]) @ cam0

    def apply(v: np.ndarray, c: np.ndarray) -> None:
        params.update({"box.to_world": box_pose(v), "sensor.to_world": camera(c)})

    truth_v = np.array([TARGET_POSE[0], TARGET_POSE[1], TARGET_POSE[2] / DEGREES])
    truth_c = np.array(TARGET_CAMERA, np.float64)
    apply(truth_v, truth_c)
    target = pyclpt.render(sc, spp=target_spp, seed=1000, max_depth=max_depth)
    v, c = np.zeros(3), np.zeros(2)
    apply(v, c)
    opt = pyclpt.optim.Adam(lr=lr, beta_1=0.8, beta_2=0.95, params={"v": v, "c": c})
    h = {"losses": [], "pose_error": [], "camera_error": [],
         "start": pyclpt.render(sc, spp=target_spp, seed=1000, max_depth=max_depth)}
    begin = time.perf_counter()
    norms: list[float] = []
    for k in range(steps):
        opt.lr = schedule(lr, k, steps, final_lr)
        v, c = opt["v"].astype(np.float64), opt["c"].astype(np.float64)
        apply(v, c)
        image = pyclpt.render(sc, spp=spp, seed=2 * k, max_depth=max_depth)
        h["losses"].append(float(np.mean((image - target) ** 2)))
        h["pose_error"].append(np.abs(v - truth_v).tolist())
        h["camera_error"].append(np.abs(c - truth_c).tolist())
        grad = (2 * (image - target) / image.size).astype(np.float32)
        names = ["box.to_world", "sensor.to_world"]
        if silhouettes_only:  # pose relative to the box where it is now, as render_backward's
            g = primary_boundary(sc, grad, names, samples=edge_samples, seed=2 * k + 1, max_depth=max_depth,
                                 parameters=SceneParameters(sc))
        else:
            g = pyclpt.render_backward(sc, grad, spp=spp, seed=2 * k + 1, max_depth=max_depth, params=names,
                                       edge_samples=edge_samples, edge_spp=edge_spp)
        # box.to_world's gradient is of a pose D applied to the box where it is now (D = I): M(w) = D M(v)
        inv = np.linalg.inv(box_pose(v))
        gv = chain(g["box.to_world"].astype(np.float64), v, lambda w, inv=inv: box_pose(w) @ inv)
        gc = chain(g["sensor.to_world"].astype(np.float64), c, camera)
        if clip_factor is not None:
            both = clip(np.concatenate([gv, gc]), norms, clip_factor)
            gv, gc = both[:3], both[3:]
        opt.step({"v": gv.astype(np.float32), "c": gc.astype(np.float32)})
    h["seconds"] = time.perf_counter() - begin
    v, c = opt["v"].astype(np.float64), opt["c"].astype(np.float64)
    apply(v, c)
    h["pose_error"].append(np.abs(v - truth_v).tolist())
    h["camera_error"].append(np.abs(c - truth_c).tolist())
    h.update(final=pyclpt.render(sc, spp=target_spp, seed=1000, max_depth=max_depth), target=target, pose=v.tolist(),
             camera=c.tolist(), truth_pose=truth_v.tolist(), truth_camera=truth_c.tolist())
    return h


def shape_setup(width: int, height: int, rings: int, segments: int, environment: float = 0.4
                ) -> tuple[pyclpt.Scene, np.ndarray, np.ndarray]:
    """A flat-shaded, diffuse grey sphere mesh under a key and a fill area light (out of every view) and a constant
    environment (0.4: brighter than the unlit side, so that every silhouette shows); the camera in inverse_shape.py's
    first view."""
    s = sphere(rings=rings, segments=segments)
    used = np.unique(s.indices)  # the generator may leave a vertex unused: drop it
    remap = np.full(len(s.positions), -1)
    remap[used] = np.arange(len(used))
    pos, faces = s.positions[used].astype(np.float64), remap[s.indices]
    shape = pyclpt.Mesh("shape", pos.astype(np.float32), faces.astype(np.int32), 0)  # normals None: flat
    meshes = [shape]
    r = rectangle()
    for name, at, size, radiance in (("key", [2.0, 3.0, 2.0], 0.75, 16.0), ("fill", [-2.0, 3.5, -2.0], 0.6, 8.0)):
        m = tf.look_at(at, [0, 0, 0], [0, 1, 0]) @ tf.scale(size)
        meshes.append(pyclpt.Mesh(name, tf.apply_points(m, r.positions).astype(np.float32), r.indices.astype(np.int32),
                                  1, emission=(radiance,) * 3))
    scene = pyclpt.Scene(meshes, [pyclpt.Diffuse((0.6, 0.6, 0.6)), pyclpt.Diffuse((0.0, 0.0, 0.0))],
                         pyclpt.Camera(tf.look_at(VIEWS[0], [0, 0, 0])),
                         pyclpt.Film(width, height, pyclpt.ReconstructionFilter("box")), environment=(environment,) * 3,
                         name="inverse-shaded")
    return scene, pos, faces


def recover_shape(steps: int = 150, width: int = 40, height: int = 40, spp: int = 8, edge_samples: int = 8192,
                  edge_spp: int = 4, max_depth: int = 2, rings: int = 12, segments: int = 24, lam: float = 8.0,
                  lr: float = 0.03, environment: float = 0.4, final_lr: float = 0.1, views: list | None = None,
                  clip_factor: float | None = 5.0) -> dict:
    """inverse_shape.recover's large-steps Adam with both terms of the shaded images' derivative (each step's gradient
    clipped by :func:`clip` unless ``clip_factor`` is None)."""
    from scipy.sparse import identity
    from scipy.sparse.linalg import splu

    scene, start_pos, faces = shape_setup(width, height, rings, segments, environment)
    truth = tf.apply_points(TARGET, start_pos).astype(np.float64)
    params = pyclpt.traverse(scene)
    views = VIEWS if views is None else views
    set_shape, view, targets = inverse_shape.views_and_targets(scene, params, views, truth, max_depth=max_depth)
    m = (identity(len(start_pos)) + lam * laplacian(len(start_pos), faces)).tocsc()
    solve = splu(m)
    opt = pyclpt.optim.Adam(lr=lr, beta_1=0.8, beta_2=0.95, params={"u": m @ start_pos})
    h = {"losses": [], "vertex_error": []}
    norms: list[float] = []
    begin = time.perf_counter()
    for step in range(steps):
        opt.lr = schedule(lr, step, steps, final_lr)
        x = solve.solve(opt["u"].astype(np.float64))
        set_shape(x)
        h["vertex_error"].append(ellipsoid_error(x))
        gx, loss = np.zeros_like(x), 0.0
        for k in range(len(views)):
            view(k)
            seed = 2 * (step * len(views) + k)
            image = pyclpt.render(scene, spp=spp, seed=seed, max_depth=max_depth)
            loss += float(np.mean((image - targets[k]) ** 2))
            grad = (2 * (image - targets[k]) / image.size).astype(np.float32)
            g = pyclpt.render_backward(scene, grad, spp=spp, seed=seed + 1, max_depth=max_depth,
                                       params=["shape.vertex_positions"], edge_samples=edge_samples, edge_spp=edge_spp)
            gx += g["shape.vertex_positions"].reshape(-1, 3)
        h["losses"].append(loss)
        if clip_factor is not None:
            gx = clip(gx.reshape(-1), norms, clip_factor).reshape(gx.shape)
        opt.step({"u": solve.solve(gx).astype(np.float32)})  # (I + lambda L) is symmetric
    h["seconds"] = time.perf_counter() - begin
    x = solve.solve(opt["u"].astype(np.float64))
    h["vertex_error"].append(ellipsoid_error(x))
    view(0)
    h["images"] = {"target": targets[0]}
    set_shape(start_pos)
    h["images"]["start"] = pyclpt.render(scene, spp=64, seed=0, max_depth=max_depth)
    set_shape(x)
    h["images"]["final"] = pyclpt.render(scene, spp=64, seed=0, max_depth=max_depth)
    h["final"], h["truth"] = x, truth
    return h


def plot_pose(h: dict, silhouette: dict | None, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 5, figsize=(17, 3.4))
    ax[0].semilogy(h["losses"])
    ax[0].set(title="image MSE", xlabel="Adam step")
    err, cam = np.asarray(h["pose_error"]), np.asarray(h["camera_error"])
    for k, name in enumerate(("box x", "box z", f"box angle / {DEGREES:g} deg")):
        ax[1].semilogy(err[:, k] + 1e-6, label=name)
    for k, name in enumerate(("camera x", "camera y")):
        ax[1].semilogy(cam[:, k] + 1e-6, "--", label=name)
    if silhouette is not None:
        ax[0].semilogy(silhouette["losses"], ":", label="silhouettes only")
        ax[0].legend(["both terms", "silhouettes only"], fontsize=7)
        err = np.concatenate([np.asarray(silhouette["pose_error"]), np.asarray(silhouette["camera_error"])], 1)
        ax[1].semilogy(np.abs(err).max(1) + 1e-6, "k:", label="silhouettes only: largest")
    ax[1].set(title="parameter error", xlabel="Adam step")
    ax[1].legend(fontsize=7)
    finish_figure(fig, ax[2:], h, path)


def plot_shape(h: dict, silhouette: dict[str, dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 5, figsize=(17, 3.4))
    ax[0].semilogy(h["losses"])
    ax[0].set(title="image MSE (5 views, shaded)", xlabel="Adam step")
    ax[1].plot(h["vertex_error"], label="shaded, both terms")
    for label, run in silhouette.items():
        ax[1].plot(run["vertex_error"], "--", label=f"emitting, silhouettes only, {label}")
    ax[1].set(title="distance to the target surface", xlabel="Adam step")
    ax[1].legend(fontsize=7)
    finish_figure(fig, ax[2:], h["images"], path, " (view 1)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("inverse-shaded"),
                    help="folder for shaded-pose.png, shaded-shape.png and shaded.json")
    ap.add_argument("--steps", type=int, default=None, help="Adam steps (default: 100 for the pose, 150 for the shape)")
    ap.add_argument("--which", choices=("pose", "shape", "both"), default="both")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    summary: dict = {"device": pyclpt.default_device().name}
    if args.which in ("pose", "both"):
        steps = args.steps or 150
        h = recover_pose(steps=steps)
        sil = recover_pose(steps=steps, silhouettes_only=True)
        plot_pose(h, sil, args.out / "shaded-pose.png")
        summary["pose"] = {
            "steps": steps, "size": "48x48", "spp": 16, "edge_samples": 16384, "edge_spp": 4,
            "seconds": round(h["seconds"], 2), "pose": h["pose"], "truth_pose": h["truth_pose"], "camera": h["camera"],
            "truth_camera": h["truth_camera"], "pose_error_first": h["pose_error"][0],
            "pose_error_last": h["pose_error"][-1], "camera_error_first": h["camera_error"][0],
            "camera_error_last": h["camera_error"][-1], "loss_first": h["losses"][0], "loss_last": h["losses"][-1],
            "losses": h["losses"],
            "silhouettes_only": {"seconds": round(sil["seconds"], 2), "pose": sil["pose"], "camera": sil["camera"],
                                 "pose_error_last": sil["pose_error"][-1], "camera_error_last": sil["camera_error"][-1],
                                 "loss_last": sil["losses"][-1], "losses": sil["losses"]}}
    if args.which in ("shape", "both"):
        steps = args.steps or 150
        h = recover_shape(steps=steps)
        # inverse_shape.py's silhouette-only run (emitting object) at the same size, spp, edge samples and steps: with
        # its own step size and lambda (20, 0.02), and with this run's (8, 0.03)
        s = inverse_shape.recover(steps=steps)
        s2 = inverse_shape.recover(steps=steps, lam=8.0, lr=0.03)
        plot_shape(h, {"lambda 20, lr 0.02": s, "lambda 8, lr 0.03": s2}, args.out / "shaded-shape.png")
        summary["shape"] = {
            "steps": steps, "size": "40x40", "spp": 8, "views": len(VIEWS), "edge_samples": 8192, "edge_spp": 4,
            "lambda": 8.0, "lr": 0.03, "environment": 0.4, "seconds": round(h["seconds"], 2),
            "vertex_error_first": h["vertex_error"][0], "vertex_error_last": h["vertex_error"][-1],
            "loss_first": h["losses"][0], "loss_last": h["losses"][-1], "vertex_error": h["vertex_error"]}
        for key, run, lam, lr in (("silhouette_only", s, 20.0, 0.02), ("silhouette_only_lambda8", s2, 8.0, 0.03)):
            summary["shape"][key] = {"lambda": lam, "lr": lr, "seconds": round(run["seconds"], 2),
                                     "vertex_error_first": run["vertex_error"][0],
                                     "vertex_error_last": run["vertex_error"][-1], "vertex_error": run["vertex_error"]}
    path = args.out / "shaded.json"
    old = json.loads(path.read_text()) if path.exists() else {}
    path.write_text(json.dumps({**old, **summary}, indent=1) + "\n")

    def short(d):
        return {k: short(v) if isinstance(v, dict) else v for k, v in d.items() if k not in ("losses", "vertex_error")}
    print(json.dumps(short(summary), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
