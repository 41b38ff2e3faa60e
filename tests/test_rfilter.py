"""Reconstruction filters (Mitsuba's ``rfilter``: box, tent, gaussian): the pixel offsets filter importance
sampling draws (estimator="importance", cl/film/rfilter.h) against Mitsuba's filter definitions by chi-square,
images of both estimators against Mitsuba 3's render of tests/data/rfilter.xml, the megakernel equal to the
wavefront and the gradient renderer's primal for every filter, the box unchanged, and the loaders' defaults
and errors; the splatting film (estimator="splat", the default):
its gather's weights against numpy, a constant image kept, its weights' mean, the seed contract, crops, lower
variance than filter importance sampling, gradients, the progressive renderer, split sample ranges merged
exactly (pooled sums), its G-buffer and the denoisers' input (each pixel's own samples), its memory counted
before a render."""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from test_sampling import chi2_pvalue

import pyclpt
from pyclpt.buffers.rfilter import CONST_FILTER_RADIUS, filter_consts, filter_kind, sample_offsets
from pyclpt.buffers.scene import SceneBuffers
from pyclpt.device.program import build_program
from pyclpt.gradients.differentiate import replay_for
from pyclpt.scene.model import ReconstructionFilter
from scenes import FRONT_CAMERA, object_under_sky, sensor

cl = pytest.importorskip("pyopencl")
integrate = pytest.importorskip("scipy.integrate")

DATA = Path(__file__).parent / "data"

KERNEL = r"""
#include "film/rfilter.h"
__kernel void rfilter_offsets(__global const float* consts, __global const float* u, __global float* out) {
    int i = get_global_id(0);
    out[i] = rfilter_position(consts, u[i]) - 0.5f;
}
"""


def mitsuba_filter(kind: str, x: np.ndarray, radius: float = 1.0, stddev: float = 0.5) -> np.ndarray:
    """w(x) as written in Mitsuba 3's src/rfilters/{box,tent}.cpp and Mitsuba 0.5's / Mitsuba 3's CUDA
    gaussian.cpp (exp(-x^2 / (2 stddev^2)) minus its value at 4 stddev)."""
    if kind == "box":
        return ((x >= -0.5) & (x < 0.5)).astype(np.float64)
    if kind == "tent":
        return np.maximum(0.0, 1.0 - np.abs(x / radius))
    alpha = -1.0 / (2.0 * stddev * stddev)
    return np.maximum(0.0, np.exp(alpha * x * x) - np.exp(alpha * (4.0 * stddev) ** 2))


def device_offsets(device, rfilter: ReconstructionFilter, u: np.ndarray) -> np.ndarray:
    defines = {"SCENE_FILTER": filter_kind(rfilter) or None}
    prg = build_program(device, source=KERNEL, defines=defines, name=f"test_rfilter_{rfilter.kind}")
    consts = np.zeros(CONST_FILTER_RADIUS + 200, np.float32)
    block = filter_consts(rfilter)
    consts[CONST_FILTER_RADIUS:CONST_FILTER_RADIUS + block.size] = block
    mf = cl.mem_flags
    bufs = [cl.Buffer(device.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a) for a in (consts, u)]
    out = np.empty_like(u)
    ob = cl.Buffer(device.context, mf.WRITE_ONLY, out.nbytes)
    cl.Kernel(prg, "rfilter_offsets")(device.queue, (u.size,), None, *bufs, ob)
    cl.enqueue_copy(device.queue, out, ob)
    return out


FILTERS = [ReconstructionFilter("tent", estimator="importance"),
           ReconstructionFilter("tent", radius=1.7, estimator="importance"),
           ReconstructionFilter("gaussian", estimator="importance"),
           ReconstructionFilter("gaussian", stddev=0.3, estimator="importance")]


def importance(scene: pyclpt.Scene) -> pyclpt.Scene:
    """``scene`` with its filter importance sampled (estimator="importance"), in place."""
    scene.film.rfilter.estimator = "importance"
    return scene


@pytest.mark.parametrize("rfilter", FILTERS, ids=lambda f: f"{f.kind}-{f.radius if f.kind == 'tent' else f.stddev}")
def test_offsets_follow_mitsubas_filter(each_device, rfilter):
    """Chi-square of 10^6 offsets in 80 bins over the filter's support against the integrals of Mitsuba's
    w(x) (normalised), and the numpy mirror of the device's mapping equal to it."""
    u = np.random.default_rng(5).random(1_000_000, dtype=np.float32)
    x = device_offsets(each_device, rfilter, u)
    r = rfilter.extent
    assert np.all(np.abs(x) <= r * (1 + 1e-6))
    edges = np.linspace(-r, r, 81)

    def w(t):
        return float(mitsuba_filter(rfilter.kind, np.array(t), rfilter.radius, rfilter.stddev))

    mass = np.array([integrate.quad(w, a, b)[0] for a, b in zip(edges[:-1], edges[1:])])
    observed = np.histogram(x, edges)[0]
    p, diag = chi2_pvalue(observed, mass / mass.sum() * u.size)
    assert p > 0.01, diag
    np.testing.assert_allclose(x, sample_offsets(rfilter, u), atol=2e-6)


def test_box_is_the_old_uniform_jitter(device):
    """The box compiles no -D and returns the random number itself: box images are bit for bit what they
    were before filters existed."""
    u = np.random.default_rng(1).random(4096, dtype=np.float32)
    np.testing.assert_array_equal(device_offsets(device, ReconstructionFilter(), u) + np.float32(0.5), u)
    assert filter_kind(ReconstructionFilter()) == 0
    assert pyclpt.load("cornell-box").film.rfilter.kind == "box"


def test_gaussian_is_mitsuba3_cpu_polynomial():
    """Mitsuba 3 on the CPU evaluates its gaussian as a Remez polynomial (src/rfilters/gaussian.cpp) shifted
    to reach 0 at 4 stddev; the exact form pyclpt samples is within 5e-4 of it (of a peak of 1)."""
    coeff = [9.992604880e-1, -4.977025247e-1, 1.222248550e-1, -1.932406282e-2, 2.136713061e-3,
             -1.679873860e-4, 9.202145248e-6, -3.329417433e-7, 7.128382794e-9, -6.821193280e-11]
    for stddev in (0.5, 0.3, 1.0):
        c = np.array(coeff) / (stddev * stddev) ** np.arange(10)
        c[0] -= np.polynomial.polynomial.polyval((4 * stddev) ** 2, c)
        x = np.linspace(-4 * stddev, 4 * stddev, 2001)
        poly = np.maximum(np.polynomial.polynomial.polyval(x * x, c), 0.0)
        assert np.abs(poly - mitsuba_filter("gaussian", x, stddev=stddev)).max() < 5e-4


@pytest.fixture(scope="module")
def rfilter_images() -> dict[str, np.ndarray]:
    """tests/data/rfilter.xml with each filter at 1024 spp (64x48); tent and gaussian with either estimator
    (``tent`` the default, splatting; ``tent-importance``)."""
    images = {k: pyclpt.render(pyclpt.load(DATA / "rfilter.xml", filter=k), spp=1024, seed=3, progress=False)
              for k in ("box", "tent", "gaussian")}
    for k in ("tent", "gaussian"):
        scene = importance(pyclpt.load(DATA / "rfilter.xml", filter=k))
        images[f"{k}-importance"] = pyclpt.render(scene, spp=1024, seed=3, progress=False)
    return images


@pytest.mark.parametrize("estimator", ["splat", "importance"])
@pytest.mark.parametrize("kind", ["tent", "gaussian"])
def test_filter_matches_mitsuba(kind, estimator, rfilter_images):
    """Mitsuba 3 rendering tests/data/rfilter.xml (tests/data/make_plugin_reference.py, 16384 spp): a
    checkerboard at a grazing angle and a slit narrower than a pixel. The mean within 1 %, pixel relative
    MSE under 4e-3 at 1024 spp (importance sampling: measured 1.8e-3 for both, the noise of 1024 spp;
    splatting, the default: 5.7e-4 and 5.4e-4), while the box differs from the same reference by more than 10 times
    that (measured 0.058 against the tent, 0.10 against the gaussian) and the other filter by more than
    twice (0.010, 0.011)."""
    ref = np.load(DATA / f"rfilter-{kind}-mitsuba.npy")
    loaded = pyclpt.load(DATA / "rfilter.xml", filter=kind).film.rfilter
    assert loaded.kind == kind and loaded.estimator == "splat"

    def rel_mse(img):
        return float(np.mean((img - ref) ** 2) / np.mean(ref ** 2))

    img = rfilter_images[kind if estimator == "splat" else f"{kind}-importance"]
    np.testing.assert_allclose(img.mean((0, 1)), ref.mean((0, 1)), rtol=0.01)
    tolerance = 4e-3
    assert rel_mse(img) < tolerance, rel_mse(img)
    assert rel_mse(rfilter_images["box"]) > 10 * tolerance
    other = "gaussian" if kind == "tent" else "tent"
    assert rel_mse(rfilter_images[other]) > 2 * tolerance


@pytest.mark.parametrize("kind", ["box", "tent", "gaussian"])
def test_megakernel_equals_wavefront_and_gradient_primal(kind, each_device):
    """Filter importance sampling (the splatting film's: test_splat_megakernel_equals_wavefront_...); the AoS path
    state with one filter (the filter is path_init's camera ray alone, written through the same accessors)."""
    scene = importance(pyclpt.load(DATA / "rfilter.xml", filter=kind))
    opts = dict(spp=2, seed=5, width=16, height=12, max_depth=3, progress=False, device=each_device)
    mega = pyclpt.render(scene, **opts)
    np.testing.assert_array_equal(mega, pyclpt.render(scene, integrator="wavefront", **opts))
    if kind == "gaussian":
        np.testing.assert_array_equal(mega, pyclpt.render(scene, integrator="wavefront", layout="aos", **opts))
    replay = replay_for(scene, width=16, height=12, max_depth=3, device=each_device)
    np.testing.assert_array_equal(replay.primal(2, 5), mega)


def test_filter_blurs_a_thin_slit(rfilter_images):
    """The slit (narrower than a pixel): the gaussian spreads its light over neighbouring columns, so the
    brightest pixel is dimmer and more pixels are lit, with the image's total the same."""
    box, gauss = rfilter_images["box"], rfilter_images["gaussian"]
    assert gauss.max() < 0.85 * box.max()
    assert (gauss.max(-1) > 2.0).sum() > (box.max(-1) > 2.0).sum()
    assert gauss.mean() == pytest.approx(box.mean(), rel=0.01)


# ---- loading ------------------------------------------------------------------------------------------


def _xml(tmp_path, film: str) -> Path:
    path = tmp_path / "s.xml"
    path.write_text(f"""<scene version="3.0.0"><sensor type="perspective">{film}</sensor>
        <shape type="sphere"/></scene>""")
    return path


def test_mitsuba_default_is_the_gaussian(tmp_path):
    """A Mitsuba file or dictionary without an rfilter (or without a film) gets Mitsuba's default, the
    gaussian of stddev 0.5; an XML 0.5 file too."""
    for film in ('<film type="hdrfilm"/>', ""):
        assert pyclpt.load(_xml(tmp_path, film)).film.rfilter == ReconstructionFilter("gaussian")
    old = tmp_path / "old.xml"
    old.write_text('<scene version="0.5.0"><sensor type="perspective"><film type="hdrfilm"/></sensor>'
                   '<shape type="sphere"/></scene>')
    assert pyclpt.load(old).film.rfilter.kind == "gaussian"
    d = {"type": "scene", "sensor": {"type": "perspective", "film": {"type": "hdrfilm"}}, "s": {"type": "sphere"}}
    assert pyclpt.load_dict(d).film.rfilter.kind == "gaussian"
    assert pyclpt.Film().rfilter.kind == "box"  # pyclpt's own model: the box


def test_filter_parameters(tmp_path):
    s = pyclpt.load(_xml(tmp_path, '<film type="hdrfilm"><rfilter type="tent"><float name="radius" value="1.5"/>'
                                   '</rfilter></film>'))
    assert s.film.rfilter == ReconstructionFilter("tent", radius=1.5) and s.film.rfilter.extent == 1.5
    s = pyclpt.load(_xml(tmp_path, '<film type="hdrfilm"><rfilter type="gaussian"><float name="stddev" '
                                   'value="0.25"/></rfilter></film>'))
    assert s.film.rfilter.stddev == 0.25 and s.film.rfilter.extent == 1.0
    d = {"type": "scene", "sensor": sensor(FRONT_CAMERA, rfilter="tent"), "s": {"type": "sphere"}}
    assert pyclpt.load_dict(d).film.rfilter.kind == "tent"


def test_bad_filters_name_the_value(tmp_path, caplog):
    with pytest.raises(pyclpt.SceneDictError, match=r"s\.xml:1.*stddev must be .*-0\.5"):
        pyclpt.load(_xml(tmp_path, '<film type="hdrfilm"><rfilter type="gaussian"><float name="stddev" '
                                   'value="-0.5"/></rfilter></film>'))
    with pytest.raises(pyclpt.SceneDictError, match="radius must be > 0 pixels, got 0"):
        pyclpt.load(_xml(tmp_path, '<film type="hdrfilm"><rfilter type="tent"><float name="radius" value="0"/>'
                                   '</rfilter></film>'))
    with pytest.raises(pyclpt.SceneDictError, match="unknown reconstruction filter 'blackman'"):
        pyclpt.load(_xml(tmp_path, '<film type="hdrfilm"><rfilter type="blackman"/></film>'))
    with caplog.at_level(logging.WARNING, logger="pyclpt"):
        s = pyclpt.load(_xml(tmp_path, '<film type="hdrfilm"><rfilter type="mitchell"/></film>'))
    assert s.film.rfilter.kind == "gaussian"
    assert "reconstruction filter 'mitchell': the gaussian (stddev 0.5) used" in caplog.text
    with pytest.raises(ValueError, match="kind must be one of"):
        ReconstructionFilter("lanczos")
    with pytest.raises(TypeError, match="ReconstructionFilter"):
        pyclpt.Film(rfilter="tent")


def test_renderer_keeps_its_filter_kind(device):
    """The filter's kind is a -D specialisation: another kind needs a new renderer (as a camera's kind);
    its parameters are constants, read again with the camera."""
    scene = object_under_sky({"type": "diffuse"}, radiance=1.0)
    scene.film.rfilter = ReconstructionFilter("gaussian", estimator="importance")
    buffers = SceneBuffers(scene, device)
    assert buffers.defines["SCENE_FILTER"] == 2
    scene.film.rfilter = ReconstructionFilter("gaussian", stddev=0.3, estimator="importance")
    buffers.refresh_camera()
    scene.film.rfilter = ReconstructionFilter("tent", estimator="importance")
    with pytest.raises(ValueError, match="reconstruction filter changed kind"):
        buffers.refresh_camera()


@pytest.mark.parametrize("size", [None, (8, 6)])
def test_progressive_renderer_follows_a_filter_change(size):
    """A filter changed on the scene reaches the progressive renderer (a rebuild, another kind compiled in),
    with or without its own resolution; its frames are then the filter's render."""
    scene = object_under_sky({"type": "diffuse"}, radiance=1.0)
    scene.film = pyclpt.Film(8, 6)
    w, h = size or (None, None)
    pr = pyclpt.ProgressiveRenderer(scene, seed=4, max_depth=2, width=w, height=h)
    pr.step(2)
    scene.film.rfilter = ReconstructionFilter("gaussian")
    assert pr.sync()
    assert pr.frame_count == 0
    pr.step(2)
    np.testing.assert_array_equal(pr.image(), pyclpt.render(scene, spp=2, seed=4, max_depth=2, width=8, height=6,
                                                            progress=False))


# ---- the splatting estimator (estimator="splat", pyclpt/film/splat.py) --------------------------------

SPLATS = [ReconstructionFilter("tent", estimator="splat"), ReconstructionFilter("tent", radius=1.7, estimator="splat"),
          ReconstructionFilter("gaussian", estimator="splat"),
          ReconstructionFilter("gaussian", stddev=0.3, estimator="splat")]


def _ids(f: ReconstructionFilter) -> str:
    return f"{f.kind}-{f.radius if f.kind == 'tent' else f.stddev}"


def _positions(seed: int, width: int, height: int, sample: int, padded_width: int, x0: int = 0,
               y0: int = 0) -> np.ndarray:
    """(H, W, 2): the camera ray's place in its pixel (rng_2d of bounce 0, DIM_CAMERA_X = 7) by the Philox
    reference of tests/test_sampling.py, for the pixels keyed (y0 + y) padded_width + x0 + x."""
    from test_sampling import philox_ref

    out = np.empty((height, width, 2))
    for y in range(height):
        for x in range(width):
            r = philox_ref((sample, 0, 7, 0), (seed, (y0 + y) * padded_width + x0 + x))
            out[y, x] = [(r[0] >> 8) * 2.0 ** -24, (r[1] >> 8) * 2.0 ** -24]
    return out


@pytest.mark.parametrize("rfilter", SPLATS, ids=_ids)
def test_splat_gather_weights(device, rfilter):
    """The gather kernel against numpy (Mitsuba's w at each neighbour sample's film position, recomputed
    from the Philox reference): a window (x0, y0) = (3, 2) of an image 20 pixels wide, its frames with the
    margin of reach pixels; random radiance over two frames, and one bright sample, whose spread is the
    filter's footprint around it (nothing beyond the reach, w at the offsets inside)."""
    from pyclpt.film.splat import SplatFilm, gather_reference, reach, weight

    w, h, seed, first, x0, y0 = 11, 9, 77, 5, 3, 2
    k = reach(rfilter)
    assert k == rfilter.splat_reach == (2 if rfilter.extent > 1.5 else 1)
    sp = SplatFilm(device, rfilter, w, h, 2, 20, x0, y0)
    tw, th = w + 2 * k, h + 2 * k
    frames = np.random.default_rng(3).random((2, th, tw, 3)).astype(np.float32)
    frames[1] = 0.0
    frames[1, 4 + k, 5 + k] = 100.0  # the bright sample, in window pixel (5, 4)
    mf = cl.mem_flags
    buf = cl.Buffer(device.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=frames)
    sp.gather(buf, 2, seed, first)
    out = np.empty((2, h, w, 3), np.float32)
    wts = np.empty((2, h, w), np.float32)
    cl.enqueue_copy(device.queue, out, sp.out)
    cl.enqueue_copy(device.queue, wts, sp.weights)
    for j in range(2):
        pos = _positions(seed, tw, th, first + j, 20 + 2 * k, x0, y0)
        num, den = gather_reference(rfilter, frames[j].astype(np.float64), pos)
        np.testing.assert_allclose(out[j], num * sp.inv_norm, rtol=2e-5, atol=1e-6)
        np.testing.assert_allclose(wts[j], den * sp.inv_norm, rtol=2e-5, atol=1e-7)
    ys, xs = np.nonzero(out[1, ..., 0] > 0)
    assert ys.min() >= 4 - k and ys.max() <= 4 + k and xs.min() >= 5 - k and xs.max() <= 5 + k
    pos = _positions(seed, tw, th, first + 1, 20 + 2 * k, x0, y0)[4 + k, 5 + k]
    py, px = np.mgrid[0:h, 0:w]
    want = 100.0 * weight(rfilter, 5 + pos[0] - px - 0.5) * weight(rfilter, 4 + pos[1] - py - 0.5)
    np.testing.assert_allclose(out[1, ..., 0] / sp.inv_norm, want, rtol=2e-5, atol=1e-5)


@pytest.mark.parametrize("rfilter", SPLATS[::2], ids=_ids)
def test_splat_keeps_a_constant_image_constant(rfilter):
    """Only a constant sky: every pixel is its radiance, edges and corners too (the weights cancel)."""
    scene = pyclpt.load_dict({"type": "scene", "sensor": sensor(FRONT_CAMERA), "sky": {"type": "constant",
                              "radiance": 0.75}, "behind": {"type": "sphere", "center": [0, 0, 9], "radius": 0.1}})
    scene.film.rfilter = rfilter
    img = pyclpt.render(scene, spp=3, seed=2, width=13, height=7, max_depth=2, progress=False)
    np.testing.assert_allclose(img, 0.75, rtol=2e-6)


@pytest.mark.parametrize("rfilter", SPLATS[::2], ids=_ids)
def test_splat_weights_average_to_the_filters_integral(device, rfilter):
    """A pixel's weights per frame average to the integral of w squared (the product of its column's and
    row's, pyclpt.film.splat.expected_weights: the margin gives the edge pixels all of it, as Mitsuba's
    sample_border), within the noise of 4096 frames."""
    from pyclpt.film.splat import SplatFilm, expected_weights, integral

    w, h = 12, 8
    sp = SplatFilm(device, rfilter, w, h, 64, image_width=w)
    k = sp.reach
    frame = cl.Buffer(device.context, cl.mem_flags.READ_WRITE, 4 * 3 * (w + 2 * k) * (h + 2 * k) * 64)
    mean = sp.mean_weights(frame, 4096, seed=9)
    want = np.outer(expected_weights(rfilter, h), expected_weights(rfilter, w))
    np.testing.assert_allclose(want, integral(rfilter) ** 2, rtol=1e-6)
    np.testing.assert_allclose(mean, want, rtol=0.03)
    assert expected_weights(rfilter, w, pad=0)[0] < 0.9 * integral(rfilter)  # without the margin: cut


@pytest.mark.parametrize("kind", ["tent", "gaussian"])
def test_splat_megakernel_equals_wavefront_and_gradient_primal(kind, each_device):
    """The seed contract with splatting: megakernel, wavefront SoA and AoS, and the gradient renderer's
    primal give the same image bit for bit, and it is the frame's gather, not the box."""
    scene = pyclpt.load(DATA / "rfilter.xml", filter=kind)
    scene.film.rfilter = ReconstructionFilter(kind, estimator="splat")
    opts = dict(spp=3, seed=5, width=16, height=12, max_depth=3, progress=False, device=each_device)
    mega = pyclpt.render(scene, **opts)
    np.testing.assert_array_equal(mega, pyclpt.render(scene, integrator="wavefront", **opts))
    np.testing.assert_array_equal(mega, pyclpt.render(scene, integrator="wavefront", layout="aos", **opts))
    replay = replay_for(scene, width=16, height=12, max_depth=3, device=each_device)
    np.testing.assert_array_equal(replay.primal(3, 5), mega)
    box = scene.film.rfilter = ReconstructionFilter()
    assert box.kind == "box"
    assert np.abs(pyclpt.render(scene, **opts) - mega).max() > 0.1


def test_splat_has_less_variance_than_importance_sampling():
    """tests/data/rfilter.xml at 32x24, 8 spp, 6 seeds: the per-pixel variance across seeds over the mean
    squared pixel. Splatting lets each sample count in every pixel the filter reaches; expected ratios
    ((integral of w)^2 / integral of w^2, 2D) 1/2.25 (tent) and 1/3.1 (gaussian); measured 0.45 and 0.29
    (bench/evaluations/rfilter_noise.py has the 64x48 figures)."""
    def rel_var(rfilter):
        scene = pyclpt.load(DATA / "rfilter.xml", filter=rfilter.kind)
        scene.film.rfilter = rfilter
        stack = np.stack([pyclpt.render(scene, spp=8, seed=s, width=32, height=24, progress=False)
                          for s in range(1, 7)])
        return stack.var(axis=0, ddof=1).mean() / np.mean(stack.mean(axis=0) ** 2)

    for kind, bound in (("tent", 0.7), ("gaussian", 0.55)):
        ratio = rel_var(ReconstructionFilter(kind)) / rel_var(ReconstructionFilter(kind, estimator="importance"))
        assert ratio < bound, (kind, ratio)


def test_splat_gradients_match_finite_differences():
    """Reverse mode through the splat's adjoint (backward.cl: the filter-weighted image gradient over the
    pixels a sample reaches, over their sums of weights) equals forward mode (the film's gather of the
    paths' derivatives) and central differences of the splatted image."""
    scene = object_under_sky({"type": "diffuse", "reflectance": [0.6, 0.4, 0.3]})
    scene.film.rfilter = ReconstructionFilter("gaussian", estimator="splat")
    params = pyclpt.traverse(scene)
    name = "sky.radiance.value"
    v0 = np.array(params[name])
    d = np.array([0.7, 1.1, 0.9], np.float32)
    h = 0.01 * float(np.abs(v0).max())
    w = np.random.default_rng(1).random((16, 16, 3)).astype(np.float32)
    opts = dict(spp=8, seed=11, max_depth=3, width=16, height=16)

    def loss(v):
        params.update({name: v})
        return float((w * pyclpt.render(scene, progress=False, **opts)).sum(dtype=np.float64))

    fd = (loss(v0 + h * d) - loss(v0 - h * d)) / (2 * h)
    params.update({name: v0})
    grad = pyclpt.render_backward(scene, w, params=[name], **opts)[name]
    backward = float((grad.astype(np.float64) * d).sum())
    forward = float((w * pyclpt.render_forward(scene, name, d, **opts)).sum(dtype=np.float64))
    assert abs(fd) > 1e-3
    assert backward == pytest.approx(fd, rel=0.02), (backward, fd)
    assert forward == pytest.approx(backward, rel=1e-3)


@pytest.mark.parametrize("integrator", ["megakernel", "wavefront"])
def test_splat_crop_is_the_image_window(device, integrator):
    """A splatting film renders its window with a margin (beyond the image too): a crop window's pixels are
    the whole image's bit for bit, edges and corners included."""
    from pyclpt.film.crop import Crop
    from pyclpt.rendering.renderer import Renderer

    scene = pyclpt.load(DATA / "rfilter.xml", filter="gaussian")
    scene.film.rfilter = ReconstructionFilter("gaussian", estimator="splat")
    r = Renderer(scene, integrator=integrator, width=20, height=14, max_depth=3, device=device)
    full = r.render(3, seed=4, first_sample=1)
    for crop in [(0, 0, 20, 14), (3, 2, 9, 7), (19, 13, 1, 1), (0, 5, 20, 3)]:
        rows, cols = Crop(*crop).slices()
        np.testing.assert_array_equal(r.cropped(crop).render(3, seed=4, first_sample=1), full[rows, cols],
                                      err_msg=str(crop))


def test_progressive_renderer_splats():
    """The progressive renderer's frames go through the gather (seed and sample index passed on): its
    image is pyclpt.render's; its frame image (the denoisers' input) is the frame's own samples."""
    scene = object_under_sky({"type": "diffuse"}, radiance=1.0)
    scene.film = pyclpt.Film(10, 8, ReconstructionFilter("tent", radius=1.3, estimator="splat"))
    pr = pyclpt.ProgressiveRenderer(scene, seed=4, max_depth=2)
    pr.step(3)
    np.testing.assert_array_equal(pr.image(), pyclpt.render(scene, spp=3, seed=4, max_depth=2, progress=False))
    one = pyclpt.ProgressiveRenderer(scene, seed=4, max_depth=2)
    one.step(1)
    film = one.renderer.film
    assert one.frame_image().shape == (8, 10, 3)  # the frame's own samples in the window, before the gather
    np.testing.assert_array_equal(one.frame_image(), film.read_own_frame(0))
    k = film.pad
    assert k == 1
    np.testing.assert_array_equal(film.read_own_frame(0), _raw_frame(film)[k:k + 8, k:k + 10])
    assert not np.array_equal(one.frame_image(), one.image())  # the image is splatted


def _raw_frame(film) -> np.ndarray:
    """Frame 0 of a film's buffer as the integrators wrote it, margin included."""
    out = np.empty((film.height, film.width, 3), np.float32)
    cl.enqueue_copy(film.device.queue, out, film.frame)
    return out


def _settings(**kw) -> tuple:
    from pyclpt.distributed.tasks import RENDERER_SETTINGS

    values = {**dict(integrator="megakernel", layout="soa", max_depth=None, width=None, height=None, wave_size=None,
                     precision="double"), **kw}
    return tuple((k, values[k]) for k in RENDERER_SETTINGS)


@pytest.mark.parametrize("kind", ["tent", "gaussian"])
def test_splat_split_ranges_merge_exactly(kind):
    """Split sample ranges (the tasks a cluster's workers run, here in this process) merge into the one-shot
    render: each returns its sums of weighted radiance and of weights, which the merge pools, within the
    documented bound of tests/test_distributed.py (relative 1e-12 on the double sum), the image within
    float rounding; averaging the ranges' ratios would be off by far more. Tiles too, and per-sample
    parts give the progressive renderer's images bit for bit."""
    from pyclpt.distributed.merge import merge, merge_tiles, running_averages
    from pyclpt.distributed.tasks import RenderTask, SceneSource
    from pyclpt.distributed.worker import run_task
    from pyclpt.film.crop import Crop
    from pyclpt.rendering.renderer import Renderer

    scene = pyclpt.load(DATA / "rfilter.xml", filter=kind)
    scene.film.rfilter = ReconstructionFilter(kind, estimator="splat")
    w, h, spp, seed = 16, 12, 7, 3
    r = Renderer(scene, width=w, height=h, max_depth=3)
    ref = r.render_sum(spp, seed)
    image = r.render(spp, seed)
    source, settings = SceneSource.of(scene), _settings(width=w, height=h, max_depth=3)
    ranges = [(0, 3), (3, 1), (4, 3)]
    parts = [run_task(RenderTask(source, settings, seed, s, n)) for s, n in ranges]
    assert all(p.weights is not None and p.weights.shape == (h, w) for p in parts)
    total, _ = merge(parts[::-1], spp)
    rel = np.abs(total - ref) / np.abs(ref).clip(1e-300)
    assert rel.max() <= 1e-12, rel.max()
    np.testing.assert_allclose((total / spp).astype(np.float32), image, rtol=1e-6)
    ratios = sum(r.render_sum(n, seed, first_sample=s) for s, n in ranges)  # per-range ratios, not pooled
    assert (np.abs(ratios - ref) / np.abs(ref).clip(1e-300)).max() > 1e-3
    # tiles (each with its margin) x ranges
    crops = [Crop(0, 0, 9, 12), Crop(9, 0, 7, 5), Crop(9, 5, 7, 7)]
    tiled = [run_task(RenderTask(source, settings, seed, s, n, crop=c)) for c in crops for s, n in ranges]
    total, _ = merge_tiles(tiled, spp, w, h)
    assert (np.abs(total - ref) / np.abs(ref).clip(1e-300)).max() <= 1e-12
    # per-sample parts: the progressive renderer's running images
    pr = pyclpt.ProgressiveRenderer(scene, seed=seed, width=w, height=h, max_depth=3)
    local = []
    for _ in range(4):
        pr.step()
        local.append(pr.image())
    per = [run_task(RenderTask(source, settings, seed, s, n, per_sample=True)) for s, n in [(0, 3), (3, 1)]]
    assert per[0].frame_weights.shape == (3, h, w)
    for a, b in zip(running_averages(per, 4), local):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("integrator", ["megakernel", "wavefront"])
def test_splat_gbuffer_is_each_pixels_own_samples(device, integrator):
    """A splatting film records the G-buffer of its window, each pixel's mean over its own samples (the
    margin's left out): the same as the box's in expectation (not shifted, not blurred across edges),
    megakernel = wavefront, a crop window's exactly the whole image's; the image is still splatted."""
    from pyclpt.rendering.renderer import Renderer

    names = ["albedo", "normal", "depth", "prim_id"]
    scene = pyclpt.load(DATA / "rfilter.xml", filter="gaussian")
    scene.film.rfilter = ReconstructionFilter("gaussian", estimator="splat")
    r = Renderer(scene, integrator=integrator, width=20, height=14, max_depth=3, device=device, aovs=names)
    image = r.render(48, seed=4)
    splat = r.aovs()
    assert {k: v.shape[:2] for k, v in splat.items()} == dict.fromkeys(names, (14, 20))
    mega = Renderer(scene, width=20, height=14, max_depth=3, device=device, aovs=names)
    np.testing.assert_array_equal(mega.render(48, seed=4), image)
    for name, value in mega.aovs().items():
        np.testing.assert_array_equal(value, splat[name], err_msg=name)
    boxed_scene = pyclpt.load(DATA / "rfilter.xml", filter="box")
    box = Renderer(boxed_scene, width=20, height=14, max_depth=3, device=device, aovs=names)
    box.render(48, seed=4)
    boxed = box.aovs()
    for name in ("albedo", "depth"):  # the same in expectation; shifted by the margin (2, 2), far apart
        err = np.abs(splat[name] - boxed[name]).mean()
        shifted = np.abs(splat[name][2:, 2:] - boxed[name][:-2, :-2]).mean()
        assert err < 0.5 * shifted, (name, err, shifted)
    full = r.render(3, seed=4, first_sample=1)
    aovs = r.aovs()
    crop = r.cropped((3, 2, 9, 7))
    np.testing.assert_array_equal(crop.render(3, seed=4, first_sample=1), full[2:9, 3:12])
    for name, value in crop.aovs().items():
        np.testing.assert_array_equal(value, aovs[name][2:9, 3:12], err_msg=name)


@pytest.mark.parametrize("mode", ["svgf", "oidn"])
def test_splat_denoisers_read_each_pixels_own_samples(mode):
    """With a splatting film the denoisers get the pixels' own samples (uncorrelated between pixels, as
    they expect) with the G-buffer of those samples: svgf the frame cropped to the window, oidn their
    average; the plain image is still the splatted one, pyclpt.render's."""
    scene = object_under_sky({"type": "diffuse"}, radiance=1.0)
    scene.film = pyclpt.Film(12, 9, ReconstructionFilter("gaussian", estimator="splat"))
    try:
        pr = pyclpt.ProgressiveRenderer(scene, seed=4, max_depth=2, denoiser=mode)
    except (ImportError, RuntimeError) as exc:  # oidn: needs its library
        pytest.skip(f"{mode}: {exc}")
    frames = []
    for _ in range(3):
        pr.step()
        frames.append(pr.frame_image())
    film = pr.renderer.film
    assert film.pad == 2
    np.testing.assert_array_equal(frames[-1], _raw_frame(film)[2:11, 2:14])
    np.testing.assert_array_equal(pr.image(), pyclpt.render(scene, spp=3, seed=4, max_depth=2, progress=False))
    np.testing.assert_allclose(film.denoiser_image(), np.mean(frames, axis=0), rtol=1e-6)
    out = pr.denoised()
    assert out.shape == (9, 12, 3) and np.isfinite(out).all()


@pytest.mark.parametrize("aovs", [False, True])
def test_render_memory_counts_the_splatting_film(device, monkeypatch, aovs):
    """The memory check before a render (pyclpt/rendering/memory.py) counts a splatting film's buffers: the
    frames with their margin, the gather's, the weights' accumulator, the G-buffer's records of the margined
    frames and the denoisers' frames; what the film allocates, to the few bytes of its counters."""
    import pyclpt.device.context as context
    from pyclpt.film.film import Film
    from pyclpt.rendering.memory import batch_frames, render_memory

    scene = pyclpt.load(DATA / "rfilter.xml", filter="gaussian")
    made = []
    check = context.check_alloc
    monkeypatch.setattr(context, "check_alloc", lambda d, n, what, *a: made.append(int(n)) or check(d, n, what, *a))
    Film(device, 64, 48, precision="double", batch=batch_frames(64 * 48, None), aovs=aovs, rfilter=scene.film.rfilter)
    parts = render_memory(scene, 64, 48, precision="double", integrator="megakernel", aovs=aovs)
    counted = sum(v for k, v in parts.items() if not k.startswith("scene"))
    assert "splatting film" in parts and ("denoiser frames" in parts) == aovs
    assert counted <= sum(made) <= counted + 64
