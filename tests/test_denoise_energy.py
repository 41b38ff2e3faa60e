"""SVGF keeps the energy of its input and handles every G-buffer value (issue 29, items 1 and 3):
the firefly clamp follows each pixel's own temporal moments and is relaxed as its history grows, so
it removes (almost) no energy from a real render; a NaN/inf depth, normal or motion affects its own
pixel only and is counted; +inf depth is the sky; a 1x1 image and an isolated bright pixel converge
to their value instead of staying black."""
from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

import pyclpt
from pyclpt.denoise import Denoiser, DenoiserSettings
from pyclpt.denoise.gbuffer import AOV_COUNT, build_aovs

SIZE = 64
FRAMES = 32


def render_frames(device, scene: str, size: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """FRAMES frames of the built-in ``scene`` at size x size, 1 sample per pixel each, and their
    G-buffers, (FRAMES, H, W, 3) and (FRAMES, AOV_COUNT, H, W)."""
    pr = pyclpt.ProgressiveRenderer(pyclpt.load(scene), width=size, height=size, device=device, denoiser="svgf",
                                    seed=seed)
    colors, gbuffers = [], []
    for _ in range(FRAMES):
        pr.step()
        colors.append(pr.frame_image())
        g = np.empty(AOV_COUNT * size * size, np.float32)
        cl.enqueue_copy(pr.device.queue, g, pr.renderer.film.aov.mean)
        gbuffers.append(g.reshape(AOV_COUNT, size, size))
    return np.array(colors), np.array(gbuffers)


@pytest.fixture(scope="module")
def frames(device) -> tuple[np.ndarray, np.ndarray]:
    """The cornell-box's FRAMES frames at SIZE x SIZE and their G-buffers (render_frames)."""
    return render_frames(device, "cornell-box", SIZE)


def denoised_mean(device, frames, settings: DenoiserSettings) -> np.ndarray:
    """The channel means of the last denoised frame."""
    colors, gbuffers = frames
    size = colors.shape[1]
    d = Denoiser(device, size, size, settings=settings)
    for color, gbuffer in zip(colors, gbuffers):
        out = d.denoise_gbuffer(color, gbuffer)
    return out.reshape(-1, 3).mean(axis=0).astype(np.float64)


def test_the_firefly_clamp_keeps_the_energy(device, frames):
    """The clamp removes less than 0.5 % of any channel's mean after 32 frames (the fixed-ratio clamp
    of before removed 1.1 to 2.1 % here: 0.979 / 0.986 / 0.989 of the unclamped output)."""
    clamped = denoised_mean(device, frames, DenoiserSettings())
    unclamped = denoised_mean(device, frames, DenoiserSettings(firefly_ratio=0.0))
    ratio = clamped / unclamped
    assert np.all(np.abs(ratio - 1) < 0.005), ratio


def test_the_denoised_mean_converges_to_the_plain_average(device, frames):
    """The goal of issue 29: the 32-frame denoised channel means within 0.5 % of the plain average's
    (docs/denoising.md, "Energy"). Before the emission was kept out of the filter and the a-trous
    luminance weight made symmetric, they were 0.939 / 0.933 / 0.925 of it; with the 3x3 clip box
    0.994 / 0.999 / 0.999 (the red channel just outside); now about 0.999 / 1.001 / 1.001. One seed's ratio
    spreads by 0.2-0.3 % (seeds 0-7: 0.9956 to 1.0059, their mean 1.0001 / 1.0006 / 1.0002), so the ratio is
    that of the sums over four seeds' renders (seed 0 alone: 1.0035 / 1.0054 / 1.0059)."""
    denoised, plain = np.zeros(3), np.zeros(3)
    for seed in range(4):
        f = frames if seed == 0 else render_frames(device, "cornell-box", SIZE, seed)
        plain += f[0].reshape(-1, 3).mean(axis=0).astype(np.float64)
        denoised += denoised_mean(device, f, DenoiserSettings())
    ratio = denoised / plain
    assert np.all(np.abs(ratio - 1) < 0.005), ratio


def test_the_bunny_converges_to_the_plain_average(device):
    """The same goal on the cornell-bunny at 80x80: a small bright light, whose light reaches the ceiling
    and the floor as a sparse 1-sample tail that the firefly clamp and the clipping take, and an object
    whose edges the a-trous filter works along. The code before gave 0.989 / 0.990 / 0.990 of the plain
    average's here: the filter gave away more of the bright pixels' light than their quiet neighbours
    took in, the clamp's deficit came back only up to the robust mean of the 3x3 tiles around, and the
    clip's noise only where the anti-lag statistic stayed under half of ``antilag``. Now about 1.001 /
    1.000 / 1.000 (DenoiserSettings.conserve, cl/denoise/conserve.cl, deficit_gain.cl; docs/denoising.md,
    "Energy at 32 frames", where other sizes are measured too: not all of them meet 0.5 %)."""
    colors, gbuffers = render_frames(device, "cornell-bunny", 80)
    ratio = denoised_mean(device, (colors, gbuffers), DenoiserSettings()) / colors.reshape(-1, 3).mean(axis=0)
    assert np.all(np.abs(ratio - 1) < 0.005), ratio


def test_without_the_filter_the_history_is_the_plain_average(device, frames):
    """The temporal part alone (no a-trous iteration, no clipping) keeps the energy: its 32-frame mean
    is the plain average's within 0.5 %, clamp included."""
    ratio = (denoised_mean(device, frames, DenoiserSettings(iterations=0, clip_gamma=-1.0))
             / frames[0].reshape(-1, 3).mean(axis=0))
    assert np.all(np.abs(ratio - 1) < 0.005), ratio


# -- jittered footprints -----------------------------------------------------------------------------
#: Temporal accumulation alone, its history the plain mean of up to 32 frames (weights 1 / N).
ACCUMULATE = dict(firefly_ratio=0.0, clip_gamma=-1.0, iterations=0, give_back=False, conserve=False, antilag=0.0,
                  alpha_min=1.0 / FRAMES, max_history=FRAMES)
#: The two surfaces a footprint can show: colour, albedo, normal, depth, material id, emission.
SKY = ((3.0, 2.5, 2.0), (0.0, 0.0, 0.0), (0, 0, 0), np.inf, -1, (3.0, 2.5, 2.0))
BAR = ((0.1, 0.08, 0.06), (0.5, 0.4, 0.3), (0, 0, 1), 2.0, 1, (0, 0, 0))
RED = ((0.8, 0.1, 0.05), (0.8, 0.1, 0.05), (0, 0, 1), 3.0, 2, (0, 0, 0))
BLUE = ((0.1, 0.1, 0.8), (0.1, 0.1, 0.8), (0, 0, 1), 3.0, 2, (0, 0, 0))
WALL = ((0.6, 0.6, 0.6), (0.6, 0.6, 0.6), (0, 0, 1), 3.0, 3, (0, 0, 0))
FLOOR = ((0.12, 0.1, 0.08), (0.6, 0.5, 0.4), (0, 1, 0), 3.0, 4, (0, 0, 0))


def footprints(width: int = 48, height: int = 24) -> tuple[list, list, np.ndarray]:
    """A window (the sky behind bars a fifth of a pixel wide every 4 columns), a red and blue texture
    (its texel edges every 4 columns, half a pixel each side) and a crease (a lit wall over a dim floor,
    one row shows both), side by side: each pixel's two surfaces and the chance of the second."""
    first, second, chance = [], [], np.zeros((height, width))
    for y in range(height):
        for x in range(width):
            if x < width // 3:
                a, b, f = SKY, BAR, 0.2 if x % 4 == 1 else 0.0
            elif x < 2 * width // 3:
                a, b = (RED, BLUE) if (x // 4) % 2 else (BLUE, RED)
                f = 0.5 if x % 4 == 0 else 0.0
            else:
                a, b, f = WALL, FLOOR, 0.5 if y == height // 2 else float(y > height // 2)
            first.append(a)
            second.append(b)
            chance[y, x] = f
    return first, second, chance


def jittered_frames(frames: int = FRAMES, seed: int = 3, sky_scale=lambda k: 1.0) -> list:
    """Noise-free frames of footprints(), each pixel's one sample a frame on its second surface with its
    chance: (colour, G-buffer) pairs. ``sky_scale(k)`` scales the sky's radiance in frame k."""
    first, second, chance = footprints()
    height, width = chance.shape
    rng = np.random.default_rng(seed)
    out = []
    for k in range(frames):
        pick = (rng.random(chance.shape) < chance).ravel()
        shown = [b if p else a for a, b, p in zip(first, second, pick)]
        field = [np.array([s[i] for s in shown], np.float64) for i in range(6)]
        scale = np.where(field[4] == -1, sky_scale(k), 1.0)[:, None]
        color, albedo, normal, depth, material, emission = (v.reshape(height, width, *v.shape[1:]) for v in field)
        gbuffer = build_aovs(albedo.astype(np.float32), normal.astype(np.float32), depth.astype(np.float32),
                             material_id=material.astype(np.int32),
                             emission=(emission * scale.reshape(height, width, 1)).astype(np.float32))
        color = (color * scale.reshape(height, width, 1)).astype(np.float32)
        out.append((color, np.asarray(gbuffer, np.float32).reshape(AOV_COUNT, height, width)))
    return out


def test_jittered_footprints_accumulate_to_the_plain_average(device):
    """The G-buffer is one jittered sample a frame: a pixel on an edge, a texture boundary or behind a
    window's bar shows one surface in one frame and the other in the next. Its history is kept (its
    sample moves with the previous one: cl/denoise/reproject.cl, moves_with), the sample demodulated by
    the footprint's albedo (the pixel's albedos blended as its history) and the emission history clipped
    only where an emitter changed (emitter_moved), so temporal accumulation is the plain average of the
    frames, pixel by pixel. Before, the history was rejected where the surface switched (the 3x3
    fallback took the neighbours' histories of the side drawn), the frame's own albedo modulated a
    history of other albedos and the emission box clipped a window's history towards the side its 3x3
    drew: the texture 0.981 / 1.000 / 0.978 and the crease 1.011 of the plain average's, single pixels
    up to 134 % off (the evaluation's living room, temporal accumulation alone at 32 frames: 0.991 /
    0.990 / 0.989 of the plain average's without albedo and emission; 0.981 in the red from the
    demodulation alone, its geometry frozen)."""
    frames = jittered_frames()
    height, width = frames[0][0].shape[:2]
    d = Denoiser(device, width, height, settings=DenoiserSettings(**ACCUMULATE))
    for color, gbuffer in frames:
        out = d.denoise_gbuffer(color, gbuffer)
    plain = np.mean([c for c, _ in frames], axis=0)
    third = width // 3
    for name, part in (("window", np.s_[:, :third]), ("texture", np.s_[:, third:2 * third]),
                       ("crease", np.s_[:, 2 * third:])):
        ratio = out[part].reshape(-1, 3).mean(axis=0) / plain[part].reshape(-1, 3).mean(axis=0)
        assert np.all(np.abs(ratio - 1) < 1e-3), (name, ratio)
    np.testing.assert_allclose(out, plain, rtol=1e-4, atol=1e-6)


def test_a_changed_sky_leaves_the_jittered_window_history_at_once(device):
    """The emission history of the window follows a change of the sky to a quarter in its own frame
    (this frame's and the previous frame's emitting samples of the sky apart: emitter_moved): a pixel
    that shows the sky alone takes the new radiance, one behind a bar no more than it (and the bar's
    light)."""
    frames = jittered_frames(FRAMES + 1, sky_scale=lambda k: 0.25 if k == FRAMES else 1.0)
    height, width = frames[0][0].shape[:2]
    d = Denoiser(device, width, height, settings=DenoiserSettings(**ACCUMULATE))
    for color, gbuffer in frames:
        out = d.denoise_gbuffer(color, gbuffer)
    _, _, chance = footprints()
    window = np.zeros(chance.shape, bool)
    window[:, :width // 3] = True
    new_sky = 0.25 * np.array(SKY[0], np.float32)
    sky_alone, behind_bars = window & (chance == 0), window & (chance > 0)
    np.testing.assert_allclose(out[sky_alone], np.broadcast_to(new_sky, (int(sky_alone.sum()), 3)), rtol=1e-5)
    assert np.all(out[behind_bars] <= new_sky + np.array(BAR[0], np.float32)), out[behind_bars].max(axis=0)


# -- every G-buffer value ---------------------------------------------------------------------------
W, H = 40, 32
AT = (10, 10)


def plane() -> dict[str, np.ndarray]:
    """A lit plane (depth 5 .. 5.4, facing the camera) under a grey albedo, and its noise-free colour."""
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    illum = 0.3 + 0.5 * np.exp(-((xx - 12) ** 2 + (yy - 14) ** 2) / 200)
    albedo = np.full((H, W, 3), 0.7, np.float32)
    normal = np.zeros((H, W, 3), np.float32)
    normal[..., 2] = -1.0
    return {"truth": (illum[..., None] * np.array([1.0, 0.9, 0.8]) * albedo).astype(np.float32),
            "albedo": albedo, "normal": normal, "depth": (5 + 0.01 * xx).astype(np.float32)}


def run(device, change=None, frames: int = 8, width: int = W, sky: slice | None = None) -> tuple[np.ndarray, int]:
    """The last of ``frames`` denoised noisy frames of the plane (seeded) and the dropped count;
    ``change(k, depth, normal, motion)`` edits frame k's G-buffer in place."""
    sc = plane()
    rng = np.random.default_rng(1)
    d = Denoiser(device, width, H)
    material = np.zeros((H, W), np.int32)
    for k in range(frames):
        color = sc["truth"] * rng.gamma(0.5, 2.0, (H, W, 1)).astype(np.float32)
        depth, normal, motion = sc["depth"].copy(), sc["normal"].copy(), np.zeros((H, W, 2), np.float32)
        if change is not None:
            change(k, depth, normal, motion)
        out = d.denoise(color[:, :width], sc["albedo"][:, :width], normal[:, :width], depth[:, :width],
                        motion[:, :width], material[:, :width])
    return out, d.dropped


def setter(what: str, value: float, channel: int | None = None):
    def change(k, depth, normal, motion):
        arr = {"depth": depth, "normal": normal, "motion": motion}[what]
        arr[AT if channel is None else (*AT, channel)] = value
    return change


@pytest.mark.parametrize("what, value, channel, same_as", [
    ("depth", np.nan, None, 0.0), ("depth", -np.inf, None, 0.0), ("depth", np.inf, None, 0.0),
    ("normal", np.nan, 1, None), ("normal", np.inf, 0, None),
    ("motion", np.nan, 0, None), ("motion", np.inf, 1, None)],
    ids=["nan-depth", "-inf-depth", "+inf-depth", "nan-normal", "inf-normal", "nan-motion", "inf-motion"])
def test_a_bad_gbuffer_value_is_counted_and_stays_in_its_pixel(device, what, value, channel, same_as):
    """A NaN/inf in one pixel's depth, normal or motion, every frame: the output is what a known
    value of that meaning gives (a bad or +inf depth: the background, depth 0; a bad normal: unknown,
    0; a bad motion: not seen, off screen), bit for bit; the pixel is counted once a frame (+inf
    depth, the sky convention, is not); and the other pixels change by at most a few per cent under
    this heavy noise: the pixel is one tap fewer in their filters (it changed them by up to 18 %,
    as its unfiltered variance loosened their weights)."""
    clean, dropped = run(device)
    assert dropped == 0
    out, dropped = run(device, setter(what, value, channel))
    meaning = {"depth": 0.0, "normal": 0.0, "motion": 1e6}[what] if same_as is None else same_as
    known, _ = run(device, setter(what, meaning, channel) if what != "normal" else
                   lambda k, d, n, m: n.__setitem__(AT, 0.0))
    np.testing.assert_array_equal(out, known)
    assert dropped == (0 if (what == "depth" and value == np.inf) else 8)
    assert np.isfinite(out).all()
    change = np.abs(out - clean).max(axis=-1) / clean.max(axis=-1)
    change[AT] = 0
    assert change.max() < 0.05, change.max()


def test_inf_depth_is_the_sky(device):
    """The right half of the image +inf depth (the sky convention) gives exactly what depth 0 gives,
    and the lit half denoises as well as on its own (the sky's variance no longer loosens the weights
    beside it)."""
    half = slice(W // 2, W)

    def sky(value):
        def change(k, depth, normal, motion):
            depth[:, half] = value
        return change

    inf, dropped = run(device, sky(np.inf))
    zero, _ = run(device, sky(0.0))
    np.testing.assert_array_equal(inf, zero)
    assert dropped == 0
    alone, _ = run(device, width=W // 2)
    truth = plane()["truth"][:, :W // 2]
    err = {name: float(np.mean((img[:, :W // 2] - truth) ** 2 / (truth ** 2 + 1e-2))) for name, img in
           (("with sky", inf), ("alone", alone))}
    assert err["with sky"] < 1.1 * err["alone"], err


def test_a_1x1_image_denoises_to_its_average(device):
    """No neighbour: no spatial reference, no clip box; the output of the first 16 frames (plain 1/N
    weights) is their average."""
    rng = np.random.default_rng(3)
    d = Denoiser(device, 1, 1)
    frames = (np.array([0.5, 1.0, 2.0], np.float32) * rng.uniform(0, 2, (16, 1, 1, 1))).astype(np.float32)
    for frame in frames:
        out = d.denoise(frame)
    np.testing.assert_allclose(out, frames.mean(axis=0), rtol=1e-5)


def test_an_isolated_bright_pixel_converges(device):
    """A lit pixel among black ones: the first frame's clamp (its neighbours' mean is 0) takes it, but
    its own moments keep it, and it converges to its value (it stayed black forever)."""
    color = np.zeros((9, 9, 3), np.float32)
    color[4, 4] = 5.0
    d = Denoiser(device, 9, 9)
    for _ in range(64):
        out = d.denoise(color)
    assert out[4, 4, 0] > 0.99 * 5.0, out[4, 4]
    assert out.sum() / 3 == pytest.approx(5.0, rel=0.01)


# -- quality on a real render ------------------------------------------------------------------------
def test_quality_beats_the_plain_average_on_the_cornell_box(device, frames):
    """The quality goal in small (docs/denoising.md, "Energy and quality"): after 8 frames the denoised
    relMSE against a converged render is a fraction of the plain 8-frame average's. At 256x256 it is
    0.15 of it (the goal: 0.25); at this size about 0.33 (a 4096-spp reference; 0.28 before the
    emission was kept out of the filter, which then dimmed the light by a tenth). The bound 0.5 is
    generous: it fails if the filter stops filtering or the light is blurred into the ceiling."""
    colors, gbuffers = frames
    ref = pyclpt.Renderer(pyclpt.load("cornell-box"), width=SIZE, height=SIZE, device=device).render(1024, seed=7)
    d = Denoiser(device, SIZE, SIZE)
    for color, gbuffer in zip(colors[:8], gbuffers[:8]):
        out = d.denoise_gbuffer(color, gbuffer)

    def rel_mse(x: np.ndarray) -> float:
        return float(np.mean((x.astype(np.float64) - ref) ** 2 / (ref.astype(np.float64) ** 2 + 1e-2)))

    ratio = rel_mse(out) / rel_mse(colors[:8].mean(axis=0))
    assert ratio < 0.5, ratio


def test_the_bunny_gets_its_ceilings_clamped_light_back_on_a_long_history(device):
    """The same goal on the cornell-bunny at 96x96, where the ceiling beside the small light loses 0.4 to 0.9
    of its light to the firefly clamp: the clamp's deficit is given back per tile, capped, and a cap of 0.25
    whatever the history's length (DEFICIT_MAX) left 0.9983 / 0.9952 / 0.9920 of the plain average's here.
    The cap now grows from 0.25 at 16 frames of history to 0.75 at 32 (cl/denoise/svgf.h, deficit_cap):
    about 0.999 / 0.999 / 0.998 (docs/denoising.md, "The deficit's cap on a long history")."""
    colors, gbuffers = render_frames(device, "cornell-bunny", 96)
    ratio = denoised_mean(device, (colors, gbuffers), DenoiserSettings()) / colors.reshape(-1, 3).mean(axis=0)
    assert np.all(np.abs(ratio - 1) < 0.005), ratio
