"""The denoiser driven by the progressive renderer on real renders: it converges faster than plain
accumulation on a static scene, jitter never resets its history, a camera move reprojects instead of
resetting, the seed's blend is what it says, and the command line's --denoise / --orbit / --sequence."""
from __future__ import annotations

import numpy as np
import pytest

import pyclpt
from pyclpt.cli import main

SIZE = 48


def relmse(x: np.ndarray, ref: np.ndarray) -> float:
    return float(np.mean((x - ref) ** 2 / (ref ** 2 + 1e-2)))


@pytest.fixture(scope="module")
def reference(device) -> np.ndarray:
    """The converged cornell-box at SIZE x SIZE (2048 spp)."""
    return pyclpt.render("cornell-box", spp=2048, width=SIZE, height=SIZE, device=device, seed=77)


def test_denoised_beats_plain_accumulation_and_converges(device, reference):
    """Static camera, 1 sample per pixel per frame: the denoised frame N has a lower relMSE than the plain
    average of the same N frames for N = 1 .. 16, and its error keeps falling from 4 to 16 frames."""
    pr = pyclpt.ProgressiveRenderer(pyclpt.load("cornell-box"), width=SIZE, height=SIZE, device=device,
                                    denoiser="svgf")
    errors = {}
    for n in range(1, 17):
        pr.step()
        plain = relmse(pr.image(), reference)
        den = relmse(pr.denoised(), reference)
        assert den < plain, f"frame {n}: denoised relMSE {den:.4f} >= plain {plain:.4f}"
        errors[n] = den
    assert errors[16] < errors[8] < errors[4]
    assert pr.reset_count == 0


def test_jitter_never_resets_the_history(device):
    """A static camera: every frame's samples are jittered, and the history of (almost) every pixel grows
    by one a frame; the pixels that restart are on silhouettes, where the jittered sample can land on
    either side."""
    pr = pyclpt.ProgressiveRenderer(pyclpt.load("cornell-box"), width=SIZE, height=SIZE, device=device,
                                    denoiser="svgf")
    pr.step(6)
    hist = pr.denoiser.history_length()
    assert np.median(hist) == 6
    assert np.mean(hist == 6) > 0.9
    assert pr.reset_count == 0 and pr.sample_index == 6


def test_a_camera_move_reprojects_instead_of_resetting(device):
    """An orbit with the denoiser on: no reset, the sample index keeps counting, the plain average restarts
    every frame, and most pixels keep their history across the moves."""
    scene = pyclpt.load("cornell-box")
    orbit = pyclpt.CameraPath.orbit(scene, 8.0, 5)
    pr = pyclpt.ProgressiveRenderer(scene, width=SIZE, height=SIZE, device=device, denoiser="svgf",
                                    camera_path=orbit)
    pr.step(5)
    assert pr.reset_count == 0 and pr.sample_index == 5 and pr.reprojections == 4
    assert pr.frame_count == 1  # the plain average holds the last frame only
    hist = pr.denoiser.history_length()
    assert np.median(hist) == 5
    assert np.all(np.isfinite(pr.denoised()))
    # without the denoiser, every move resets
    plain = pyclpt.ProgressiveRenderer(pyclpt.load("cornell-box"), width=SIZE, height=SIZE, device=device,
                                       camera_path=pyclpt.CameraPath.orbit(pyclpt.load("cornell-box"), 8.0, 5))
    plain.step(5)
    assert plain.reset_count == 4 and plain.sample_index == 1


def test_the_seeds_blend(device):
    """Mode blend: 0.3 of the new frame plus 0.7 of the history, the first frame as it is."""
    pr = pyclpt.ProgressiveRenderer(pyclpt.load("cornell-box"), width=SIZE, height=SIZE, device=device,
                                    denoiser="blend")
    pr.step()
    first = pr.frame_image()
    np.testing.assert_allclose(pr.denoised(), first, rtol=1e-6)
    pr.step()
    np.testing.assert_allclose(pr.denoised(), 0.7 * first + 0.3 * pr.frame_image(), rtol=1e-5, atol=1e-6)


def test_cli_denoise_writes_the_denoised_last_frame(tmp_path, device, capsys):
    out = tmp_path / "den.exr"
    assert main(["render", "cornell-box", "--frames", "3", "--width", "24", "--height", "24", "--denoise",
                 "--device", "pocl", "-o", str(out), "--quiet"]) == 0
    assert "denoised (svgf)" in capsys.readouterr().out
    pr = pyclpt.ProgressiveRenderer(pyclpt.load("cornell-box"), width=24, height=24, device=device, denoiser="svgf")
    pr.step(3)
    np.testing.assert_allclose(pyclpt.read_image(out), pr.denoised(), rtol=1e-6, atol=1e-7)
    with pytest.raises(SystemExit):
        main(["render", "cornell-box", "--frames", "2", "--width", "8", "--height", "8", "--denoise", "median",
              "-o", str(out)])
    assert "invalid choice" in capsys.readouterr().err


def test_cli_oidn_and_its_missing_extra(tmp_path, capsys, monkeypatch):
    """--denoise oidn runs Intel Open Image Denoise on the plain average; without pyoidn the command says
    which extra to install, in one line."""
    pytest.importorskip("pyoidn", reason="the oidn extra (pip install 'pyclpt[oidn]') is not installed")
    out = tmp_path / "oidn.exr"
    assert main(["render", "cornell-box", "--frames", "2", "--width", "16", "--height", "16", "--denoise", "oidn",
                 "--device", "pocl", "-o", str(out), "--quiet"]) == 0
    assert np.all(np.isfinite(pyclpt.read_image(out)))
    monkeypatch.setitem(__import__("sys").modules, "pyoidn", None)  # as if not installed
    assert main(["render", "cornell-box", "--frames", "1", "--width", "8", "--height", "8", "--denoise", "oidn",
                 "--device", "pocl", "-o", str(out), "--quiet"]) == 1
    assert "pyclpt[oidn]" in capsys.readouterr().err
