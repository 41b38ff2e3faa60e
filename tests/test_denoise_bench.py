"""The denoising evaluation's pieces: the OIDN wrapper (pyclpt/denoise/oidn.py), the image metrics
(bench/evaluations/denoise_metrics.py) on inputs with known answers, and the evaluation driver
(bench/evaluations/denoise_eval.py) on small runs. Correctness only: no timing is checked.

pyoidn, scikit-image and flip-evaluator are optional extras ([oidn], [bench]); the tests that need
one skip with the reason when it is missing."""
from __future__ import annotations

import copy
import importlib.util
import json
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # a source checkout: bench/evaluations/ beside pyclpt/
    sys.path.insert(0, str(REPO))
import pyclpt  # noqa: E402
from bench.evaluations import denoise_eval as E  # noqa: E402
from bench.evaluations import denoise_metrics as M  # noqa: E402
from bench.evaluations import denoise_references as R  # noqa: E402
from pyclpt.denoise import oidn as oidn_module  # noqa: E402


def _has(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


needs_oidn = pytest.mark.skipif(not oidn_module.available(), reason="pyoidn (optional extra [oidn]) is not installed "
                                "or OIDN's CPU device is unsupported")
needs_skimage = pytest.mark.skipif(not _has("skimage"), reason="scikit-image (optional extra [bench]) is not installed")
needs_flip = pytest.mark.skipif(not _has("flip_evaluator"),
                                reason="flip-evaluator (optional extra [bench]) is not installed")


def _truth(h: int = 48, w: int = 64) -> np.ndarray:
    """A smooth HDR image: gradients, a bright disc, a dark corner."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    img = np.stack([x / w, y / h, 0.3 + 0.2 * np.sin(x / 7.0)], axis=-1)
    img[(x - w / 2) ** 2 + (y - h / 2) ** 2 < (min(h, w) / 5) ** 2] *= 6.0
    return img.astype(np.float32)


def _noisy(truth: np.ndarray, seed: int = 0) -> np.ndarray:
    """Unbiased Monte Carlo-like noise: the truth times an exponential variate of mean 1."""
    rng = np.random.default_rng(seed)
    return (truth * rng.exponential(1.0, size=truth.shape)).astype(np.float32)


# -- OIDN -------------------------------------------------------------------------------------------

@needs_oidn
def test_oidn_reduces_the_error_of_a_noisy_image():
    truth = _truth()
    noisy = _noisy(truth)
    h, w = truth.shape[:2]
    albedo = np.full_like(truth, 0.8)
    normal = np.zeros_like(truth)
    normal[..., 2] = 1.0
    with oidn_module.Oidn(w, h) as oidn:
        plain = oidn.run_numpy(noisy)
        guided = oidn.run_numpy(noisy, albedo, normal)
        assert oidn.calls == 2
    for out in (plain, guided):
        assert out.shape == truth.shape and out.dtype == np.float32 and np.isfinite(out).all()
        assert M.relmse(out, truth) < 0.2 * M.relmse(noisy, truth)


@needs_oidn
def test_oidn_sanitises_non_finite_input_and_counts_it():
    truth = _truth(24, 32)
    noisy = _noisy(truth)
    noisy[1, 2, 0] = np.nan
    noisy[3, 4, :] = np.inf
    noisy[5, 6, 1] = -2.0  # negative: clamped, not counted as non-finite
    albedo = np.full_like(truth, 0.5)
    albedo[0, 0, 0] = np.nan
    oidn = oidn_module.Oidn(32, 24, quality="fast")
    out = oidn.run_numpy(noisy, albedo)
    assert np.isfinite(out).all()
    assert oidn.last_nonfinite == {"color": 4, "albedo": 1, "normal": 0}
    assert oidn.clamped["color"] == 1
    oidn.run_numpy(truth)
    assert oidn.last_nonfinite["color"] == 0 and oidn.nonfinite["color"] == 4
    assert oidn.stats()["calls"] == 2
    oidn.close()
    with pytest.raises(RuntimeError, match="closed"):
        oidn.run_numpy(truth)


@needs_oidn
def test_oidn_validates_shapes_and_types():
    oidn = oidn_module.Oidn(16, 8)
    good = np.zeros((8, 16, 3), np.float32)
    with pytest.raises(ValueError, match=r"color must have shape \(height, width, 3\) = \(8, 16, 3\).*\(16, 8, 3\)"):
        oidn.run_numpy(np.zeros((16, 8, 3), np.float32))
    with pytest.raises(ValueError, match=r"albedo must have shape.*got \(8, 16\)"):
        oidn.run_numpy(good, np.zeros((8, 16), np.float32))
    with pytest.raises(TypeError, match="color must be a float array.*int32"):
        oidn.run_numpy(np.zeros((8, 16, 3), np.int32))
    with pytest.raises(TypeError, match="normal must be a numpy array"):
        oidn.run_numpy(good, good, [[0.0]])
    with pytest.raises(ValueError, match="normal image only together with an albedo"):
        oidn.run_numpy(good, None, good)
    with pytest.raises(ValueError, match="unknown quality 'best'"):
        oidn_module.Oidn(16, 8, quality="best")
    with pytest.raises(ValueError, match="width must be an integer >= 1"):
        oidn_module.Oidn(0, 8)
    assert oidn.run_numpy(good.astype(np.float64)).dtype == np.float32  # float64 input accepted


def test_oidn_missing_module_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyoidn", None)  # "import pyoidn" now raises ImportError
    with pytest.raises(ImportError, match=r"pip install 'pyclpt\[oidn\]'"):
        oidn_module.Oidn(8, 8)
    assert oidn_module.available() is False


# -- metrics ------------------------------------------------------------------------------------------

def test_relmse_known_values():
    ref = np.zeros((4, 5, 3), np.float32)
    assert M.relmse(ref, ref) == 0.0
    assert M.relmse(ref + 1.0, ref) == pytest.approx(100.0)  # 1 / (0 + 1e-2)
    ref1 = np.ones((4, 5, 3), np.float32)
    assert M.relmse(ref1 * 2.0, ref1) == pytest.approx(1.0 / 1.01)
    x = ref1.copy()
    x[0, 0] = 2.0  # one pixel of 20 off by 1 in all channels
    assert M.relmse(x, ref1) == pytest.approx(1.0 / 1.01 / 20)
    mask = np.zeros((4, 5), bool)
    mask[0, :2] = True
    assert M.relmse(x, ref1, mask=mask) == pytest.approx(1.0 / 1.01 / 2)
    assert np.isnan(M.relmse(x, ref1, mask=np.zeros((4, 5), bool)))
    with pytest.raises(ValueError, match="shapes differ"):
        M.relmse(x, ref1[:3])
    with pytest.raises(ValueError, match="mask must be"):
        M.relmse(x, ref1, mask=np.ones((5, 4), bool))


def test_tonemap_clips_and_encodes_srgb():
    img = np.array([[[0.0, 0.0031308, 1.0], [2.0, -1.0, np.nan]]], np.float32)
    out = M.tonemap(img)
    assert out.dtype == np.float32
    np.testing.assert_allclose(out, [[[0.0, 0.0031308 * 12.92, 1.0], [1.0, 0.0, 0.0]]], rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(M.tonemap(np.full((1, 1, 3), 0.5, np.float32), exposure=1.0), 1.0)


@needs_skimage
def test_ssim_identical_is_one_and_noise_lowers_it():
    truth = _truth()
    assert M.ssim(truth, truth) == pytest.approx(1.0)
    a = M.ssim(_noisy(truth), truth)
    b = M.ssim(0.5 * (_noisy(truth, 1) + _noisy(truth, 2)), truth)
    assert a < b < 1.0
    mask = np.zeros(truth.shape[:2], bool)
    mask[:10] = True
    assert M.ssim(truth, truth, mask=mask) == pytest.approx(1.0)
    assert M.ssim(truth[:5, :4], truth[:5, :4]) == pytest.approx(1.0)  # small images: a smaller window


@needs_flip
def test_flip_identical_is_zero_and_grows_with_the_error():
    truth = _truth()
    for mode in M.FLIP_MODES:
        assert M.flip(truth, truth, mode=mode) == pytest.approx(0.0, abs=1e-6)
        a = M.flip(_noisy(truth), truth, mode=mode)
        b = M.flip(0.25 * sum(_noisy(truth, s) for s in range(4)), truth, mode=mode)
        assert 0.0 < b < a <= 1.0, mode
    black = np.zeros((16, 16, 3), np.float32)
    assert M.flip(black + 1.0, black) > 0.9  # white against black: nearly the largest error
    assert M.flip_map(truth, truth).shape == truth.shape[:2]
    with pytest.raises(ValueError, match="unknown FLIP mode"):
        M.flip(truth, truth, mode="sdr")


def test_temporal_instability_known_values():
    a = np.zeros((3, 4, 3), np.float32)
    b = np.ones((3, 4, 3), np.float32)
    assert M.temporal_instability([a, a, a]) == [0.0, 0.0]
    assert M.temporal_instability([a, b, a]) == pytest.approx([1.0, 1.0])
    assert M.temporal_instability([a, 0.5 * b], exposure=None) == [0.5]
    assert M.temporal_instability([a]) == []


def test_lag_frames():
    assert M.lag_frames([5, 4, 3, 1, 0.5], 2.0) == 3
    assert M.lag_frames([1, 4, 3], 2.0) == 0
    assert M.lag_frames([5, 4, 3], 2.0) is None
    assert M.lag_frames([5, 4, 3], [6, 1, 1]) == 0
    assert M.lag_frames([5, 4, 3], [1, 1, 3]) == 2
    assert M.lag_frames([float("nan"), 1.0], 2.0) == 1
    with pytest.raises(ValueError, match="2 thresholds for 3 errors"):
        M.lag_frames([5, 4, 3], [1, 2])


def test_change_and_disocclusion_masks():
    before = np.ones((2, 3, 3), np.float32)
    after = before.copy()
    after[0, 1] = 0.5
    after[1, 2] = 1.05  # a 5 % change: under the 10 % threshold
    assert M.change_mask(before, after).tolist() == [[False, True, False], [False, False, False]]
    prev = np.array([[1, 1, 2, 2], [1, 1, 2, 2]], np.int32)
    cur = np.array([[1, 2, 2, 3], [1, 1, 2, 2]], np.int32)
    motion = np.zeros((2, 4, 2), np.float32)
    motion[0, 1, 0] = 1.0  # pixel (0, 1) was at (0, 2) in the previous frame: prim 2 there, seen
    motion[1, 0, 0] = -1.0  # was left of the screen: disoccluded
    motion[1, 3] = 1.0e6  # behind the previous camera (the offscreen marker)
    mask = M.disocclusion_mask(prev, cur, motion)
    assert mask.tolist() == [[False, False, False, True], [True, False, False, True]]


# -- references ---------------------------------------------------------------------------------------

def test_references_are_cached_by_scene_camera_size_and_spp(tmp_path, device, cornell_box):
    refs = R.ReferenceRenderer(cornell_box, "cornell-box", 12, 8, 4, device=device, folder=tmp_path)
    a = refs.render()
    assert a.shape == (8, 12, 3) and a.dtype == np.float32 and refs.misses == 1
    direct = pyclpt.Renderer(cornell_box, width=12, height=8, device=device).render(4, seed=R.SEED)
    np.testing.assert_array_equal(a, direct)
    again = R.ReferenceRenderer(cornell_box, "cornell-box", 12, 8, 4, device=device, folder=tmp_path)
    np.testing.assert_array_equal(again.render(), a)
    assert again.hits == 1 and again.misses == 0
    moved = copy.copy(cornell_box.camera)
    moved.to_world = np.array(moved.to_world, np.float64)
    moved.to_world[0, 3] += 0.1
    b = again.render(moved)
    assert again.misses == 1 and not np.array_equal(a, b)
    np.testing.assert_array_equal(again.render(), a)  # the default view is still the scene's camera
    keys = {R.reference_key(cornell_box, 12, 8, 4), R.reference_key(cornell_box, 12, 8, 8),
            R.reference_key(cornell_box, 8, 12, 4), R.reference_key(cornell_box, 12, 8, 4, camera=moved)}
    assert len(keys) == 4
    names = sorted(p.name for p in tmp_path.iterdir())
    assert len(names) == 4 and all(n.startswith("cornell-box-12x8-4spp-") for n in names)
    meta = json.loads(next(tmp_path.glob("*.json")).read_text())
    assert meta["spp"] == 4 and meta["width"] == 12 and len(meta["camera"]["to_world"]) == 4


# -- the evaluation's helpers ---------------------------------------------------------------------------

def test_quality_size_and_scene_edits(cornell_box):
    assert E.quality_size(cornell_box, "auto") == (120, 120)
    wide = copy.copy(cornell_box)
    wide.film = pyclpt.Film(1280, 720)
    assert E.quality_size(wide, "auto") == (160, 90)
    assert E.quality_size(cornell_box, "64x48") == (64, 48)
    sc = E.clone_scene(cornell_box)
    light = next(i for i, m in enumerate(sc.meshes) if m.emission is not None)
    before = tuple(cornell_box.meshes[light].emission)
    assert E.scale_emitters(sc, 0.25) == 1
    assert sc.meshes[light].emission == pytest.approx(tuple(0.25 * c for c in before))
    assert tuple(cornell_box.meshes[light].emission) == before  # the original is untouched
    E.scale_emitters(sc, 0.0)
    assert sc.meshes[light].emission is None
    env = E.clone_scene(cornell_box)
    env.environment = (1.0, 2.0, 3.0)
    env.lights = [pyclpt.PointLight((0, 1, 0), (4.0, 4.0, 4.0))]
    assert E.scale_emitters(env, 0.5) == 3
    assert env.environment == (0.5, 1.0, 1.5) and env.lights[0].intensity == (2.0, 2.0, 2.0)
    assert cornell_box.lights == []


def test_auto_exposure_brings_the_median_to_middle_grey():
    img = np.full((10, 10, 3), 0.09, np.float32)
    img[:3] = 100.0  # bright windows: not the median
    assert E.auto_exposure(img) == pytest.approx(1.0, abs=1e-5)
    assert E.auto_exposure(np.zeros((4, 4, 3), np.float32)) == 0.0


class FakeProfile:
    def __init__(self) -> None:
        self.frames = 0

    def clear(self) -> None:
        self.frames = 0

    def table(self) -> list[dict]:
        return [{"kernel": "fake", "launches": self.frames, "total_ms": 0.5 * self.frames, "mean_ms": 0.5}]


class FakeProgressiveRenderer:
    """The ProgressiveRenderer interface the evaluation drives, on numpy: the "scene" is a gradient
    scaled by the emission and shifted by the camera; "blend"/"svgf" are moving averages of the frames
    that keep their history across changes, as the real denoisers do."""

    def __init__(self, scene, *, seed, width, height, device, integrator, denoiser=None, aovs=None,
                 camera_path=None) -> None:
        self.scene, self.w, self.h = scene, width, height
        self.denoiser_mode, self.camera_path = denoiser, camera_path
        self.rng = np.random.default_rng(seed)
        self.renderer = SimpleNamespace(integrator=SimpleNamespace(profile=FakeProfile()))
        self.denoiser = SimpleNamespace(profile=FakeProfile()) if denoiser else None
        self.frame_index = 0
        self._sum = np.zeros((height, width, 3))
        self._n = 0
        self._history = None
        self._state = self._key()

    def _key(self):
        return (tuple(tuple(m.emission) if m.emission is not None else None for m in self.scene.meshes),
                float(self.scene.camera.to_world[0, 3]))

    def sync(self) -> None:
        if self._key() != self._state:
            self._state = self._key()
            self._sum[:] = 0
            self._n = 0

    def set_emission(self, i, value) -> None:
        self.scene.meshes[i].emission = value
        self.sync()

    def step(self) -> None:
        if self.camera_path is not None:
            self.scene.camera = self.camera_path.camera(self.frame_index)
        self.sync()
        truth = fake_truth(self.scene, self.w, self.h)
        self._frame = (truth * self.rng.exponential(1.0, truth.shape)).astype(np.float32)
        self._sum += self._frame
        self._n += 1
        if self.denoiser is not None:
            a = 0.5 if self.denoiser_mode == "blend" else 0.3
            smooth = 0.5 * (self._frame + np.roll(self._frame, 1, axis=1))
            self._history = smooth if self._history is None else (1 - a) * self._history + a * smooth
            self.denoiser.profile.frames += 1
        self.renderer.integrator.profile.frames += 1
        self.frame_index += 1

    def frame_image(self):
        return self._frame

    def image(self):
        return (self._sum / max(self._n, 1)).astype(np.float32)

    def denoised(self):
        return self._history.astype(np.float32)

    def aovs(self, names):
        shift = int(round(40 * float(self.scene.camera.to_world[0, 3])))
        ids = (np.arange(self.w)[None, :] + shift > self.w // 2).astype(np.int32) * np.ones((self.h, 1), np.int32)
        out = {"albedo": np.full((self.h, self.w, 3), 0.7, np.float32),
               "normal": np.zeros((self.h, self.w, 3), np.float32), "mesh_id": ids,
               "motion": np.zeros((self.h, self.w, 2), np.float32)}
        return {n: out[n] for n in names}


def fake_truth(scene, w, h):
    emission = sum(sum(m.emission) for m in scene.meshes if m.emission is not None) / 39.128
    x = np.arange(w)[None, :, None] / w + float(scene.camera.to_world[0, 3])
    return (emission * (0.2 + 0.8 * np.abs(np.sin(3 * x))) * np.ones((h, 1, 3))).astype(np.float32)


class FakeReferences:
    def __init__(self, scene, label, w, h) -> None:
        self.scene, self.w, self.h, self.hits, self.misses, self.seconds, self.files = scene, w, h, 0, 1, 0.0, []
        self.camera = scene.camera

    def render(self, camera=None):
        sc = copy.copy(self.scene)
        sc.camera = self.camera if camera is None else camera
        return fake_truth(sc, self.w, self.h)


def _fake_settings(tmp_path, **over) -> dict:
    a = E.build_parser().parse_args(["--scenes", "cornell-box", "--frames", "4", "--image-frame", "2",
                                      "--size", "24x16", "--after", "3", "--orbit-ref-every", "2",
                                      "--timing-size", "24x16", "--timing-frames", "2", "--timing-warmup", "1",
                                      "--arrays", str(tmp_path / "arr")])
    s = E.settings_from(a)
    s.update(over)
    return s


@needs_oidn
@needs_skimage
@needs_flip
def test_evaluation_runs_on_a_fake_renderer_and_writes_the_report(tmp_path, device):
    s = _fake_settings(tmp_path)
    out = tmp_path / "out"
    res = E.run(s, out, factory=FakeProgressiveRenderer, device=device, log=lambda m: None,
                references=lambda sc, label: FakeReferences(sc, label, 24, 16))
    E.write_report(res, out)
    sc = res["scenes"][0]
    assert sc["scene"] == "cornell-box" and (sc["width"], sc["height"]) == (24, 16) and not sc["errors"]
    for m in E.MODES:
        met = sc["static"]["metrics"][m]
        assert len(met["relmse"]) == len(met["ssim"]) == len(met["flip"]) == 4
        assert all(np.isfinite(met["relmse"])) and all(0 < v <= 1 for v in met["ssim"])
        assert len(sc["static"]["instability"][m]) == 3
        assert len(sc["light"]["region"][m]) == len(sc["light"]["baseline"][m]) == 3
        assert len(sc["orbit"]["metrics"][m]["relmse"]) == 2  # frames 2 and 4
        assert len(sc["orbit"]["region"][m]) == 4 and len(sc["orbit"]["baseline"][m]) == 4
    # the plain average restarts with the change, as its fresh baseline does: no lag by construction
    assert sc["light"]["lag"]["none"] == 0 and sc["light"]["lag"]["oidn"] == 0
    assert sc["light"]["region"]["none"] == pytest.approx(sc["light"]["baseline"]["none"], rel=1.0)
    assert sc["light"]["region_pixels"] == 24 * 16 and sc["light"]["emitters"] == 1
    assert sc["orbit"]["ref_frames"] == [2, 4] and sc["orbit"]["region_pixels"] > 0
    # the fake moving averages carry the old light into the new frames: they lag
    assert sc["light"]["region"]["svgf"][0] > 2 * sc["light"]["baseline"]["svgf"][0]
    t = res["timing"][0]
    assert set(t["modes"]) == {"none", "blend", "svgf", "oidn"} and not t["errors"]
    assert t["modes"]["svgf"]["denoise_ms"] == pytest.approx(0.5)
    assert t["modes"]["svgf"]["share_of_render"] == pytest.approx(1.0)
    saved = json.loads((out / "results.json").read_text())
    assert saved["meta"]["cpu"] and saved["settings"]["frames"] == 4
    report = (out / "report.md").read_text()
    for heading in ("## Goals", "## Static camera, frame 2", "## Lag after a change", "## Orbit", "## Cost per frame",
                    "## Images"):
        assert heading in report
    assert saved["meta"]["cpu"] in report
    for name in ("cornell-box_static.png", "cornell-box_orbit.png", "cornell-box_curves.png"):
        assert (out / name).read_bytes()[:4] == b"\x89PNG", name
    # the report can be rewritten from the JSON alone
    (out / "report.md").unlink()
    assert E.main(["--from-json", str(out / "results.json")]) == 0
    assert (out / "report.md").read_text() == report


def test_a_failing_mode_is_recorded_and_the_others_go_on(tmp_path, device):
    class Broken(FakeProgressiveRenderer):
        def denoised(self):
            raise RuntimeError("no svgf here")

    s = _fake_settings(tmp_path, modes=["none", "svgf"], timing_scenes=[])
    s["flip"] = "ldr"
    metrics_ok = _has("skimage") and _has("flip_evaluator")
    if not metrics_ok:
        pytest.skip("scikit-image and flip-evaluator (optional extra [bench]) are needed for the metrics")
    res = E.run(s, tmp_path / "out", factory=Broken, device=device, log=lambda m: None,
                references=lambda sc, label: FakeReferences(sc, label, 24, 16))
    sc = res["scenes"][0]
    assert "no svgf here" in sc["errors"]["svgf"]
    assert len(sc["static"]["metrics"]["none"]["relmse"]) == 4
    assert "svgf" not in sc["light"]["lag"]
    assert "failed" in E.markdown(res)


def test_settings_and_command_line_checks():
    s = E.settings_from(E.build_parser().parse_args([]))
    assert s["ref_spp"] >= 4096 and s["frames"] == 16 and s["image_frame"] == 8 and s["modes"] == list(E.MODES)
    assert s["timing_size"] == "1280x720" and s["timing_scenes"] == s["scenes"]
    with pytest.raises(ValueError, match="past the last frame"):
        E.settings_from(E.build_parser().parse_args(["--frames", "4"]))
    with pytest.raises(SystemExit):
        E.build_parser().parse_args(["--size", "12"])
    assert E.settings_from(E.build_parser().parse_args(["--no-timing"]))["timing_scenes"] == []


def test_missing_optional_packages_are_named(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "flip_evaluator", None)
    monkeypatch.setitem(sys.modules, "pyoidn", None)
    assert E.missing_packages(["none", "oidn"])[-2:] == ["flip-evaluator", "pyoidn"]
    assert E.main(["--out", "never-written"]) == 2
    err = capsys.readouterr().err
    assert "flip-evaluator" in err and "pip install 'pyclpt[bench,oidn]'" in err and "--modes none blend svgf" in err
    assert "pyoidn" not in E.missing_packages(["none", "svgf"])


@pytest.mark.slow
@needs_oidn
@needs_skimage
@needs_flip
def test_evaluation_end_to_end_on_the_renderer(tmp_path, device):
    """The real ProgressiveRenderer and its denoisers, tiny: every mode runs, every figure is there."""
    s = _fake_settings(tmp_path, size="16x16", ref_spp=16, frames=3, image_frame=2, after=2,
                       timing_size="16x16", timing_frames=1)
    s["reference_cache"] = str(tmp_path / "refs")
    out = tmp_path / "out"
    res = E.run(s, out, device=device, log=lambda m: None)
    E.write_report(res, out)
    sc = res["scenes"][0]
    assert not sc["errors"], sc["errors"]
    assert not res["timing"][0]["errors"], res["timing"][0]["errors"]
    for m in E.MODES:
        assert len(sc["static"]["metrics"][m]["relmse"]) == 3
        assert all(np.isfinite(sc["static"]["metrics"][m]["relmse"]))
    assert sc["light"]["lag"]["none"] == 0  # the plain average restarts with the light change
    assert len(list((tmp_path / "refs").glob("*.npy"))) == 1 + 2  # static, orbit frames 2 and 3
    assert res["timing"][0]["modes"]["svgf"]["passes"]
