"""Do pyclpt's derivatives with respect to where meshes are agree with Mitsuba 3's projective integrator?

    python -m bench.peers.mitsuba_geometry [--mitsuba-python PATH] [--seeds 8] [--spp 64] [--fd-spp 2048]
                                           [-o docs/benchmarks/mitsuba-geometry.md]

Question: for the same scene files, is d(image sum per channel)/d(motion of one mesh) by
``pyclpt.render_forward`` (interior term + boundary terms) the same as Mitsuba 3's ``prb_projective``
(forward mode, ``dr.forward``) within their noise?

Method: four 48 x 48 scenes (box filter, max depth 2: direct light; the cube's shadow 3), every shape a PLY mesh
written once and loaded by both renderers from the same dictionary (Mitsuba's ``rectangle`` is an analytic shape
with a ``to_world``, not a mesh, so it is not used):

* ``lit-square``: a diffuse square turned 20 degrees, lit by a point light over a constant sky (0.25), moving
  along x and along z: its silhouette over the sky (primary visibility) and its shading. Nothing casts a shadow,
  so the point light (which Mitsuba's projective integrators cannot differentiate shadows of) is kept.
* ``floor``: a coloured diffuse floor filling the view under a rectangular area light, moving along z and turning
  about x: no outline moves in the image or in the light, the interior term alone.
* ``soft-shadow``: tests/test_shadows.py's soft-shadow scene (a black square between a rectangular area light and
  a floor), the occluder moving along x, out of the camera's view: the outline of its shadow only.
* ``cube-shadow``: a cube of 24 corners split at its edges (as both renderers' cubes are) over a floor under an
  area light, beside a wall the floor lights, moving along x, at max depth 3: its silhouettes and creases, its
  shadow, and its shadow in the light the wall receives after a bounce.
* ``mirror``: an emitter square out of the camera's view, seen only in a perfect mirror (a smooth ``conductor``)
  turned 45 degrees, moving along x (away from the mirror), at max depth 3: its outline seen in a planar mirror.

A motion is a 4x4 tangent T of the mesh's pose: the vertices move as v + s (T v). pyclpt: ``render_forward(scene,
"SHAPE.to_world", T)`` summed over pixels, ``--seeds`` seeds at ``--spp`` (65,536 edge samples, 4 shading points
a pixel for the outlines in the light): the mean and its standard error. Mitsuba 3.9.1 ``llvm_ad_rgb``: the
vertices of ``SHAPE.vertex_positions`` set to rest + s (T rest) with s attached, ``mi.render`` with
``prb_projective`` at the same spp (which sets sppc = sppp = sppi), ``dr.forward(s)``, ``--seeds`` seeds.
A third column: central differences of pyclpt's primal renders, (I(+h) - I(-h)) / 2h with h = 0.02, the same seed
on both sides, ``--fd-spp`` spp, averaged over two seeds. The Mitsuba side runs in the Python of its own
environment (``--mitsuba-python`` or ``$PYCLPT_MITSUBA_PYTHON``) as a subprocess of this module
(``--mitsuba-side``); the primal image sums of both renderers are printed too, as a check that they render the
same scene.

Answer (AMD EPYC, 2 cores shared with other work; pyclpt on PoCL; 16 seeds x 64 spp a side; the table is
docs/benchmarks/mitsuba-geometry.md, which this script writes): yes. The five motions agree within 2.4 standard
errors of the difference (lit square x: 4.08 vs 4.14, z: 66.14 vs 66.24; floor z: 119.51 vs 119.56, rotation
about x: -29.56 vs -29.48, -29.53 on 48 other seeds; soft shadow: 54.3 +- 1.6 vs 52.1 +- 0.3, 52.7 +- 0.3 with
edge_spp 128; red channel, pyclpt vs Mitsuba) and with the finite differences (4.11, 66.10, 119.56, -29.48,
52.24). The primal images agree within 0.4 %. Mitsuba's projective sampling of the soft shadow's outline costs
7.5 s a seed here, pyclpt's 0.1 s (edge_spp 4), which is the noisier of the two there.

The square seen in a mirror (2026-11-28, PoCL, 8 seeds of 64 spp a side): pyclpt -156.80 (red; the same to 5 digits
on every seed), the exact value (the virtual square's area A = 115.0 pixels at depth D = 5.5 shrinks at -2 A / D
per unit, times the radiance difference 3.75); Mitsuba 0 on every seed (its projective integrator connects a
boundary segment to the sensor, which no connection reaches through a delta vertex); the finite differences -159.8
(h = 0.02; -161.0 and -157.6 at h = 0.01 and 0.04 with 4096 spp: their spread).

The cube's shadow (2026-11-28, PoCL, the same settings): red -20.5 +- 1.8 (pyclpt) vs -19.6 +- 0.7 (Mitsuba), green
-23.8 +- 1.7 vs -21.6 +- 0.6, finite differences -18.5 and -21.8; in blue pyclpt -18.6 +- 1.7 and the finite
differences -16.5 agree, Mitsuba's -3.1 +- 0.6 does not (its primal image agrees with pyclpt's within 0.1 %).
"""
from __future__ import annotations

import argparse
import json
import math
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

W = H = 48
MAX_DEPTH = 2
STEP = 0.02
LLVM = "/usr/lib/x86_64-linux-gnu/libLLVM-19.so"
ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "benchmarks" / "mitsuba-geometry.md"
CHANNELS = "RGB"


# -- transforms and meshes (numpy only: this module also runs in Mitsuba's environment) --------------------------
def translate(v) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = v
    return m


def scale(v) -> np.ndarray:
    return np.diag([*np.broadcast_to(np.asarray(v, np.float64), (3,)), 1.0])


def rotate(axis, degrees: float) -> np.ndarray:
    """Rodrigues' rotation about ``axis`` (right-handed, as Mitsuba's)."""
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = math.radians(degrees)
    m = np.eye(4)
    m[:3, :3] = np.eye(3) + math.sin(t) * k + (1 - math.cos(t)) * k @ k
    return m


def look_at(origin, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Mitsuba's look_at: columns (left, up, direction, origin)."""
    o, t, u = (np.asarray(x, np.float64) for x in (origin, target, up))
    d = (t - o) / np.linalg.norm(t - o)
    left = np.cross(u, d)
    left /= np.linalg.norm(left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, np.cross(d, left), d, o
    return m


def square(m: np.ndarray) -> np.ndarray:
    """The corners of Mitsuba's rectangle ([-1, 1]^2 at z = 0, normal +z) moved by ``m``: (4, 3)."""
    corners = np.array([[-1, -1, 0, 1], [1, -1, 0, 1], [1, 1, 0, 1], [-1, 1, 0, 1]], np.float64)
    return (corners @ np.asarray(m, np.float64).T)[:, :3]


def moved(vertices: np.ndarray, tangent: np.ndarray, s: float) -> np.ndarray:
    """Vertices moved by s along a pose tangent: v + s (T v)."""
    t = np.asarray(tangent, np.float64)
    return vertices + s * (vertices @ t[:3, :3].T + t[:3, 3])


_AXES = np.eye(3)


def cube(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[-1, 1]^3 moved by ``m``: (24, 3) corners, four to a face, and (12, 3) triangles wound outwards."""
    corners, faces = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            u, v = _AXES[(axis + 1) % 3], _AXES[(axis + 2) % 3]
            n = sign * _AXES[axis]
            quad = [n + a * u + b * v for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            base = len(corners)
            corners += quad
            tri = [(0, 1, 2), (0, 2, 3)] if sign > 0 else [(0, 2, 1), (0, 3, 2)]  # n = u x v on the + side
            faces += [tuple(base + k for k in t) for t in tri]
    c = np.c_[np.array(corners), np.ones(len(corners))] @ np.asarray(m, np.float64).T
    return c[:, :3], np.array(faces)


def write_ply(path: Path, vertices: np.ndarray, faces: np.ndarray | None = None) -> Path:
    """A triangle mesh; by default two triangles (0 1 2, 0 2 3): the winding of Mitsuba's rectangle, so the same
    face normal."""
    faces = np.array([[0, 1, 2], [0, 2, 3]]) if faces is None else np.asarray(faces)
    path.write_text(f"ply\nformat ascii 1.0\nelement vertex {len(vertices)}\nproperty float x\nproperty float y\n"
                    f"property float z\nelement face {len(faces)}\nproperty list uchar int vertex_indices\n"
                    "end_header\n" + "".join(f"{x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in vertices)
                    + "".join(f"3 {a} {b} {c}\n" for a, b, c in faces))
    return path


def _rgb(v) -> dict:
    return {"type": "rgb", "value": [float(x) for x in np.broadcast_to(v, (3,))]}


def _diffuse(v) -> dict:
    return {"type": "diffuse", "reflectance": _rgb(v)}


def _sensor(origin, fov: float = 40.0) -> dict:
    return {"type": "perspective", "fov": fov, "fov_axis": "x", "to_world": look_at(origin, [0, 0, 0]).tolist(),
            "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"}, "pixel_format": "rgb"}}


#: scene -> {shape: corners}, the shapes' rest poses
def shapes(name: str) -> dict[str, np.ndarray]:
    if name == "lit-square":
        return {"shape": square(rotate([0, 1, 0], 20) @ scale([0.8, 0.6, 1.0]))}
    if name == "floor":
        return {"floor": square(scale(6.0)), "light": square(translate([0, 1.2, 1.5]) @ rotate([1, 0, 0], 180)
                                                             @ scale(0.25))}
    if name == "soft-shadow":  # tests/test_shadows.py's _soft_scene
        return {"light": square(translate([-4, 0, 3]) @ rotate([0, 1, 0], 180 - 53) @ scale(0.25)),
                "floor": square(scale(6.0)),
                "occluder": square(translate([-2, 0, 1.5]) @ rotate([0, 0, 1], 25) @ scale(0.3))}
    if name == "cube-shadow":  # a cube of split corners over a floor, its soft shadow also seen after a bounce
        return {"light": square(translate([1.2, 0.4, 2.0]) @ rotate([0, 1, 0], 180 + 20) @ scale(0.35)),
                "floor": square(scale(3.0)), "wall": square(translate([-1.2, 0, 1.0]) @ rotate([0, 1, 0], 90)
                                                            @ scale([1.0, 3.0, 1.0])),
                "cube": cube(translate([-0.1, 0.1, 0.55]) @ rotate([1, 1, 0], 30) @ scale(0.25))[0]}
    if name == "mirror":  # an emitter square out of the camera's view, seen in a mirror turned 45 degrees
        return {"mirror": square(rotate([0, 1, 0], 45) @ scale(1.5)),
                "shape": square(translate([2.5, 0, 0]) @ rotate([0, 1, 0], -90) @ scale([0.5, 0.4, 1.0]))}
    raise KeyError(name)


SCENES = ("lit-square", "floor", "soft-shadow", "cube-shadow", "mirror")
#: the depth of each scene's paths: direct light, and the cube's shadow also in the light the wall throws back; the
#: mirror's emitter seen after its delta bounce
DEPTHS = {"cube-shadow": 3, "mirror": 3}


def depth_of(name: str) -> int:
    return DEPTHS.get(name, MAX_DEPTH)
_TX, _TZ = translate([1, 0, 0]) - np.eye(4), translate([0, 0, 1]) - np.eye(4)
_RX = np.zeros((4, 4))
_RX[1, 2], _RX[2, 1] = -1.0, 1.0  # d/dtheta of a rotation about x at 0 (radians)
#: scene -> [(motion label, shape, tangent)]
MOTIONS: dict[str, list[tuple[str, str, np.ndarray]]] = {
    "lit-square": [("translate x", "shape", _TX), ("translate z", "shape", _TZ)],
    "floor": [("translate z", "floor", _TZ), ("rotate x (rad)", "floor", _RX)],
    "soft-shadow": [("translate x", "occluder", _TX)],
    "cube-shadow": [("translate x", "cube", _TX)],
    "mirror": [("translate x", "shape", _TX)],
}


def scene_dict(name: str, folder: Path, move: tuple[str, np.ndarray, float] | None = None) -> dict:
    """The Mitsuba 3 scene dictionary of ``name`` (to_world as 4x4 lists), its meshes written to ``folder``;
    ``move`` = (shape, tangent, s) moves one mesh's vertices (finite differences)."""
    files = {}
    for shape, verts in shapes(name).items():
        if move is not None and move[0] == shape:
            verts = moved(verts, move[1], move[2])
        faces = cube(np.eye(4))[1] if len(verts) == 24 else None
        files[shape] = str(write_ply(folder / f"{name}-{shape}.ply", verts, faces))
    if name == "lit-square":
        return {"type": "scene", "sensor": _sensor([0, 0, 5]),
                "env": {"type": "constant", "radiance": _rgb(0.25)},
                "light": {"type": "point", "position": [1.0, 1.0, 4.0], "intensity": _rgb(30.0)},
                "shape": {"type": "ply", "filename": files["shape"], "bsdf": _diffuse([0.6, 0.5, 0.4])}}
    if name == "floor":
        return {"type": "scene", "sensor": _sensor([0, 0, 3]),
                "floor": {"type": "ply", "filename": files["floor"], "bsdf": _diffuse([0.7, 0.5, 0.3])},
                "light": {"type": "ply", "filename": files["light"], "bsdf": _diffuse(0.0),
                          "emitter": {"type": "area", "radiance": _rgb(10.0)}}}
    if name == "cube-shadow":
        return {"type": "scene", "sensor": _sensor([0.3, 0, 3.2], fov=55.0),
                "light": {"type": "ply", "filename": files["light"], "bsdf": _diffuse(0.0),
                          "emitter": {"type": "area", "radiance": _rgb(20.0)}},
                "floor": {"type": "ply", "filename": files["floor"], "bsdf": _diffuse(0.6)},
                "wall": {"type": "ply", "filename": files["wall"], "bsdf": _diffuse([0.8, 0.5, 0.3])},
                "cube": {"type": "ply", "filename": files["cube"], "bsdf": _diffuse([0.3, 0.4, 0.6])}}
    if name == "mirror":
        return {"type": "scene", "sensor": _sensor([0, 0, 3]),
                "env": {"type": "constant", "radiance": _rgb(0.25)},
                "mirror": {"type": "ply", "filename": files["mirror"], "bsdf": {"type": "conductor"}},
                "shape": {"type": "ply", "filename": files["shape"], "bsdf": _diffuse(0.0),
                          "emitter": {"type": "area", "radiance": _rgb([4.0, 3.0, 2.0])}}}
    return {"type": "scene", "sensor": _sensor([0, 0, 3]),
            "light": {"type": "ply", "filename": files["light"], "bsdf": _diffuse(0.0),
                      "emitter": {"type": "area", "radiance": _rgb(80.0)}},
            "floor": {"type": "ply", "filename": files["floor"], "bsdf": _diffuse(0.5)},
            "occluder": {"type": "ply", "filename": files["occluder"], "bsdf": _diffuse(0.0)}}


def mean_se(rows) -> tuple[np.ndarray, np.ndarray]:
    """Per-column mean and standard error of the mean over rows (seeds)."""
    a = np.asarray(rows, np.float64).reshape(len(rows), -1)
    se = a.std(0, ddof=1) / math.sqrt(len(a)) if len(a) > 1 else np.full(a.shape[1], np.nan)
    return a.mean(0), se


def table(results: dict) -> str:
    """The markdown table: one row per scene, motion and channel. ``results[scene][motion]`` holds ``pyclpt``
    and ``mitsuba`` (per-seed RGB sums) and ``fd`` (RGB)."""
    lines = ["| scene | motion | channel | pyclpt mean ± se | Mitsuba prb_projective mean ± se | FD (pyclpt) "
             "| difference / se |", "|---|---|---|---|---|---|---|"]
    for scene, motions in results.items():
        for motion, r in motions.items():
            pm, ps = mean_se(r["pyclpt"])
            mm, ms = mean_se(r["mitsuba"])
            fd = np.asarray(r["fd"], np.float64)
            for c in range(3):
                se = math.hypot(ps[c], ms[c])
                z = f"{(pm[c] - mm[c]) / se:+.2f}" if se > 1e-4 * max(abs(pm[c]), abs(mm[c]), 1.0) else "-"
                lines.append(f"| {scene} | {motion} | {CHANNELS[c]} | {pm[c]:.3f} ± {ps[c]:.3f} | "
                             f"{mm[c]:.3f} ± {ms[c]:.3f} | {fd[c]:.3f} | {z} |")
    return "\n".join(lines)


# -- Mitsuba's side (run by the Python of Mitsuba's environment) ---------------------------------------------------
def mitsuba_side(a: argparse.Namespace) -> dict:
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(a.variant)

    def convert(d):
        if isinstance(d, dict):
            return {k: (mi.ScalarTransform4f(v) if k == "to_world" else convert(v)) for k, v in d.items()}
        return d

    out: dict = {"mitsuba": mi.__version__, "variant": a.variant, "integrator": a.integrator, "scenes": {}}
    folder = Path(tempfile.mkdtemp(prefix="mitsuba-geometry-"))
    for name in a.scenes:
        d = convert(scene_dict(name, folder))
        d["integrator"] = {"type": a.integrator, "max_depth": depth_of(name)}
        scene = mi.load_dict(d)
        params = mi.traverse(scene)
        primal = np.asarray(mi.render(scene, spp=a.spp, seed=12345), np.float64)
        entry: dict = {"primal": primal.sum((0, 1)).tolist(), "motions": {}}
        for motion, shape, tangent in MOTIONS[name]:
            key = f"{shape}.vertex_positions"
            rest = dr.unravel(mi.Point3f, params[key])
            t = np.asarray(tangent, np.float64)
            vel = mi.Vector3f(*(t[i, 0] * rest.x + t[i, 1] * rest.y + t[i, 2] * rest.z + t[i, 3] for i in range(3)))
            sums, seconds = [], []
            for seed in range(a.seeds + 1):  # the first round compiles Dr.Jit's kernels: not kept
                start = time.perf_counter()
                s = mi.Float(0.0)
                dr.enable_grad(s)
                params[key] = dr.ravel(rest + s * vel)
                params.update()
                image = mi.render(scene, params, spp=a.spp, seed=1000 + seed)
                dr.forward(s)
                g = np.asarray(dr.grad(image), np.float64)
                if seed:
                    sums.append(g.sum((0, 1))[:3].tolist())
                    seconds.append(time.perf_counter() - start)
                params[key] = dr.ravel(rest)
                params.update()
            entry["motions"][motion] = {"sums": sums, "seconds": seconds}
        out["scenes"][name] = entry
    return out


def run_mitsuba(python: str, a: argparse.Namespace) -> dict:
    from pyclpt.common import env as envvars  # the pyclpt side only: Mitsuba's environment has no pyclpt

    env = envvars.child_environment()
    env.setdefault("DRJIT_LIBLLVM_PATH", LLVM)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "mitsuba.json"
        cmd = [python, "-m", "bench.peers.mitsuba_geometry", "--mitsuba-side", "--spp", str(a.spp), "--seeds",
               str(a.seeds), "--integrator", a.integrator, "--variant", a.variant, "--scenes", *a.scenes,
               "--json", str(out)]  # a file: Mitsuba's log (colour codes included) goes to stdout
        run = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
        if run.returncode != 0 or not out.is_file():
            raise RuntimeError(f"Mitsuba's side failed ({' '.join(cmd)}):\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}")
        return json.loads(out.read_text())


# -- pyclpt's side -------------------------------------------------------------------------------------------------
def pyclpt_side(a: argparse.Namespace) -> dict:
    import pyclpt

    out: dict = {"scenes": {}}
    folder = Path(tempfile.mkdtemp(prefix="pyclpt-geometry-"))
    for name in a.scenes:
        scene = pyclpt.load_dict(scene_dict(name, folder))
        primal = pyclpt.render(scene, spp=a.spp, seed=12345, max_depth=depth_of(name)).astype(np.float64)
        entry: dict = {"primal": primal.sum((0, 1)).tolist(), "motions": {}}
        for motion, shape, tangent in MOTIONS[name]:
            sums, seconds = [], []
            for seed in range(a.seeds):
                start = time.perf_counter()
                g = pyclpt.render_forward(scene, f"{shape}.to_world", tangent, spp=a.spp, seed=1000 + seed,
                                          max_depth=depth_of(name), edge_samples=a.edge_samples,
                                          edge_spp=a.edge_spp)
                sums.append(np.asarray(g, np.float64).sum((0, 1)).tolist())
                seconds.append(time.perf_counter() - start)
            start = time.perf_counter()
            fd = np.zeros(3)
            for seed in (7, 8):
                side = []
                for s in (STEP, -STEP):
                    sc = pyclpt.load_dict(scene_dict(name, folder, (shape, tangent, s)))
                    side.append(pyclpt.render(sc, spp=a.fd_spp, seed=seed, max_depth=depth_of(name)
                                              ).astype(np.float64))
                fd += (side[0] - side[1]).sum((0, 1)) / (2 * STEP) / 2
            entry["motions"][motion] = {"sums": sums, "seconds": seconds, "fd": fd.tolist(),
                                        "fd_seconds": time.perf_counter() - start}
        out["scenes"][name] = entry
    if a.more:
        out["more"] = more_runs(folder)
    return out


#: ``--more``: further pyclpt runs (label, scene, motion, seeds, spp, edge_spp, first seed) of the motions whose
#: difference was largest in the first run, on other seeds, and finite differences with other steps
MORE = [("render_forward, 48 other seeds", "floor", "rotate x (rad)", 48, 64, 4, 2000),
        ("render_forward, edge_spp 32", "soft-shadow", "translate x", 16, 64, 32, 1000),
        ("render_forward, edge_spp 32, 48 other seeds", "soft-shadow", "translate x", 48, 64, 32, 3000),
        ("render_forward, edge_spp 128, 16 other seeds", "soft-shadow", "translate x", 16, 64, 128, 3000)]
MORE_FD = [("floor", "rotate x (rad)", 0.01), ("floor", "rotate x (rad)", 0.04)]  # 4 seeds of 2048 spp


def more_runs(folder: Path) -> list[dict]:
    """The runs of :data:`MORE` and :data:`MORE_FD`: the red channel's mean and standard error."""
    import pyclpt

    rows = []
    for label, name, motion, seeds, spp, edge_spp, first in MORE:
        _, shape, tangent = next(m for m in MOTIONS[name] if m[0] == motion)
        scene = pyclpt.load_dict(scene_dict(name, folder))
        g = [float(pyclpt.render_forward(scene, f"{shape}.to_world", tangent, spp=spp, seed=first + k,
                                         max_depth=depth_of(name), edge_spp=edge_spp).astype(np.float64)[..., 0].sum())
             for k in range(seeds)]
        mean, se = mean_se([[x] for x in g])
        rows.append({"scene": name, "motion": motion, "run": f"{label} ({seeds} x {spp} spp)",
                     "mean": float(mean[0]), "se": float(se[0])})
    for name, motion, h in MORE_FD:
        _, shape, tangent = next(m for m in MOTIONS[name] if m[0] == motion)
        fd = []
        for seed in (11, 12, 13, 14):
            side = [pyclpt.render(pyclpt.load_dict(scene_dict(name, folder, (shape, tangent, s))), spp=2048,
                                  seed=seed, max_depth=depth_of(name)).astype(np.float64)[..., 0].sum()
                    for s in (h, -h)]
            fd.append([(side[0] - side[1]) / (2 * h)])
        mean, se = mean_se(fd)
        rows.append({"scene": name, "motion": motion, "run": f"central differences, h = {h} (4 seeds x 2048 spp)",
                     "mean": float(mean[0]), "se": float(se[0])})
    return rows


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


NOTES = """Reading the tables. A scene's three channels come from the same paths (the colours are in proportion),
so each motion is one comparison, not three. On the two estimators:

* the lit square keeps its point light because nothing casts a shadow there; Mitsuba's projective integrators
  sample no boundary of a point light's shadow (pyclpt's `shadow_boundary` does: docs/differentiable.md), so a
  scene with one would compare nothing; its sky is a constant environment. Its motion along x is small (what the
  square gains on one side it nearly loses on the other); Mitsuba's 64 primary-visibility samples a pixel
  (sppp) are noisier there than pyclpt's 65,536 edge samples;
* the floor checks the interior term alone (no outline moves in the image or in the light). When the rotation
  about x lands 2 or more standard errors off, the further runs (other seeds, other steps of the finite
  differences) say whether it is noise;
* the soft shadow is the outline of the occluder in the light the floor receives: pyclpt samples it from
  `edge_spp` shading points a pixel (4 by default), Mitsuba by projective sampling with an octree guide
  (sppi = 64); pyclpt's values per seed are heavy-tailed at small `edge_spp`, so a standard error from 16
  seeds is rough;
* the cube's shadow (max depth 3): a cube whose 24 corners are split at its edges (four to a face, as both
  renderers' cubes are) over a floor under an area light, beside a wall the floor lights: its outlines in the
  camera's view and in the light the floor receives, and the floor's shadow in the light the wall receives
  after a bounce (pyclpt's later vertices, docs/differentiable.md). The other scenes have direct light only
  (max depth 2); Mitsuba's film `sample_border` is off (no shape leaves the view);
* the mirror (max depth 3; 8 seeds a side, added to the page from its own run): an emitter square seen only in a
  perfect planar mirror, moving away from it. pyclpt's value is the exact one (-2 A / D x the radiance difference:
  -156.80 in red); Mitsuba's projective integrator connects boundary segments to the sensor and has no outline
  seen through a delta reflection, so 0; pyclpt's finite differences spread by 2 % with their step
  (-161.0, -159.8, -157.6 at h = 0.01, 0.02, 0.04).

Timings are of a machine shared with other work (2 cores, other processes running), Dr.Jit's LLVM backend and
PoCL on the same CPU; the whole pyclpt side includes the further runs of `--more`."""


def page(results: dict, mine: dict, theirs: dict, a: argparse.Namespace) -> str:
    primal = ["| scene | image sum R G B, pyclpt | image sum R G B, Mitsuba |", "|---|---|---|"]
    timing = ["| scene | motion | pyclpt render_forward, s/seed | Mitsuba render + dr.forward, s/seed "
              "| pyclpt FD (4 renders), s |", "|---|---|---|---|---|"]
    for name in a.scenes:
        p, m = mine["scenes"][name], theirs["scenes"][name]
        primal.append(f"| {name} | {' '.join(f'{x:.2f}' for x in p['primal'])} | "
                      f"{' '.join(f'{x:.2f}' for x in m['primal'])} |")
        for motion in p["motions"]:
            pm, mm = p["motions"][motion], m["motions"][motion]
            timing.append(f"| {name} | {motion} | {np.median(pm['seconds']):.2f} | {np.median(mm['seconds']):.2f} | "
                          f"{pm['fd_seconds']:.1f} |")
    return "\n".join([
        "# Geometry gradients against Mitsuba 3",
        "",
        "d(image sum per channel)/d(motion of one mesh), 48 x 48, box filter, max depth 2 (the cube's shadow, the "
        "mirror: 3), by pyclpt's `render_forward` (interior + boundary terms), by Mitsuba 3's `prb_projective` in "
        "forward mode and by central differences of pyclpt's primal renders; made by "
        "`bench/peers/mitsuba_geometry.py` (its docstring describes the scenes and the method).",
        "",
        f"CPU: {cpu_model()}; pyclpt on {mine['device']}; Mitsuba {theirs['mitsuba']} `{theirs['variant']}`, "
        f"`{theirs['integrator']}`. Command: `python -m bench.peers.mitsuba_geometry --seeds {a.seeds} --spp {a.spp} "
        f"--fd-spp {a.fd_spp}{' --more' if mine.get('more') else ''}` ({a.seeds} seeds of {a.spp} spp on either "
        f"side, Mitsuba's sppc = sppp = sppi = "
        f"{a.spp}; pyclpt's boundary terms with {a.edge_samples} edge samples and {a.edge_spp} shading points a "
        f"pixel; finite differences h = {STEP}, {a.fd_spp} spp, two seeds). The difference is in standard errors of "
        "the difference of the two means (the finite differences have their own noise, not given). The raw "
        f"results are `{a.json.name}` beside this page (`--from-json` writes the page again from them).",
        "",
        table(results),
        "",
        "The primal images, a check that both render the same scene (image sums, "
        f"{a.spp} spp, one seed):",
        "",
        *primal,
        "",
        "Seconds (medians over the seeds; Mitsuba's first round, which compiles its kernels, not counted"
        + (f"; the whole Mitsuba side {theirs['wall_s']:.0f} s, the whole pyclpt side {mine['wall_s']:.0f} s"
           if "wall_s" in theirs and "wall_s" in mine else "") + "):",
        "",
        *timing,
        "",
        *(["Further pyclpt runs (`--more`), the red channel (the others are in proportion), mean ± se:", "",
           "| scene | motion | run | d(red sum) |", "|---|---|---|---|"]
          + [f"| {r['scene']} | {r['motion']} | {r['run']} | {r['mean']:.3f} ± {r['se']:.3f} |"
             for r in mine["more"]]
          + [""] if mine.get("more") else []),
        NOTES,
        "",
    ])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mitsuba-side", action="store_true", help="run Mitsuba's side here and print JSON")
    ap.add_argument("--mitsuba-python", default=None,
                    help="the python of an environment with mitsuba (default $PYCLPT_MITSUBA_PYTHON)")
    ap.add_argument("--scenes", nargs="+", choices=SCENES, default=list(SCENES))
    ap.add_argument("--seeds", type=int, default=16)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--fd-spp", type=int, default=4096)
    ap.add_argument("--edge-samples", type=int, default=65536)
    ap.add_argument("--edge-spp", type=int, default=4)
    ap.add_argument("--integrator", default="prb_projective")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--more", action="store_true", help="further pyclpt runs (MORE, MORE_FD) listed on the page")
    ap.add_argument("-o", "--output", type=Path, default=PAGE)
    ap.add_argument("--json", type=Path, default=None,
                    help="write the raw results here (default: the page's path with .json)")
    ap.add_argument("--mitsuba-json", type=Path, default=None,
                    help="use the output of an earlier Mitsuba side (--mitsuba-side --json FILE) instead of running it")
    ap.add_argument("--from-json", type=Path, default=None,
                    help="write the page from the raw results of an earlier run (its --json) instead of rendering")
    a = ap.parse_args(argv)
    if a.json is None and not a.mitsuba_side:
        a.json = a.output.with_suffix(".json")
    if a.mitsuba_side:
        text = json.dumps(mitsuba_side(a))
        if a.json:
            a.json.write_text(text)
        else:
            print(text)
        return 0
    from pyclpt.common import env as envvars  # the pyclpt side from here: Mitsuba's environment has no pyclpt

    a.mitsuba_python = a.mitsuba_python or envvars.get("PYCLPT_MITSUBA_PYTHON")
    t0 = t1 = t2 = time.perf_counter()
    if a.from_json:
        raw = json.loads(a.from_json.read_text())
        mine, theirs = raw["pyclpt"], raw["mitsuba"]
    elif not (a.mitsuba_python or a.mitsuba_json):
        print("mitsuba_geometry: give --mitsuba-python or set PYCLPT_MITSUBA_PYTHON", file=sys.stderr)
        return 2
    else:
        theirs = json.loads(a.mitsuba_json.read_text()) if a.mitsuba_json else run_mitsuba(a.mitsuba_python, a)
        t1 = time.perf_counter()
        if a.json and not a.mitsuba_json:  # kept before pyclpt's side runs (reuse: --mitsuba-json)
            theirs["wall_s"] = t1 - t0
            a.json.with_name(a.json.stem + "-mitsuba.json").write_text(json.dumps(theirs))
        mine = pyclpt_side(a)
        t2 = time.perf_counter()
        if not a.mitsuba_json:
            theirs["wall_s"] = t1 - t0
        mine["wall_s"] = t2 - t1
    mine.setdefault("device", f"PYCLPT_DEVICE={envvars.get('PYCLPT_DEVICE')}" if envvars.get("PYCLPT_DEVICE")
                    else "the default OpenCL device")
    results = {name: {motion: {"pyclpt": mine["scenes"][name]["motions"][motion]["sums"],
                               "mitsuba": theirs["scenes"][name]["motions"][motion]["sums"],
                               "fd": mine["scenes"][name]["motions"][motion]["fd"]}
                      for motion in mine["scenes"][name]["motions"]} for name in a.scenes}
    text = page(results, mine, theirs, a)
    print(text)
    print(f"Mitsuba's side {t1 - t0:.0f} s, pyclpt's side {t2 - t1:.0f} s", file=sys.stderr)
    a.output.parent.mkdir(parents=True, exist_ok=True)
    a.output.write_text(text)
    if a.json and not a.from_json:
        a.json.write_text(json.dumps({"pyclpt": mine, "mitsuba": theirs}, indent=1))
        a.json.with_name(a.json.stem + "-mitsuba.json").unlink(missing_ok=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
