"""Issue 29's perceptual and lag goals in small, on real renders of the built-in cornell-box at 64x64
(docs/denoising.md, "Perceptual quality at 8 frames", "The light change, in the same frame" and
"Energy at 8 frames"): the denoised 8th frame's FLIP and relMSE against a converged render, its
energy against the plain average's, and how soon the histories follow a light switched to a
quarter. Each bound fails with the settings and passes of before."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pyopencl as cl
import pytest

import pyclpt
from pyclpt.denoise import Denoiser, DenoiserSettings
from pyclpt.denoise.gbuffer import AOV_COUNT

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # the evaluation's metrics: bench/evaluations/ beside pyclpt/
    sys.path.insert(0, str(REPO))

SIZE = 64
#: The defaults before issue 29's FLIP work (iterations, clip_gamma, firefly_ratio, firefly_sigma,
#: antilag), for the comparisons below.
BEFORE = dict(iterations=5, clip_gamma=2.5, firefly_ratio=4.0, firefly_sigma=3.0, antilag=4.0, conserve=False)


def relmse(x: np.ndarray, ref: np.ndarray, mask: np.ndarray | None = None) -> float:
    e = (x.astype(np.float64) - ref) ** 2 / (ref.astype(np.float64) ** 2 + 1e-2)
    return float(e[mask].mean() if mask is not None else e.mean())


@pytest.fixture(scope="module")
def reference(device) -> np.ndarray:
    """The converged cornell-box at SIZE x SIZE (1024 spp)."""
    return pyclpt.Renderer(pyclpt.load("cornell-box"), width=SIZE, height=SIZE, device=device).render(1024, seed=7)


def _frames(device, count: int, scale: float = 1.0, after: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """``count`` frames of 1 sample per pixel (colour, G-buffer), then with every emitter scaled by
    ``scale``, ``after`` more (the same renderer: the sample index goes on)."""
    scene = pyclpt.load("cornell-box")
    pr = pyclpt.ProgressiveRenderer(scene, width=SIZE, height=SIZE, device=device, denoiser="blend")
    out = []
    for k in range(count + after):
        if k == count:
            for i, m in enumerate(scene.meshes):
                if m.emission is not None:
                    pr.set_emission(i, tuple(float(c) * scale for c in m.emission))
            pr.sync()
        pr.step()
        g = np.empty(AOV_COUNT * SIZE * SIZE, np.float32)
        cl.enqueue_copy(pr.device.queue, g, pr.renderer.film.aov.mean)
        out.append((pr.frame_image(), g.reshape(AOV_COUNT, SIZE, SIZE)))
    return out


def _denoise(device, frames, settings: DenoiserSettings | None = None) -> list[np.ndarray]:
    d = Denoiser(device, SIZE, SIZE, settings=settings)
    return [d.denoise_gbuffer(color, gbuffer) for color, gbuffer in frames]


def test_flip_and_relmse_at_8_frames_on_the_cornell_box(device, reference):
    """FLIP (LDR, the evaluation's metric) of the denoised 8th frame against the 1024-spp reference:
    0.0949 with the defaults, 0.105 with those of before (against a 4096-spp reference OIDN's is
    0.075); relMSE 0.273 of the plain average's, 0.293 before. Fewer a-trous iterations, a looser
    firefly clamp and clip box. The code before the energy-preserving changes of issue 29 (the
    a-trous weight symmetric from 2 frames of history on, the firefly clamp against the
    neighbourhood's temporal moments: docs/denoising.md, "Energy at 8 frames") gave FLIP 0.101,
    relMSE 0.280 (and 0.119, 0.336 with the settings of before); the FLIP bound fails there."""
    pytest.importorskip("flip_evaluator")
    from bench.evaluations import denoise_metrics as M

    frames = _frames(device, 8)
    now = _denoise(device, frames)[-1]
    before = _denoise(device, frames, DenoiserSettings(**BEFORE))[-1]
    plain = np.mean([c for c, _ in frames], axis=0)
    flip_now, flip_before = M.flip(now, reference), M.flip(before, reference)
    assert flip_now < 0.92 * flip_before, (flip_now, flip_before)
    assert flip_now < 0.098, flip_now
    ratio_now, ratio_before = relmse(now, reference) / relmse(plain, reference), \
        relmse(before, reference) / relmse(plain, reference)
    assert ratio_now < 0.3 and ratio_now < 0.95 * ratio_before, (ratio_now, ratio_before)


def test_the_8th_frame_keeps_the_energy(device):
    """The channel means of the denoised 8th frame within 0.5 % of the plain 8-frame average's (the
    issue's 32-frame goal, reached at 8): 0.998 / 0.999 / 0.999. Before, 0.987 / 0.992 / 0.993: on a
    history under 8 frames the a-trous luminance weight was p's own variance's, so a noisy bright
    pixel gave its energy to quiet dark neighbours that took none in, and the firefly clamp cut the
    1-sample tail against a single pixel's moments (docs/denoising.md, "Energy at 8 frames")."""
    frames = _frames(device, 8)
    now = _denoise(device, frames)[-1]
    plain = np.mean([c for c, _ in frames], axis=0)
    ratio = now.reshape(-1, 3).mean(axis=0) / plain.reshape(-1, 3).mean(axis=0)
    assert np.all(np.abs(ratio - 1.0) < 0.005), ratio


def test_a_light_change_is_followed_in_its_own_frame(device, reference):
    """After 16 frames every emitter drops to a quarter. The anti-lag cuts the histories in the frame
    that sees the change (cl/denoise/antilag.cl), and for 4 frames after a light changed in view at a lower
    threshold (``antilag_changed``; cl/denoise/light_age.cl): in that frame the changed region's relMSE is
    0.0136 against a fresh run's first frame's 0.0172, and from that frame on it is within 1.5 x the fresh
    run's at the same age (+ 1e-4; the evaluation's lag rule: 0 frames). Without the lower threshold
    (``antilag_frames`` 0) it was 0.063 in the frame of the change and the lag 3 frames (0.48 and never
    within 8 when the cut came a frame late; docs/denoising.md, "The light change: cutting more readily
    after it")."""
    dark = reference * np.float32(0.25)
    luminance = np.array([0.2126, 0.7152, 0.0722])
    la, lb = reference @ luminance, dark @ luminance
    region = np.abs(lb - la) > 0.1 * np.maximum(la, lb) + 1e-2
    changed = _denoise(device, _frames(device, 16, 0.25, 8))[16:]
    fresh = _denoise(device, _frames(device, 0, 0.25, 8))
    errors = [relmse(x, dark, region) for x in changed]
    baseline = [relmse(x, dark, region) for x in fresh]
    assert errors[0] < 1.5 * baseline[0], (errors, baseline)
    lag = next(k for k, (e, b) in enumerate(zip(errors, baseline)) if e <= 1.5 * b + 1e-4)
    assert lag <= 1, (errors, baseline)
