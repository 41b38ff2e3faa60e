"""Emitters (cl/scene/lights.h, pyclpt/light_buffers.py, pyclpt/scene/sky/): environment maps with
importance sampling, point lights, the baked sun and sky.

Device-level checks call lights.h through a small test kernel on a real packed scene: the
envmap lookup against Mitsuba 3's own ``envmap`` (tests/data/envmap-mitsuba3-eval.npz) and a
numpy reference, its sampling against its pdf (chi-square over the sampling cells), the pdf's
normalisation. Render-level checks compare with analytic or quadrature values.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import pyclpt
from pyclpt.buffers.lights import (
    LIGHT_CDF,
    LIGHT_ENVMAP,
    LIGHT_PMF,
    LIGHT_POINT,
    LIGHT_PRIM,
    LIGHT_TRIANGLE,
    LIGHT_TYPE,
    pack_lights,
)
from pyclpt.buffers.materials import TextureTable
from pyclpt.buffers.scene import SceneBuffers, pack_scene
from pyclpt.scene.model import Envmap, PointLight
from pyclpt.scene.sky import SunTime, directional_sun_05, sunsky_envmap, texel_directions
from pyclpt.scene.sky.bake import row_hat_solid_angle
from pyclpt.scene.sky.sun import SUN_RADIUS_DEG, sun_radiance_rgb_05
from pyclpt.scene.transform import rotate
from scenes import FRONT_CAMERA, object_under_sky, sensor

cl = pytest.importorskip("pyopencl")
stats = pytest.importorskip("scipy.stats")

DATA = Path(__file__).parent / "data"
CLASSROOM_SUN = np.array([-0.865804, 0.416766, -0.276929])

KERNELS = r"""
#include "scene/lights.h"

/* u: (u_select, u1, u2) per item. out: wi[3] dist radiance[3] pdf delta ok eval_radiance[3] eval_pdf, _, _,
 * then the same sample with an environment's radiance deferred (ENV_DEFERRED): wi[3] pdf radiance[3] ok */
__kernel void light_sample_k(SCENE_PARAMS, __global const float* p, __global const float* u,
                             __global float* out) {
    int i = get_global_id(0);
    Scene sc = SCENE_INIT;
    LightSample ls;
    ls.wi = v3_splat(0.0f);
    ls.dist = 0.0f;
    ls.radiance = v3_splat(0.0f);
    ls.pdf = 0.0f;
    ls.delta = false;
    bool ok = light_sample(&sc, load3(p, 0), u[3 * i], v2(u[3 * i + 1], u[3 * i + 2]), &ls, true);
    float eval_pdf;
    vec3 le = env_eval(&sc, ls.wi, true, &eval_pdf);
    __global float* o = out + 24 * i;
    LightSample later = ls;
    bool later_ok = light_sample(&sc, load3(p, 0), u[3 * i], v2(u[3 * i + 1], u[3 * i + 2]), &later, false);
    store3(o + 16, 0, later.wi);
    o[19] = later.pdf;
    store3(o + 20, 0, later.radiance);
    o[23] = later_ok ? 1.0f : 0.0f;
    store3(o, 0, ls.wi);
    o[3] = ls.dist;
    store3(o + 4, 0, ls.radiance);
    o[7] = ls.pdf;
    o[8] = ls.delta ? 1.0f : 0.0f;
    o[9] = ok ? 1.0f : 0.0f;
    store3(o + 10, 0, le);
    o[13] = eval_pdf;
    o[14] = 0.0f;
    o[15] = 0.0f;
}

/* out: radiance[3] pdf of the environment along each world direction */
__kernel void env_eval_k(SCENE_PARAMS, __global const float* dirs, __global float* out) {
    int i = get_global_id(0);
    Scene sc = SCENE_INIT;
    float pdf;
    vec3 le = env_eval(&sc, load3(dirs, i), true, &pdf);
    store3(out + 4 * i, 0, le);
    out[4 * i + 3] = pdf;
}
"""


# --------------------------------------------------------------------------------------------
# helpers


def small_scene(environment=None, lights=(), **shape) -> pyclpt.Scene:
    """A unit quad facing +z at the origin (diffuse 0.5), seen from z = 4, with the given emitters."""
    d = {"type": "scene", "sensor": sensor(FRONT_CAMERA, fov=30.0, size=16),
         "quad": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": 0.5}, **shape}}
    scene = pyclpt.load_dict(d, name="lights-test")
    scene.environment = environment
    scene.lights = list(lights)
    return scene


class LightKit:
    """lights.h on the device for one packed scene."""

    def __init__(self, device, scene: pyclpt.Scene) -> None:
        from pyclpt.device.program import build_program

        self.device = device
        self.buffers = SceneBuffers(scene, device)
        self.prg = build_program(device, source=KERNELS, defines=self.buffers.defines, name="test_lights")
        self.args = self.buffers.args(8, 8)

    def _run(self, name: str, n: int, inputs: list[np.ndarray], width: int) -> np.ndarray:
        ctx, queue, mf = self.device.context, self.device.queue, cl.mem_flags
        bufs = [cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a, np.float32))
                for a in inputs]
        out = np.empty((n, width), np.float32)
        obuf = cl.Buffer(ctx, mf.WRITE_ONLY, out.nbytes)
        cl.Kernel(self.prg, name)(queue, (n,), None, *self.args, *bufs, obuf)
        cl.enqueue_copy(queue, out, obuf)
        queue.finish()
        return out

    def sample(self, u: np.ndarray, p=(0.0, 0.0, 0.0)) -> dict[str, np.ndarray]:
        u = np.ascontiguousarray(u, np.float32).reshape(-1, 3)
        o = self._run("light_sample_k", len(u), [np.asarray(p, np.float32), u], 24)
        return {"wi": o[:, 0:3], "dist": o[:, 3], "radiance": o[:, 4:7], "pdf": o[:, 7], "delta": o[:, 8] > 0.5,
                "ok": o[:, 9] > 0.5, "eval_radiance": o[:, 10:13], "eval_pdf": o[:, 13],
                "later_wi": o[:, 16:19], "later_pdf": o[:, 19], "later_radiance": o[:, 20:23],
                "later_ok": o[:, 23] > 0.5}

    def eval(self, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dirs = np.ascontiguousarray(dirs, np.float32).reshape(-1, 3)
        o = self._run("env_eval_k", len(dirs), [dirs], 4)
        return o[:, :3], o[:, 3]


def envmap_reference(pixels: np.ndarray, rotation: np.ndarray, scale: float, dirs: np.ndarray) -> np.ndarray:
    """Mitsuba 3's envmap lookup (src/emitters/envmap.cpp, eval_spectrum) in numpy."""
    px = np.asarray(pixels, np.float64)
    h, w = px.shape[:2]
    loc = np.asarray(dirs, np.float64) @ np.asarray(rotation, np.float64)  # R^T d
    u = np.arctan2(loc[:, 0], -loc[:, 2]) / (2 * np.pi)
    v = np.arccos(np.clip(loc[:, 1], -1, 1)) / np.pi
    x, y = np.mod(u * w - 0.5, w), v * (h - 1)
    i0 = np.minimum(np.floor(x).astype(int), w - 1)
    j0 = np.minimum(np.floor(y).astype(int), h - 2)
    fx, fy, i1 = (x - i0)[:, None], (y - j0)[:, None], (i0 + 1) % w
    c = (1 - fy) * ((1 - fx) * px[j0, i0] + fx * px[j0, i1]) + fy * ((1 - fx) * px[j0 + 1, i0] + fx * px[j0 + 1, i1])
    return c * scale


def sphere_grid(n_cos: int, n_phi: int) -> tuple[np.ndarray, float]:
    """Midpoint directions of an (n_cos x n_phi) grid uniform in (cos theta, phi) about +z, and the
    solid angle of one cell."""
    c = -1 + 2 * (np.arange(n_cos) + 0.5) / n_cos
    phi = 2 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    s = np.sqrt(1 - c * c)
    d = np.stack([s[:, None] * np.cos(phi)[None], s[:, None] * np.sin(phi)[None],
                  np.broadcast_to(c[:, None], (n_cos, n_phi))], axis=-1)
    return d.reshape(-1, 3), 4 * np.pi / (n_cos * n_phi)


def irradiance(env: Envmap, normal, n_cos: int = 400, n_phi: int = 800) -> np.ndarray:
    """E = integral of L max(cos, 0) about ``normal``, by quadrature of the reference lookup."""
    d, dw = sphere_grid(n_cos, n_phi)
    n = np.asarray(normal, np.float64)
    cos = np.maximum(d @ (n / np.linalg.norm(n)), 0.0)
    L = envmap_reference(env.pixels, np.asarray(env.to_world, np.float64)[:3, :3], env.scale, d)
    return (L * cos[:, None]).sum(0) * dw


def render(scene, integrator="megakernel", **kw):
    return pyclpt.render(scene, integrator=integrator, progress=False, **kw)


def cap_map(h: int, w: int, centre_local, angle_deg: float, value) -> np.ndarray:
    """A map that is ``value`` at texels within angle_deg of centre_local and 0 elsewhere."""
    d = texel_directions(w, h)
    c = np.asarray(centre_local, np.float64)
    inside = d @ (c / np.linalg.norm(c)) >= np.cos(np.radians(angle_deg))
    return np.where(inside[..., None], np.asarray(value, np.float32), 0.0).astype(np.float32)


# --------------------------------------------------------------------------------------------
# 1. The lookup convention


def test_envmap_lookup_matches_mitsuba3(device):
    """Radiance along 200 directions of a rotated, scaled random map: Mitsuba 3's own values."""
    ref = np.load(DATA / "envmap-mitsuba3-eval.npz")
    env = Envmap(ref["pixels"], ref["to_world"], float(ref["scale"]), "mitsuba-reference")
    kit = LightKit(device, small_scene(env))
    le, pdf = kit.eval(ref["dirs"])
    np.testing.assert_allclose(le, ref["values"], rtol=2e-5, atol=2e-5)
    np.testing.assert_allclose(envmap_reference(ref["pixels"], ref["to_world"][:3, :3], 2.0, ref["dirs"]),
                               ref["values"], rtol=1e-5, atol=1e-5)
    assert np.all(pdf > 0)


# --------------------------------------------------------------------------------------------
# 2. Importance sampling


def structured_map() -> np.ndarray:
    """17 x 32: smooth variation, a bright texel, a black band, a coloured region."""
    rng = np.random.default_rng(3)
    h, w = 17, 32
    px = (0.2 + rng.random((h, w, 1)) * np.linspace(0.5, 2.0, w)[None, :, None]) * np.ones((1, 1, 3))
    px[:, 20:24] *= np.array([3.0, 0.2, 0.1])
    px[6:8] = 0.0  # the cells of row 6 (between texel rows 6 and 7) have zero weight
    px[11, 5] = 60.0
    return px.astype(np.float32)


@pytest.fixture(scope="module")
def env_kit(device):
    return LightKit(device, small_scene(Envmap(structured_map(), name="structured")))


def test_envmap_sampling_chi2(env_kit):
    """Directions from light_sample, counted in the sampling cells, against N * P(cell), P computed here
    from first principles: the mean luminance (Rec. 709) of the cell's 4 corner texels times the cell's
    solid angle (2 pi / W)(cos theta_r - cos theta_r+1), normalised; and the pdf the kernel reports at
    each cell's centre times that solid angle against the same P."""
    px = structured_map().astype(np.float64)
    h, w = px.shape[:2]
    n = 400_000
    s = env_kit.sample(np.random.default_rng(5).random((n, 3), dtype=np.float32))
    assert s["ok"].mean() > 0.999 and not s["delta"].any() and np.all(np.isinf(s["dist"][s["ok"]]))
    d = s["wi"][s["ok"]].astype(np.float64)
    x = np.mod(np.arctan2(d[:, 0], -d[:, 2]) / (2 * np.pi) * w - 0.5, w)
    y = np.arccos(np.clip(d[:, 1], -1, 1)) / np.pi * (h - 1)
    cell = np.minimum(y.astype(int), h - 2) * w + np.minimum(x.astype(int), w - 1)
    observed = np.bincount(cell, minlength=(h - 1) * w)
    lum = px @ np.array([0.2126, 0.7152, 0.0722])
    right = np.roll(lum, -1, axis=1)  # column c + 1, periodic
    corners = 0.25 * (lum[:-1] + right[:-1] + lum[1:] + right[1:])
    row_theta = np.pi * np.arange(h) / (h - 1)  # texel rows sit on theta = pi j / (H - 1)
    omega = 2 * np.pi / w * (np.cos(row_theta[:-1]) - np.cos(row_theta[1:]))
    assert omega.sum() * w == pytest.approx(4 * np.pi)
    prob = (corners * omega[:, None]).reshape(-1)
    prob /= prob.sum()
    # the kernel's pdf at each cell's centre
    r, c = np.divmod(np.arange((h - 1) * w), w)
    theta = np.pi * (r + 0.5) / (h - 1)
    phi = 2 * np.pi * (c + 1.0) / w
    centres = np.stack([np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)], axis=1)
    _, pdf = env_kit.eval(centres)
    np.testing.assert_allclose(pdf * omega[r], prob, rtol=3e-4, atol=1e-9)
    assert np.all(prob[6 * w:7 * w] == 0) and observed[6 * w:7 * w].sum() == 0
    expected = n * prob
    keep = expected > 0
    chi2 = ((observed[keep] - expected[keep]) ** 2 / expected[keep]).sum()
    p = stats.chi2.sf(chi2, keep.sum() - 1)
    assert p > 0.01, (chi2, keep.sum())


def test_envmap_sample_agrees_with_eval(env_kit):
    """A sample's radiance and pdf are the environment's along the sampled direction."""
    s = env_kit.sample(np.random.default_rng(6).random((20000, 3), dtype=np.float32))
    ok = s["ok"]
    np.testing.assert_allclose(s["radiance"][ok], s["eval_radiance"][ok], rtol=1e-4, atol=1e-6)
    # the pdf is piecewise constant: away from cell borders (float rounding) the two agree exactly
    same = np.isclose(s["pdf"][ok], s["eval_pdf"][ok], rtol=1e-4)
    assert same.mean() > 0.999
    np.testing.assert_allclose(np.linalg.norm(s["wi"][ok], axis=1), 1.0, atol=1e-5)


def test_alias_tables_give_every_cell_its_probability():
    """alias_tables (Vose's construction, every row at once): a cell's own share q / n plus the (1 - q) / n of the
    entries aliased to it is its pmf, to float64 rounding, on rows with zeros, spikes, ties, one cell, all black."""
    from pyclpt.buffers.lights import alias_tables

    rng = np.random.default_rng(5)
    rows = [rng.random((50, n)) ** rng.integers(1, 30, (50, 1)) for n in (1, 2, 3, 7, 64, 2048)]
    edge = rng.random((6, 256))
    edge[0] = 0.0  # black: uniform
    edge[1] = 1.0  # ties: every q 1
    edge[2, :] = 1e-30
    edge[2, 17] = 1.0  # one spike over tiny cells
    edge[3, rng.random(256) < 0.9] = 0.0  # black runs
    edge[4] = np.arange(256.0)
    for w in [*rows, edge]:
        w = np.where(rng.random(w.shape) < 0.2, 0.0, w) if w is not edge else w
        q, alias, pmf = alias_tables(w)
        r, n = w.shape
        assert q.min() >= 0.0 and q.max() <= 1.0 and alias.min() >= 0 and alias.max() < n
        got = q / n
        np.add.at(got, (np.repeat(np.arange(r), n), alias.ravel()), ((1.0 - q) / n).ravel())
        np.testing.assert_allclose(got, pmf, rtol=0, atol=1e-12)
        total = w.sum(axis=1, keepdims=True)
        np.testing.assert_allclose(pmf, np.where(total > 0, w / np.where(total > 0, total, 1), 1 / n), rtol=1e-12)


def test_envmap_sampling_picks_the_cells_of_its_tables(device):
    """env_sample's cell is the marginal CDF's row (its guide table, cdf_search_guided) and that row's alias entry
    (env_alias_pick): the kernel's pdf is the pdf of the cell a float32 numpy emulation of both picks, on a map with
    black runs, a spike and 8 guide intervals. An alias entry read from the wrong row or column, or the alias's pmf
    taken for the cell's, picks or prices another cell."""
    from pyclpt.buffers.lights import ENV_HEADER, cdf_guide, guide_size, pack_envmap
    from pyclpt.buffers.materials import TextureTable

    rng = np.random.default_rng(11)
    h, w = 65, 256
    px = (rng.random((h, w, 3)) ** 3).astype(np.float32)
    px[20:30] = 0.0
    px[:, 100:180] *= 1e-4
    px[40, 7] = 500.0
    env = Envmap(px, name="alias")
    block, _ = pack_envmap(env, TextureTable())
    rows = h - 1
    assert int(block[13]) == guide_size(rows) == 8
    entries = block[ENV_HEADER:ENV_HEADER + 4 * rows * w].reshape(rows, w, 4)
    q, alias, pmf, alias_pmf = entries[..., 0], entries[..., 1].view(np.int32), entries[..., 2], entries[..., 3]
    np.testing.assert_array_equal(alias_pmf, np.take_along_axis(pmf, alias, axis=1))
    at = ENV_HEADER + 4 * rows * w
    marginal, omega = block[at:at + rows], block[at + rows:at + 2 * rows]
    guide = block[at + 2 * rows + h:].view(np.int32)
    np.testing.assert_array_equal(guide, cdf_guide(marginal, 8))
    u = rng.random((100_000, 3), dtype=np.float32)
    u[:64, 1:] = np.arange(64, dtype=np.float32)[:, None] / 64  # the guide's and the alias columns' boundaries
    s = LightKit(device, small_scene(env)).sample(u)
    assert s["ok"].all()
    r = np.minimum(np.searchsorted(marginal, u[:, 1], side="right"), rows - 1)
    x = u[:, 2] * np.float32(w)
    i = np.minimum(x.astype(np.int32), w - 1)
    f = np.minimum(x - i.astype(np.float32), np.float32(1 - 2**-24))
    own = f < q[r, i]
    c = np.where(own, i, alias[r, i])
    cell_pmf = np.where(own, pmf[r, i], alias_pmf[r, i])
    prev_r = np.where(r > 0, marginal[np.maximum(r - 1, 0)], np.float32(0))
    np.testing.assert_allclose(s["pdf"], (marginal[r] - prev_r) * cell_pmf / omega[r], rtol=2e-6)
    np.testing.assert_array_equal(cell_pmf, pmf[r, c])
    # the directions fall in the cells picked: phi's column is c (the map is not rotated)
    d = s["wi"]
    col = np.floor((np.arctan2(d[:, 0], -d[:, 2]) / (2 * np.pi) % 1.0) * w - 0.5).astype(np.int64) % w
    assert np.mean(col == c) > 0.999


def test_scene_memory_estimate_covers_the_envmap_tables():
    """The estimate the renderer checks device memory with (rendering/memory.py scene_bytes) holds a map's texels and
    alias tables: at least the packed buffers' bytes, and within 1 % of them plus the plain scene's."""
    from pyclpt.rendering.memory import scene_bytes

    px = np.random.default_rng(3).random((257, 512, 3)).astype(np.float32)
    plain = small_scene()
    scene = small_scene(Envmap(px, name="big"))
    packed, packed_plain = pack_scene(scene).nbytes, pack_scene(plain).nbytes
    estimate, estimate_plain = scene_bytes(scene), scene_bytes(plain)
    assert estimate >= packed
    assert estimate - estimate_plain == pytest.approx(packed - packed_plain, rel=0.01)


def test_deferred_environment_radiance_is_the_same_sample(env_kit):
    """light_sample with env_radiance false (ENV_DEFERRED: the radiance is looked up once the shadow ray is
    found unoccluded, path_lit) draws the same direction with the same pdf and leaves the radiance at 1."""
    s = env_kit.sample(np.random.default_rng(12).random((5000, 3), dtype=np.float32))
    assert s["ok"].all() and np.array_equal(s["later_ok"], s["ok"])
    np.testing.assert_array_equal(s["later_wi"], s["wi"])
    np.testing.assert_array_equal(s["later_pdf"], s["pdf"])
    np.testing.assert_array_equal(s["later_radiance"], 1.0)


@pytest.mark.parametrize("rotation", [np.eye(4), rotate([1.0, -2.0, 0.5], 70.0)])
def test_envmap_pdf_integrates_to_one(device, rotation):
    """The pdf over a world-space quadrature grid sums to 1 (the map rotated or not); it is zero
    exactly where the map is black."""
    kit = LightKit(device, small_scene(Envmap(structured_map(), rotation, name="structured")))
    d, dw = sphere_grid(600, 1200)
    le, pdf = kit.eval(d)
    assert np.all(pdf >= 0) and np.all(np.isfinite(pdf))
    assert pdf.sum() * dw == pytest.approx(1.0, abs=2e-3)
    assert np.all(pdf[le.max(axis=1) > 0] > 0)  # light sampling covers every lit direction


def test_envmap_rotation_moves_samples(device):
    """The same random numbers give R times the unrotated direction, with the same pdf and radiance."""
    rot = rotate([0.3, 1.0, -0.4], 125.0)
    u = np.random.default_rng(8).random((5000, 3), dtype=np.float32)
    a = LightKit(device, small_scene(Envmap(structured_map(), name="a"))).sample(u)
    b = LightKit(device, small_scene(Envmap(structured_map(), rot, name="b"))).sample(u)
    np.testing.assert_allclose(b["wi"], a["wi"] @ rot[:3, :3].T, atol=2e-5)
    np.testing.assert_allclose(b["pdf"], a["pdf"], rtol=1e-5)
    np.testing.assert_allclose(b["radiance"], a["radiance"], rtol=1e-4, atol=1e-6)


# --------------------------------------------------------------------------------------------
# 3. Renders


@pytest.mark.parametrize("integrator", ["megakernel", "wavefront"])
def test_constant_envmap_renders_like_constant_environment(integrator):
    """A diffuse cube under a constant-valued map reflects albedo * Le, as under the constant sky.
    The two estimators are equal in distribution, not sample by sample, so each is rendered with 8
    seeds and the bounds are 4 standard errors measured from those (about 1 %), not a fixed guess."""
    scene = object_under_sky({"type": "diffuse", "reflectance": 0.7}, radiance=1.5)
    centre = (slice(9, 15), slice(9, 15))
    stats_of = {}
    for kind, environment in (("constant", (1.5, 1.5, 1.5)),
                              ("map", Envmap(np.full((8, 16, 3), 1.5, np.float32), name="constant-map"))):
        scene.environment = environment
        means = []
        for seed in range(8):
            img = render(scene, integrator, spp=32, max_depth=-1, seed=10 + seed)
            assert np.allclose(img[0, 0], 1.5) and np.allclose(img[-1, -1], 1.5)
            means.append(img[centre].mean())
        stats_of[kind] = float(np.mean(means)), float(np.std(means, ddof=1) / np.sqrt(len(means)))
    for kind, (mean, se) in stats_of.items():
        assert se < 0.004 * 1.05, (kind, se)  # the test keeps its power: 4 se < 1.6 %
        assert abs(mean - 0.7 * 1.5) < 4 * se, (kind, mean, se)
    (a, sa), (b, sb) = stats_of["constant"], stats_of["map"]
    assert abs(a - b) < 4 * np.hypot(sa, sb), stats_of


ORIENTATIONS = {
    # name: (cap centre in the map's frame, to_world); the quad faces world +z
    "facing": ((0, 0, 1), np.eye(4)),
    "behind": ((0, 0, 1), rotate([0, 1, 0], 180.0)),
    "zenith-rotated-to-face": ((0, 1, 0), rotate([1, 0, 0], 90.0)),
    "grazing": ((1, 0, 0), np.eye(4)),
}


@pytest.mark.parametrize("name", list(ORIENTATIONS))
def test_envmap_orientation(name):
    """A map bright only in a 25-degree cap lights a quad facing the cap's world direction and not one
    facing away; to_world moves the cap. Radiance = albedo / pi * E, E by quadrature of the reference."""
    centre, to_world = ORIENTATIONS[name]
    env = Envmap(cap_map(33, 64, centre, 25.0, (8.0, 4.0, 2.0)), to_world, 1.5, name)
    expected = 0.5 / np.pi * irradiance(env, (0, 0, 1))
    if name in ("facing", "zenith-rotated-to-face"):
        assert expected[0] > 1.0
    if name == "behind":
        assert expected.max() == 0.0
    img = render(small_scene(env), spp=64, max_depth=2, seed=3, width=16, height=16)
    quad = img[5:11, 5:11].reshape(-1, 3).mean(0)
    np.testing.assert_allclose(quad, expected, rtol=0.03, atol=2e-3)


def camera_hits_on_plane(scene, width, height, offset=(0.5, 0.5)):
    """World points where the rays of the scene's camera through ``offset`` in each pixel (the centre by
    default) meet the plane z = 0."""
    origin, forward, right, up = scene.camera.basis(width, height)
    px, py = np.meshgrid(np.arange(width), np.arange(height))
    sx = 2 * (px + offset[0]) / width - 1
    sy = 1 - 2 * (py + offset[1]) / height
    d = forward + sx[..., None] * right + sy[..., None] * up
    t = -origin[2] / d[..., 2]
    return origin + t[..., None] * d


def test_point_light_analytic():
    """Direct lighting from a point light: L = albedo / pi * I cos / d^2 at every pixel of the quad."""
    pos, intensity = np.array([0.3, -0.2, 1.5]), np.array([4.0, 2.0, 1.0])
    scene = small_scene(lights=[PointLight(tuple(pos), tuple(intensity))])
    img = render(scene, spp=64, max_depth=-1, seed=4, width=24, height=24)
    hits = camera_hits_on_plane(scene, 24, 24)
    v = pos - hits
    dist = np.linalg.norm(v, axis=-1)
    expected = 0.5 / np.pi * intensity * (v[..., 2] / dist)[..., None] / (dist**2)[..., None]
    inside = np.all(np.abs(hits[..., :2]) < 0.85, axis=-1)  # the footprint is well inside the quad
    assert inside.sum() > 100
    np.testing.assert_allclose(img[inside], expected[inside], rtol=0.01)
    outside = np.all(np.abs(hits[..., :2]) > 1.15, axis=-1)
    assert np.all(img[outside] == 0)  # the point light itself is never seen


def _spot_falloff(cos_t, cutoff_deg, beam_deg):
    """Mitsuba 3's spot falloff: 1 inside the beam, linear in angle to 0 at the cutoff."""
    cutoff, beam = np.radians(cutoff_deg), np.radians(beam_deg)
    ramp = (cutoff - np.arccos(np.clip(cos_t, -1, 1))) / (cutoff - beam)
    return np.where(cos_t > np.cos(cutoff), np.where(cos_t >= np.cos(beam), 1.0, ramp), 0.0)


@pytest.mark.parametrize("integrator", ["megakernel", "wavefront"])
def test_spot_light_analytic(integrator):
    """Direct lighting from a spot light: L = albedo / pi * I falloff(angle) cos / d^2, with Mitsuba's
    falloff (full in the beam, linear in angle to the cutoff, 0 beyond)."""
    pos, axis, intensity = np.array([0.2, 0.1, 1.2]), np.array([0.3, -0.1, -1.0]), np.array([3.0, 2.0, 1.0])
    axis /= np.linalg.norm(axis)
    spot = pyclpt.SpotLight(tuple(pos), tuple(axis), tuple(intensity), cutoff_angle=25.0, beam_width=12.0)
    scene = small_scene(lights=[spot])
    img = render(scene, spp=256, max_depth=2, seed=4, width=32, height=32, integrator=integrator)

    def radiance_at(offset):
        v = pos - camera_hits_on_plane(scene, 32, 32, offset)
        dist = np.linalg.norm(v, axis=-1)
        cos_t = -(v / dist[..., None]) @ axis
        return 0.5 / np.pi * intensity * (_spot_falloff(cos_t, 25.0, 12.0) * v[..., 2] / dist**3)[..., None], cos_t

    grid = (np.arange(8) + 0.5) / 8  # the pixel average of the radiance (the render jitters uniformly)
    expected = np.mean([radiance_at((a, b))[0] for a in grid for b in grid], axis=0)
    hits = camera_hits_on_plane(scene, 32, 32)
    cos_t = radiance_at((0.5, 0.5))[1]
    on_quad = np.all(np.abs(hits[..., :2]) < 0.9, axis=-1)
    beam = on_quad & (cos_t > np.cos(np.radians(11.0)))
    ramp = on_quad & (cos_t < np.cos(np.radians(13.0))) & (cos_t > np.cos(np.radians(23.0)))
    dark = on_quad & (cos_t < np.cos(np.radians(27.0)))
    assert beam.sum() > 20 and ramp.sum() > 20 and dark.sum() > 20
    np.testing.assert_allclose(img[beam], expected[beam], rtol=0.01)
    np.testing.assert_allclose(img[ramp], expected[ramp], rtol=0.03, atol=1e-3)
    assert np.all(img[dark] == 0)


@pytest.mark.parametrize("integrator", ["megakernel", "wavefront"])
def test_directional_light_analytic(integrator):
    """A distant light of irradiance E at angle theta: L = albedo / pi * E cos(theta) in every pixel of
    the quad, exactly (next-event estimation of a delta light, nothing else)."""
    theta = np.radians(35.0)
    sun = pyclpt.DirectionalLight((np.sin(theta), 0.0, -np.cos(theta)), (2.0, 1.0, 0.5))
    scene = small_scene(lights=[sun])
    img = render(scene, spp=4, max_depth=2, seed=4, width=16, height=16, integrator=integrator)
    hits = camera_hits_on_plane(scene, 16, 16)
    inside = np.all(np.abs(hits[..., :2]) < 0.85, axis=-1)
    expected = 0.5 / np.pi * np.array([2.0, 1.0, 0.5]) * np.cos(theta)
    np.testing.assert_allclose(img[inside], np.broadcast_to(expected, img[inside].shape), rtol=1e-5)
    behind = pyclpt.DirectionalLight((0.0, 0.0, 1.0), 3.0)  # lights the quad's back: a one-sided diffuse is black
    scene.lights = [behind]
    assert render(scene, spp=1, max_depth=2, width=16, height=16).max() == 0


def test_spot_and_directional_match_mitsuba():
    """Mitsuba 3 rendering the same XML file (tests/data/make_plugin_reference.py, 16384 spp): a
    spot light and a directional light over a floor and a box, shadows and interreflection included."""
    ref = np.load(DATA / "delta-emitters-mitsuba.npy")
    scene = pyclpt.load(DATA / "delta-emitters.xml")
    img = render(scene, spp=256, seed=3)
    np.testing.assert_allclose(img.mean((0, 1)), ref.mean((0, 1)), rtol=0.01)

    def blocks(x):
        return x.reshape(4, 8, 6, 8, 3).mean((1, 3))

    rel_mse = np.mean((blocks(img) - blocks(ref)) ** 2) / np.mean(blocks(ref) ** 2)
    assert rel_mse < 5e-4, rel_mse


# Mitsuba 3's relMSE on tests/data/delta-emitters.xml at 256 spp against its 16384-spp reference, mean of seeds
# 1-4 (llvm_ad_rgb 3.9.1: python -m bench.evaluations.light_noise --mitsuba F --spp 256 --seeds 4)
DELTA_EMITTERS_MITSUBA_RELMSE = 1.842e-3


def test_distant_lights_do_not_starve_the_others():
    """Light selection (pyclpt/buffers/lights.py, SELECTION): a directional light's power estimate (through the
    whole scene's cross-section) dwarfs the spot's, and choosing by power alone left the spot's footprint with
    a tenth of the samples: 7x Mitsuba's relMSE at equal spp. The default rule gives the distant light its
    uniform share: within 1.2x of Mitsuba's, and under half of what power alone gives."""
    from pyclpt.buffers import lights

    ref = np.load(DATA / "delta-emitters-mitsuba.npy").astype(np.float64)
    scene = pyclpt.load(DATA / "delta-emitters.xml")

    def rel_mse() -> float:
        return float(np.mean([np.mean((render(scene, spp=256, seed=s)[..., :3] - ref) ** 2) for s in (1, 2)])
                     / np.mean(ref ** 2))

    now = rel_mse()
    assert lights.SELECTION == "distant-uniform"
    try:
        lights.SELECTION = "power"
        by_power = rel_mse()
    finally:
        lights.SELECTION = "distant-uniform"
    assert now < 1.2 * DELTA_EMITTERS_MITSUBA_RELMSE, now
    assert now < 0.5 * by_power, (now, by_power)


def test_light_selection_rules():
    """selection_pmf: per rule, the probabilities of two triangles of one shape (power 1 and 3), a point light
    (power 4) and a directional light (power 100)."""
    from pyclpt.buffers.lights import selection_pmf

    power = np.array([1.0, 3.0, 4.0, 100.0])
    group = np.array([0, 0, 1, 2])
    distant = np.array([False, False, False, True])
    np.testing.assert_allclose(selection_pmf(power, group, distant, "power"), power / 108)
    np.testing.assert_allclose(selection_pmf(power, group, distant, "uniform"), [1 / 12, 3 / 12, 1 / 3, 1 / 3])
    np.testing.assert_allclose(selection_pmf(power, group, distant), [1 / 12, 3 / 12, 1 / 3, 1 / 3])
    np.testing.assert_allclose(selection_pmf(power, group, distant), selection_pmf(power, group, distant,
                                                                                   "distant-uniform"))
    # two distant lights and one finite emitter of any power: a third each
    np.testing.assert_allclose(selection_pmf(np.array([1e-3, 5.0, 9.0]), np.arange(3), np.array([False, True, True])),
                               [1 / 3, 1 / 3, 1 / 3])
    # finite emitters only: power; powers beyond double range: alike
    np.testing.assert_allclose(selection_pmf(power[:3], group[:3], distant[:3]), power[:3] / 8)
    np.testing.assert_allclose(selection_pmf(np.array([np.inf, 1.0]), np.arange(2), np.zeros(2, bool)), [0.5, 0.5])
    with pytest.raises(ValueError, match="light selection rule 'bogus'"):
        selection_pmf(power, group, distant, "bogus")


def test_delta_emitters_load_with_mitsuba_defaults_and_names(tmp_path):
    xml = """<scene version="0.6.0">
      <emitter type="spot"><spectrum name="intensity" value="2"/><float name="cutoffAngle" value="40"/>
        <transform name="toWorld"><lookat origin="0,3,0" target="0,0,0" up="0,0,1"/></transform></emitter>
      <emitter type="directional"><vector name="direction" x="0" y="-2" z="0"/>
        <spectrum name="irradiance" value="3"/></emitter>
      <shape type="rectangle"/></scene>"""
    path = tmp_path / "lights.xml"
    path.write_text(xml)
    spot, sun = (scene := pyclpt.load_xml(path)).lights
    assert isinstance(spot, pyclpt.SpotLight) and isinstance(sun, pyclpt.DirectionalLight)
    assert spot.cutoff_angle == 40.0 and spot.beam_width == 30.0  # Mitsuba: 3/4 of the cutoff
    np.testing.assert_allclose(spot.position, [0, 3, 0], atol=1e-6)
    np.testing.assert_allclose(spot.direction, [0, -1, 0], atol=1e-6)
    np.testing.assert_allclose(sun.direction, [0, -1, 0])
    assert sun.irradiance == (3.0, 3.0, 3.0)
    params = pyclpt.traverse(scene).unsupported()
    assert any("spot light" in r for r in params.values()) and any("directional" in r for r in params.values())
    with pytest.raises(ValueError, match="beam_width"):
        pyclpt.SpotLight((0, 0, 0), cutoff_angle=10.0, beam_width=20.0)
    with pytest.raises(ValueError, match="direction"):
        pyclpt.DirectionalLight((0, 0, 0))


def test_point_light_with_environment():
    """Two emitters of different kinds (a distant one and a finite one): the quad under a constant map (one-sided,
    so albedo * Le) plus the point light's albedo / pi * I cos / d^2."""
    pos, intensity = np.array([0.0, 0.0, 2.0]), np.array([6.0, 6.0, 6.0])
    env = Envmap(np.full((6, 12, 3), 0.8, np.float32), name="grey")
    scene = small_scene(env, [PointLight(tuple(pos), tuple(intensity))])
    img = render(scene, spp=128, max_depth=2, seed=5, width=16, height=16)
    hits = camera_hits_on_plane(scene, 16, 16)
    v = pos - hits
    dist = np.linalg.norm(v, axis=-1)
    expected = 0.5 * 0.8 + 0.5 / np.pi * 6.0 * v[..., 2] / dist**3
    block = (slice(5, 11), slice(5, 11))
    assert img[block].mean() == pytest.approx(expected[block].mean(), rel=0.02)


def test_megakernel_equals_wavefront_with_envmap_and_point_light():
    env = Envmap(structured_map(), rotate([1, 1, 0], 35.0), 2.0, "structured")
    scene = object_under_sky({"type": "roughplastic", "alpha": 0.2, "diffuse_reflectance": 0.5})
    scene.environment = env
    scene.lights = [PointLight((1.5, 1.0, 2.0), (3.0, 2.0, 1.0))]
    kw = dict(spp=4, max_depth=-1, width=16, height=16, seed=6)
    mega = render(scene, "megakernel", **kw)
    wave = render(scene, "wavefront", **kw)
    assert mega.max() > 0 and np.isfinite(mega).all()
    assert np.array_equal(mega, wave)


# --------------------------------------------------------------------------------------------
# 4. Packing and bad inputs


def test_pack_lights_records_and_power():
    scene = pyclpt.load_dict({
        "type": "scene", "sensor": sensor(FRONT_CAMERA),
        "quad": {"type": "rectangle", "emitter": {"type": "area", "radiance": 2.0}},
    })
    scene.lights = [PointLight((0, 1, 2), (1.0, 1.0, 1.0)), PointLight((0, 0, 5), (0.0, 0.0, 0.0))]
    scene.environment = Envmap(np.full((4, 8, 3), 0.25, np.float32), name="grey")
    arrays = pack_scene(scene)
    la = arrays.lights
    types = la.lights[:, LIGHT_TYPE].astype(int).tolist()
    assert types == [LIGHT_TRIANGLE, LIGHT_TRIANGLE, LIGHT_POINT, LIGHT_ENVMAP]  # the dark light is dropped
    assert la.env_light == 3
    assert la.lights[-1, LIGHT_CDF] == 1.0 and np.all(np.diff(la.lights[:, LIGHT_CDF]) > 0)
    pmf = la.lights[:, LIGHT_PMF]
    # three emitters (the quad, the point light, the map): the distant map is chosen as uniformly, 1/3; the
    # finite ones share the rest by power: area 2 * 2 -> 8 for the quad's two triangles, 4 pi for the point light
    assert pmf[3] == pytest.approx(1 / 3, rel=1e-6)
    assert pmf[2] / pmf[:2].sum() == pytest.approx(4 * np.pi / 8.0, rel=1e-5)
    assert pmf[:3].sum() == pytest.approx(2 / 3, rel=1e-6)
    offset = la.lights[2, LIGHT_PRIM:LIGHT_PRIM + 1].view(np.int32)[0]
    np.testing.assert_array_equal(la.light_data[offset:offset + 3], [0, 1, 2])


def test_bad_envmaps_name_the_emitter():
    with pytest.raises(ValueError, match="'sky-neg'"):
        Envmap(np.full((4, 8, 3), -1.0), name="sky-neg")
    bad = np.ones((4, 8, 3))
    bad[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="'sky-nan'.*finite"):
        Envmap(bad, name="sky-nan")
    with pytest.raises(ValueError, match="'sky-empty'"):
        Envmap(np.zeros((0, 0, 3)), name="sky-empty")
    with pytest.raises(ValueError, match="'sky-sheared'.*rotation"):
        env = Envmap(np.ones((4, 8, 3)), np.diag([1.0, 2.0, 1.0, 1.0]), name="sky-sheared")
        pack_lights(small_scene(env), np.zeros((0, 9)), np.zeros((0, 3)), np.zeros((2, 3)), TextureTable())
    # a uniform scale is divided out
    env = Envmap(np.ones((4, 8, 3)), np.diag([3.0, 3.0, 3.0, 1.0]), name="scaled")
    pack_lights(small_scene(env), np.zeros((0, 9)), np.zeros((0, 3)), np.zeros((2, 3)), TextureTable())


# --------------------------------------------------------------------------------------------
# 5. Sun and sky


@pytest.fixture(scope="module")
def classroom_sky() -> Envmap:
    return sunsky_envmap(CLASSROOM_SUN, turbidity=3, sky_scale=6, sun_scale=10, sun_radius_scale=18.8131)


def test_sunsky_classroom_config(classroom_sky):
    """The classroom scene's sunsky (a Mitsuba 0.6 file): finite, non-negative, the sun where
    sun_direction points, a blue zenith, black below the horizon, and the sun's power that of Mitsuba
    0.5's sun x sun_scale."""
    env = classroom_sky
    px = env.pixels
    h, w = px.shape[:2]
    assert (h, w) == (256, 512) and np.isfinite(px).all() and px.min() >= 0
    dirs = texel_directions(w, h)
    sun = CLASSROOM_SUN / np.linalg.norm(CLASSROOM_SUN)
    radius = np.radians(SUN_RADIUS_DEG * 18.8131)
    angle = np.arccos(np.clip(dirs @ sun, -1, 1))
    lum = px @ np.array([0.2127, 0.7152, 0.0722])
    brightest = np.argsort(lum.ravel())[-50:]
    assert np.all(angle.ravel()[brightest] < radius + np.radians(1.0))
    assert np.all(lum[angle < 0.8 * radius] > 50 * lum[angle > 2 * radius].max())  # a disk, brighter than the sky
    zenith = px[0].mean(0)
    assert zenith[2] > zenith[1] > zenith[0] > 0
    assert np.all(px[dirs[..., 1] < 0] == 0)
    assert np.all(lum[(dirs[..., 1] > 0.05) & (angle > 2 * radius)] > 0)
    # power of the sun on the (bilinearly reconstructed) map
    sky_only = sunsky_envmap(CLASSROOM_SUN, turbidity=3, sky_scale=6, sun_scale=0, sun_radius_scale=18.8131)
    weight = row_hat_solid_angle(h)[:, None, None] * (2 * np.pi / w)
    sun_power = ((px.astype(np.float64) - sky_only.pixels) * weight).sum((0, 1))
    real = 2 * np.pi * (1 - np.cos(np.radians(SUN_RADIUS_DEG)))
    expected = 10 * sun_radiance_rgb_05(np.arccos(sun[1]), 3.0) * real
    np.testing.assert_allclose(sun_power, expected, rtol=1e-3)
    assert expected[0] > expected[1] > expected[2] > 0  # a low sun is yellowish


def test_sunsky_lights_a_ground_plane(classroom_sky):
    """Render-level: an upward quad under the classroom sky shows albedo / pi * E, E from the map by
    quadrature (dominated by the sun: tests importance sampling of a very peaked map)."""
    scene = small_scene(classroom_sky, to_world=[{"rotate": {"axis": [1, 0, 0], "angle": -90}}])
    scene.camera = pyclpt.Camera.look_at((0, 3, 1.5), (0, 0, 0), fov=30.0)
    img = render(scene, spp=256, max_depth=2, seed=7, width=16, height=16)
    px = classroom_sky.pixels.astype(np.float64)
    h, w = px.shape[:2]
    cos = np.maximum(texel_directions(w, h)[..., 1], 0.0)
    weight = row_hat_solid_angle(h)[:, None] * (2 * np.pi / w)
    E = (px * (cos * weight)[..., None]).sum((0, 1))
    expected = 0.5 / np.pi * E
    centre = img[6:10, 6:10].reshape(-1, 3).mean(0)
    assert np.isfinite(img).all()
    np.testing.assert_allclose(centre, expected, rtol=0.03)


@pytest.fixture(scope="module")
def sunsky_reference() -> dict[str, np.ndarray]:
    with np.load(DATA / "sunsky-mitsuba3-eval.npz") as f:
        return dict(f)


SUNSKY_CONFIGS = range(6)  # tests/data/make_sunsky_reference.py: CONFIGS


@pytest.mark.parametrize("k", SUNSKY_CONFIGS)
def test_sky_matches_mitsuba3(sunsky_reference, k):
    """The baked Hosek-Wilkie sky (Mitsuba 3's frame, to_world) against Mitsuba 3's ``sunsky`` along 400
    directions, for sun elevations 5-80 degrees, turbidities 1-9 and albedos 0-1: within 0.5 % (the
    map's bilinear reconstruction) away from the sun and the horizon."""
    ref = sunsky_reference
    elev, azim, turb, alb = ref[f"c{k}_params"]
    m = ref[f"c{k}_to_world"]
    env = sunsky_envmap(ref[f"c{k}_sun"], convention="mitsuba3", turbidity=turb, albedo=alb, sun_scale=0,
                        to_world=m)
    dirs = ref[f"c{k}_dirs"]
    got = envmap_reference(env.pixels, env.to_world[:3, :3], 1.0, dirs)
    keep = (dirs @ ref[f"c{k}_sun"] < np.cos(np.radians(10))) & (dirs @ m[:3, 2] > 0.03)
    assert keep.sum() > 300
    np.testing.assert_allclose(got[keep], ref[f"c{k}_sky"][keep], rtol=5e-3)
    # near the sun: the map's texels blur a steep peak, still close (above 1 degree of elevation)
    above = dirs @ m[:3, 2] > np.sin(np.radians(1.0))
    np.testing.assert_allclose(got[above], ref[f"c{k}_sky"][above], rtol=0.05, atol=1e-3 * ref[f"c{k}_sky"].max())


@pytest.mark.parametrize("k", SUNSKY_CONFIGS)
def test_sun_matches_mitsuba3(sunsky_reference, k):
    """Mitsuba 3's sun: its radiance at the real aperture and at 5 degrees (constant power), the
    limb-darkened disk (``complex_sun``), and the baked power. Mitsuba 3 is 0.22 % brighter: it computes
    the sun's solid angle 2 pi (1 - cos 0.2679 deg) in float32."""
    from pyclpt.scene.sky.sun import SUN_HALF_APERTURE, complex_sun_radiance_rgb_3, sun_radiance_rgb_3

    ref = sunsky_reference
    elev, azim, turb, alb = ref[f"c{k}_params"]
    m, sun = ref[f"c{k}_to_world"], ref[f"c{k}_sun"]
    real = sun_radiance_rgb_3(np.radians(elev), turb)
    wide = np.radians(2.5)
    ratio = (1 - np.cos(SUN_HALF_APERTURE)) / (1 - np.cos(wide))
    np.testing.assert_allclose(ref[f"c{k}_sun_rgb"], [real, real * ratio], rtol=3e-3)
    local = ref[f"c{k}_limb_dirs"] @ m[:3, :3]
    gamma = np.arccos(np.clip(local @ (m[:3, :3].T @ sun), -1, 1))
    limb = complex_sun_radiance_rgb_3(local[:, 2], gamma, turb, wide) * ratio
    np.testing.assert_allclose(limb, ref[f"c{k}_limb"], rtol=3e-3)
    assert np.all(limb[-1] < 0.8 * limb[0])  # darker towards the limb
    # the baked disks hold the sun's power (uniform: exactly; limb-darkened: as its quadrature)
    for complex_sun in (False, True):
        env = sunsky_envmap(sun, convention="mitsuba3", turbidity=turb, sky_scale=0, sun_aperture=5.0,
                            complex_sun=complex_sun, resolution=256, to_world=m)
        h, w = env.pixels.shape[:2]
        weight = row_hat_solid_angle(h)[:, None, None] * (2 * np.pi / w)
        power = (env.pixels.astype(np.float64) * weight).sum((0, 1))
        expected = real * 2 * np.pi * (1 - np.cos(SUN_HALF_APERTURE))
        if not complex_sun:
            np.testing.assert_allclose(power, expected, rtol=1e-3)
        elif elev > 10:  # Mitsuba 3's two suns differ by a few % in power (and more for low suns)
            np.testing.assert_allclose(power, expected, rtol=0.03)


def test_sun_position_matches_mitsuba3(sunsky_reference):
    """The sun's direction from a place and time (PSA) in Mitsuba 3's frame, as Mitsuba 3 computes it
    (in float32: within 0.05 degrees)."""
    from pyclpt.scene.sky.sun_position import local_sun_direction

    names = ("latitude", "longitude", "timezone", "year", "month", "day", "hour", "minute", "second")
    for k in range(2):
        t = sunsky_reference[f"t{k}_time"]
        kw = {n: (int(v) if n in ("year", "month", "day") else float(v)) for n, v in zip(names, t) if np.isfinite(v)}
        got = local_sun_direction(SunTime(**kw), "mitsuba3")
        assert np.degrees(np.arccos(np.clip(got @ sunsky_reference[f"t{k}_sun"], -1, 1))) < 0.05
    # Mitsuba 0.5's frame: the same sun, +y up, east +x, north +z
    d05 = local_sun_direction(SunTime(), "mitsuba0.5")
    d3 = local_sun_direction(SunTime(), "mitsuba3")
    np.testing.assert_allclose([d05[1], np.hypot(d05[0], d05[2])], [d3[2], np.hypot(d3[0], d3[1])], atol=1e-12)


def test_sunsky_options_and_errors():
    sky = sunsky_envmap((0, 1, 1), sun_scale=0.0, resolution=64)
    assert sky.pixels.shape == (32, 64, 3) and sky.name == "sunsky"
    assert sky.pixels.max() < 1.0  # no sun
    ext = sunsky_envmap((0, 1, 1), sun_scale=0.0, resolution=64, extend=True)
    assert ext.pixels[20].min() > 0 and np.all(ext.pixels[-1] == 0)  # extended, faded out at the nadir
    stretched = sunsky_envmap((0, 1, 1), sun_scale=0.0, resolution=64, stretch=1.5)
    assert stretched.pixels[20].min() > 0 and np.all(stretched.pixels[-1] == 0)  # down to 135 degrees
    # to_world: the sun stays where sun_direction points in the world, in either frame
    for convention, rot in (("mitsuba0.5", rotate([1, 0, 0], 90.0)), ("mitsuba3", rotate([0, 1, 1], 30.0))):
        env = sunsky_envmap((0.2, 0.1, 0.9), resolution=128, to_world=rot, convention=convention)
        h, w = env.pixels.shape[:2]
        j, i = np.unravel_index(np.argmax(env.pixels.sum(-1)), (h, w))
        world = env.to_world[:3, :3] @ texel_directions(w, h)[j, i]
        assert np.degrees(np.arccos(world @ np.array([0.2, 0.1, 0.9]) / np.linalg.norm([0.2, 0.1, 0.9]))) < 3.0
    # the default place and time: 15:00 in Tokyo in July, a high sun
    from pyclpt.scene.sky.sun_position import local_sun_direction

    timed = sunsky_envmap(time=SunTime(), convention="mitsuba3", resolution=64)
    j, i = np.unravel_index(np.argmax(timed.pixels.sum(-1)), timed.pixels.shape[:2])
    brightest = timed.to_world[:3, :3] @ texel_directions(64, 32)[j, i]
    assert brightest @ local_sun_direction(SunTime(), "mitsuba3") > np.cos(np.radians(6.0))
    for kwargs, match in [(dict(sun_direction=(0, -1, 0.2)), "below the horizon"),
                          (dict(sun_direction=(0, 0, 1), convention="mitsuba3", to_world=rotate([1, 0, 0], 100)),
                           "below the horizon"),
                          (dict(sun_direction=(0, 0, 0)), "sun_direction"),
                          (dict(sun_direction=(0, 1, 0), time=SunTime()), "sun_direction or a time"),
                          (dict(sun_direction=(0, 1, 0), turbidity=12), "turbidity"),
                          (dict(sun_direction=(0, 1, 0), turbidity="x"), "turbidity"),
                          (dict(sun_direction=(0, 1, 0), sky_scale=-1), "sky_scale"),
                          (dict(sun_direction=(0, 1, 0), resolution=3), "resolution"),
                          (dict(sun_direction=(0, 1, 0), stretch=3), "stretch"),
                          (dict(sun_direction=(0, 1, 0), convention="mitsuba3", sun_aperture=0), "sun_aperture"),
                          (dict(sun_direction=(0, 1, 0), convention="mitsuba2"), "convention"),
                          (dict(sun_direction=(0, 1, 0), albedo=float("nan")), "albedo"),
                          (dict(sun_direction=(0, 1, 0), albedo=(0.1, 0.2)), "albedo")]:
        with pytest.raises(ValueError, match=f"sunsky.*{match}"):
            sunsky_envmap(**kwargs)
    # Mitsuba 0.5's directional sun (sun_radius_scale 0): not in the map, a light of the disk's power
    assert sunsky_envmap((0, 1, 1), sun_radius_scale=0.0, resolution=32).pixels.max() < 1.0
    direction, irradiance = directional_sun_05((0, 1, 1), sun_scale=2.0)
    np.testing.assert_allclose(direction, -np.array([0, 1, 1]) / np.sqrt(2), atol=1e-12)
    disk = sunsky_envmap((0, 1, 1), sky_scale=0.0, sun_scale=2.0, resolution=256)
    weight = row_hat_solid_angle(128)[:, None, None] * (2 * np.pi / 256)
    np.testing.assert_allclose((disk.pixels * weight).sum((0, 1)), irradiance, rtol=1e-3)


def test_sunsky_loader_versions(tmp_path):
    """The dict loader: a ``sunsky`` is Mitsuba 3's (+z up) unless its file was older than 2.0
    (``__version__``, set by the XML importer); time and place parameters; errors name the element."""
    from pyclpt.scene.mitsuba_dict import VERSION, SceneDictError
    from pyclpt.scene.mitsuba_xml import load_xml

    def load_string(text: str) -> pyclpt.Scene:
        (tmp_path / "sky.xml").write_text(text)
        return load_xml(tmp_path / "sky.xml")

    def env_of(emitter: dict) -> Envmap:
        scene = pyclpt.load_dict({"type": "scene", "sensor": sensor(FRONT_CAMERA, fov=30.0, size=8),
                                  "quad": {"type": "rectangle"}, "sky": emitter})
        return scene.environment

    up_y = env_of({"type": "sunsky", "sun_direction": [0, 1, 0], "sun_scale": 0, "albedo": 0.3, VERSION: "0.6.0"})
    up_z = env_of({"type": "sunsky", "sun_direction": [0, 0, 1], "sun_scale": 0, "albedo": 0.3})
    assert up_y.pixels.shape == (256, 512, 3) and up_z.pixels.shape == (512, 1024, 3)
    # both a sun at the zenith of their frame: the same sky, seen through each map's to_world
    zen_y = envmap_reference(up_y.pixels, up_y.to_world[:3, :3], 1.0, np.array([[0, 1.0, 0]]))
    zen_z = envmap_reference(up_z.pixels, up_z.to_world[:3, :3], 1.0, np.array([[0, 0, 1.0]]))
    np.testing.assert_allclose(zen_y, zen_z * 106.7502594 / 106.85698, rtol=1e-5)  # Mitsuba 0.5's / 3's y-bar
    with pytest.raises(SceneDictError, match="below the horizon"):
        env_of({"type": "sunsky", "sun_direction": [0, 1, 0.2], VERSION: "0.5.0", "to_world": rotate([1, 0, 0], 150)})
    with pytest.raises(SceneDictError, match="sky.*not both"):
        env_of({"type": "sunsky", "sun_direction": [0, 0, 1], "hour": 12})
    timed = env_of({"type": "sunsky", "hour": 11.5, "month": 3, "sun_aperture": 3.0, "complex_sun": True})
    assert timed.pixels.max() > 100  # a 3 degree sun: 1/125 of the real sun's radiance, still far above the sky
    # a 0.6 file: camelCase names, the old plug-in
    xml = """<scene version="0.6.0"><shape type="rectangle"/>
        <emitter type="sunsky"><vector name="sunDirection" x="0" y="1" z="1"/>
        <float name="sunRadiusScale" value="4"/><integer name="resolution" value="64"/></emitter></scene>"""
    old = load_string(xml)
    assert old.environment.pixels.shape == (32, 64, 3)
    directional = load_string(xml.replace('name="sunRadiusScale" value="4"', 'name="sunRadiusScale" value="0"'))
    (light,) = directional.lights
    np.testing.assert_allclose(light.direction, -np.array([0, 1, 1]) / np.sqrt(2), atol=1e-6)
    assert directional.environment.pixels.max() < 1.0  # the sky alone
    xml3 = """<scene version="3.0.0"><shape type="rectangle"/>
        <emitter type="sunsky"><vector name="sun_direction" x="0" y="1" z="1"/>
        <float name="sun_aperture" value="4"/></emitter></scene>"""
    assert load_string(xml3).environment.pixels.shape == (512, 1024, 3)
