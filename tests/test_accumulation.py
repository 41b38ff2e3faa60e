"""The accumulator (precisions, overflow modes, input types, HDR guard) and progressive rendering
(sample order, auto-reset), plus the command line's accumulation options."""
from __future__ import annotations

import dataclasses
import json
import logging

import numpy as np
import pyopencl as cl
import pytest

import pyclpt
from pyclpt.cli import main
from pyclpt.device.program import build_program
from pyclpt.film.accumulator import UNSAFE_MATH_OPTIONS, Accumulator, AccumulatorError

MODES = [("single", False), ("compensated", False), ("double", False), ("double", True)]
MODE_IDS = ["single", "compensated", "double", "double-float"]


def make(device, w=4, h=3, *, emulated=False, **kw) -> Accumulator:
    return Accumulator(device, w, h, force_emulated_double=emulated, **kw)


# -- precision over 10^6 frames ------------------------------------------------------------------

def test_precision_million_frames(device):
    """10^6 frames of 4x4 RGBA: pixels of 0.1 + noise, a constant 0.1 pixel and a constant 1/3 pixel
    (the float drift of mitsuba2 issue 82). Each mode's mean against the exact mean of the float
    inputs (an int64 sum of the values scaled by 2^40, which is exact for these values)."""
    W = H = 4
    C, N, B = 4, 10**6, 8192
    accs = [make(device, W, H, channels=C, precision=p, emulated=e) for p, e in MODES]
    assert [a.implementation for a in accs] == MODE_IDS
    rng = np.random.default_rng(20240513)
    exact = np.zeros((H, W, C), np.int64)
    staging = cl.Buffer(device.context, cl.mem_flags.READ_ONLY, size=B * W * H * C * 4)
    done = 0
    while done < N:
        b = min(B, N - done)
        fr = np.float32(0.1) + np.float32(0.01) * rng.standard_normal((b, H, W, C), dtype=np.float32)
        fr[:, 0, 0, :] = np.float32(0.1)
        fr[:, 0, 1, :] = np.float32(1 / 3)
        fr = np.clip(fr, np.float32(0.01), np.float32(1.0))
        scaled = fr.astype(np.float64) * 2.0**40
        assert np.all(scaled == np.rint(scaled))  # every value is a multiple of 2^-40: the int sum is exact
        exact += scaled.astype(np.int64).sum(0)
        cl.enqueue_copy(device.queue, staging, fr)
        for a in accs:
            a.add_batch(staging, b)
        done += b
    ref = exact.astype(np.float64) / 2.0**40 / N
    errors = {}
    for name, a in zip(MODE_IDS, accs):
        assert a.frame_count == N
        rel64 = np.abs(a.image(np.float64) / ref - 1.0)  # the sum as kept, read in float64
        rel32 = np.abs(a.image().astype(np.float64) / ref - 1.0)  # the float32 image from the device
        errors[name] = (rel64.max(), rel32.max(), rel64[0, 0].max(), rel64[0, 1].max())
        print(f"{name:12s} max rel error: as kept {rel64.max():.3e}, float image {rel32.max():.3e}, "
              f"constant 0.1 {rel64[0, 0].max():.3e}, constant 1/3 {rel64[0, 1].max():.3e}, "
              f"noisy pixels {rel64[1:].max():.3e}")
    eps = 2.0**-24  # float's unit roundoff
    single, comp = errors["single"], errors["compensated"]
    assert single[2] > 1e-3  # single drifts: the constant 0.1 pixel is off by far more than float precision
    assert comp[0] < 4 * eps  # compensated stays near float epsilon...
    assert comp[1] < 2 * eps  # ...and its float image is the reference rounded to float (or next to it)
    assert single[0] > 1000 * comp[0]  # compensation is not optimised away: it beats single measurably
    assert errors["double"][0] < 1e-12
    assert errors["double-float"][0] < 1e-12
    for name in ("double", "double-float"):
        assert errors[name][1] < 2 * eps


def test_compensated_is_built_without_unsafe_math_and_survives_fast_math(device):
    acc = make(device, precision="compensated")
    assert not set(acc.build_options) & set(UNSAFE_MATH_OPTIONS)
    assert "-DACC_PRECISION=1" in acc.build_options
    # The Kahan guard (an XOR with a kernel argument that is 0) keeps the correction even where
    # fast math would let LLVM fold it to 0.
    n, value = 100000, np.float32(0.1)
    frames = cl.Buffer(device.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                       hostbuf=np.full(n, value, np.float32))
    prog = build_program(device, ["film/accumulate.cl"], options=["-cl-fast-relaxed-math"],
                         defines={"ACC_PRECISION": 1, "ACC_INPUT": 0, "ACC_CHANNELS": 1})
    state = cl.Buffer(device.context, cl.mem_flags.READ_WRITE, size=8)
    counters = cl.Buffer(device.context, cl.mem_flags.READ_WRITE, size=8)
    cl.enqueue_fill_buffer(device.queue, state, np.uint32(0), 0, 8)
    cl.Kernel(prog, "accumulate_batch")(device.queue, (16, 16), (16, 16), state, frames, np.int32(1), np.int32(1),
                                  np.uint64(0), np.uint64(1), np.int32(n), np.uint32(0), np.uint32(0), np.uint32(0),
                                  counters)
    out = np.empty(2, np.float32)
    cl.enqueue_copy(device.queue, out, state)
    s, c = out
    assert c != 0.0
    assert abs((float(s) - float(c)) / (n * float(value)) - 1.0) < 1e-7


# -- batch = sequence, overflow modes --------------------------------------------------------------

@pytest.mark.parametrize("precision,emulated", MODES, ids=MODE_IDS)
@pytest.mark.parametrize("overflow,max_frames", [("stop", 0), ("ema", 5), ("reset", 4), ("stop", 7)])
def test_batch_equals_sequential_adds(device, precision, emulated, overflow, max_frames):
    rng = np.random.default_rng(1)
    frames = rng.random((13, 3, 4, 3)).astype(np.float32) * np.float32(10)
    kw = dict(precision=precision, emulated=emulated, overflow=overflow, max_frame_count=max_frames)
    one, batch = make(device, **kw), make(device, **kw)
    for f in frames:
        one.add(f)
    batch.add_batch(frames)
    assert one.frame_count == batch.frame_count
    assert np.array_equal(one.sum(), batch.sum())
    assert np.array_equal(one.image(), batch.image())
    assert one.ignored_frames == batch.ignored_frames


@pytest.mark.parametrize("precision,emulated", MODES, ids=MODE_IDS)
def test_overflow_modes_at_max_frame_count(device, precision, emulated):
    values = np.arange(1, 8, dtype=np.float32)  # frames of a constant 1, 2, ..., 7
    frames = np.broadcast_to(values[:, None, None, None], (7, 3, 4, 3)).astype(np.float32)

    def run(overflow):
        a = make(device, precision=precision, emulated=emulated, max_frame_count=4, overflow=overflow)
        for f in frames:
            a.add(f)
        return a

    stop = run("stop")
    assert stop.frame_count == 4 and stop.stopped and stop.ignored_frames == 3
    np.testing.assert_allclose(stop.image(), 2.5, rtol=1e-6)  # mean of 1..4, kept

    reset = run("reset")
    assert reset.frame_count == 3 and not reset.stopped  # 5, 6, 7 after starting over at frame 5
    np.testing.assert_allclose(reset.image(), 6.0, rtol=1e-6)

    ema = run("ema")
    expected = 0.0
    for n, v in enumerate(values, start=1):
        expected += (v - expected) / min(n, 4)  # weight 1 / min(n, max)
    assert ema.frame_count == 7 and ema.divisor == 4
    np.testing.assert_allclose(ema.image(), expected, rtol=1e-6)
    np.testing.assert_allclose(ema.image(np.float64), expected, rtol=1e-6 if precision == "single" else 1e-12)


def test_ema_stays_bounded_where_a_sum_would_overflow(device):
    big = np.full((3, 4, 3), 2e38, np.float32)
    ema = make(device, precision="single", max_frame_count=1, overflow="ema")
    for _ in range(5):
        ema.add(big)
    assert ema.overflowed_samples == 0
    np.testing.assert_allclose(ema.image(), 2e38, rtol=1e-6)


def test_explicit_reset_and_disabled(device):
    a = make(device, precision="double")
    a.add(np.full((3, 4, 3), 2.0, np.float32))
    a.reset()
    assert a.frame_count == 0
    assert np.all(a.image() == 0)
    a.add(np.full((3, 4, 3), 5.0, np.float32))
    assert a.frame_count == 1 and np.all(a.image() == 5.0)

    off = make(device, enabled=False)
    for v in (1.0, 7.0, 3.0):
        off.add(np.full((3, 4, 3), v, np.float32))
    assert off.frame_count == 1 and np.all(off.image() == 3.0)  # the last frame, passed through
    off.configure(enabled=True)
    off.add(np.full((3, 4, 3), 1.0, np.float32))
    off.add(np.full((3, 4, 3), 2.0, np.float32))
    assert np.all(off.image() == 1.5)


# -- work-groups, input formats -------------------------------------------------------------------

@pytest.mark.parametrize("local_size", [None, (16, 16), (8, 8), (32, 4), (256, 1)])
def test_sizes_that_are_not_multiples_of_the_work_group(device, local_size):
    frames = np.random.default_rng(2).random((3, 7, 13, 4)).astype(np.float32)
    a = Accumulator(device, 13, 7, channels=4, precision="double", local_size=local_size)
    a.add_batch(frames)
    np.testing.assert_allclose(a.image(), frames.astype(np.float64).mean(0), rtol=1e-6)


@pytest.mark.parametrize("precision,emulated", MODES, ids=MODE_IDS)
def test_uint_frames(device, precision, emulated):
    rng = np.random.default_rng(3)
    frames = rng.integers(0, 2**32 - 1, size=(6, 2, 3, 4), dtype=np.uint64).astype(np.uint32)
    frames[:, 0, 0, :] = 2**32 - 1  # the largest value, not exact in float
    a = Accumulator(device, 3, 2, channels=4, input_type="uint", precision=precision,
                    force_emulated_double=emulated)
    a.add_batch(frames)
    exact = frames.astype(np.float64).mean(0)  # sums below 2^53: exact in float64
    got = a.image(np.float64)
    if precision == "double":  # native double and double-float both take 32-bit integers exactly
        np.testing.assert_array_equal(got * 6, exact * 6)
    else:
        np.testing.assert_allclose(got, exact, rtol=3e-7)
    np.testing.assert_allclose(a.image(), exact, rtol=1e-7)


def test_int_frames_and_small_integer_arrays(device):
    frames = np.array([-5, 3, 9, -1], np.int32)[:, None, None, None] * np.ones((1, 2, 2, 1), np.int32)
    a = Accumulator(device, 2, 2, channels=1, input_type="int", precision="double")
    a.add_batch(frames)
    assert np.all(a.image() == 1.5)
    u8 = Accumulator(device, 2, 2, channels=4, input_type="uint", precision="single")
    u8.add(np.full((2, 2, 4), 255, np.uint8))  # safely cast up to uint32
    assert np.all(u8.image() == 255.0)


def test_rgba_float_frames(device):
    frames = np.random.default_rng(4).random((5, 6, 5, 4)).astype(np.float32)
    a = Accumulator(device, 5, 6, channels=4, precision="compensated")
    for f in frames:
        a.add(f)
    np.testing.assert_allclose(a.image(), frames.astype(np.float64).mean(0), rtol=2e-7)


# -- HDR guard ------------------------------------------------------------------------------------

@pytest.mark.parametrize("precision,emulated", MODES, ids=MODE_IDS)
def test_nan_and_inf_are_skipped_and_counted(device, precision, emulated):
    frames = np.ones((4, 3, 4, 3), np.float32)
    frames[1, 0, 0, 1] = np.nan
    frames[2, 1, 2, 0] = np.inf
    frames[3, 1, 2, 2] = -np.inf
    a = make(device, precision=precision, emulated=emulated)
    a.add_batch(frames)
    img = a.image()
    assert np.isfinite(img).all()
    assert a.skipped_samples == 3
    assert np.all(img[0, 0] == 0.75)  # a skipped pixel sample counts as zero, like a dropped path sample
    assert np.all(img[1, 2] == 0.5)
    mask = np.ones((3, 4), bool)
    mask[0, 0] = mask[1, 2] = False
    assert np.all(img[mask] == 1.0)


def test_single_sum_overflow_is_detected_and_reported(device, caplog):
    big = np.full((3, 4, 3), 3e38, np.float32)
    single = make(device, precision="single")
    with caplog.at_level(logging.WARNING, logger="pyclpt.film.accumulator"):
        for _ in range(3):
            single.add(big)
        img = single.image()
    assert np.isfinite(img).all()
    assert single.overflowed_samples == 2 * 12  # frames 2 and 3 of every pixel
    assert "overflow" in caplog.text and "single" in caplog.text
    double = make(device, precision="double")
    for _ in range(3):
        double.add(big)
    assert double.overflowed_samples == 0
    np.testing.assert_allclose(double.image(), 3e38, rtol=1e-7)


# -- options --------------------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, needle", [
    (dict(precision="quad"), "'quad'"),
    (dict(overflow="wrap"), "'wrap'"),
    (dict(input_type="half"), "'half'"),
    (dict(channels=5), "got 5"),
    (dict(channels=0), "got 0"),
    (dict(max_frame_count=-1), "got -1"),
    (dict(overflow="ema"), "max_frame_count=0 means unlimited"),
    (dict(overflow="reset", max_frame_count=0), "never act"),
    (dict(enabled=False, max_frame_count=8), "passes each frame through"),
    (dict(local_size=(0, 16)), "0x16"),
])
def test_refused_options(device, kwargs, needle):
    with pytest.raises(AccumulatorError, match=None) as info:
        make(device, **kwargs)
    assert needle in str(info.value)
    too_big = device.device.max_work_group_size
    with pytest.raises(AccumulatorError, match=f"{too_big}x2 is not possible"):
        make(device, local_size=(too_big, 2))


def test_refused_frames(device):
    a = make(device, input_type="uint")
    with pytest.raises(AccumulatorError, match="float32 .*input_type='uint'|dtype float32"):
        a.add(np.zeros((3, 4, 3), np.float32))
    with pytest.raises(AccumulatorError, match=r"shape \(4, 3, 3\)"):
        a.add(np.zeros((4, 3, 3), np.uint32))
    with pytest.raises(AccumulatorError, match="outside the range"):
        a.add(np.full((3, 4, 3), 2**33, np.uint64))
    small = cl.Buffer(device.context, cl.mem_flags.READ_ONLY, size=16)
    with pytest.raises(AccumulatorError, match="holds 16 bytes"):
        a.add(small)
    with pytest.raises(AccumulatorError, match="unknown accumulator option"):
        a.configure(precison="double")
    with pytest.raises(AccumulatorError, match="never act"):
        a.configure(overflow="ema")
    assert a.overflow == "stop"  # a refused change leaves the options as they were


def test_forced_emulated_double(device, monkeypatch):
    a = make(device, precision="double", emulated=True)
    assert a.implementation == "double-float" and a.emulated_double
    assert "-DACC_PRECISION=3" in a.build_options
    monkeypatch.setenv("PYCLPT_EMULATE_FP64", "1")
    b = make(device, precision="double", emulated=None)
    assert b.implementation == "double-float"
    monkeypatch.setenv("PYCLPT_EMULATE_FP64", "0")
    assert make(device, precision="double", emulated=None).implementation == (
        "double" if device.has_fp64 else "double-float")
    # a value a float sum loses entirely: 1 + 1e-8 + 1e-8 ...
    frames = np.full((101, 3, 4, 3), 1e-8, np.float32)
    frames[0] = 1.0
    a.add_batch(frames)
    exact = (1.0 + 100 * float(np.float32(1e-8))) / 101
    np.testing.assert_allclose(a.image(np.float64), exact, rtol=1e-13)


# -- progressive rendering ------------------------------------------------------------------------

SIZE = dict(width=16, height=16, max_depth=3)


@pytest.mark.parametrize("precision", ["single", "double"])
def test_progressive_equals_one_shot(cornell_box, precision):
    pr = pyclpt.ProgressiveRenderer(cornell_box, seed=9, precision=precision, **SIZE)
    for k in range(5):
        assert pr.sample_index == k
        assert pr.step() == 1
    one_shot = pyclpt.Renderer(cornell_box, precision=precision, **SIZE).render(5, seed=9, progress=False)
    assert np.array_equal(pr.image(), one_shot)
    assert pr.reset_count == 0


def test_new_frames_jitter_but_never_reset(cornell_box):
    pr = pyclpt.ProgressiveRenderer(cornell_box, seed=1, **SIZE)
    frames = []
    for _ in range(3):
        pr.step()
        frames.append(pr.renderer.film.read_frame())
    assert pr.reset_count == 0 and pr.frame_count == 3 and pr.sample_index == 3
    assert not np.array_equal(frames[0], frames[1])  # each sample jitters the camera ray differently


def _shift():
    m = np.zeros((4, 4))
    m[0, 3] = 0.05
    return m


CHANGES = {
    "camera": lambda pr: pr.set_camera(pyclpt.Camera(pr.scene.camera.to_world + _shift(), pr.scene.camera.fov)),
    "camera-direct": lambda pr: setattr(pr.scene.camera, "fov", pr.scene.camera.fov + 1.0),
    "material": lambda pr: pr.set_material(0, pyclpt.Diffuse((0.2, 0.3, 0.4))),
    "material-direct": lambda pr: setattr(pr.scene.materials[1], "reflectance", (0.3, 0.3, 0.3)),
    "emitter": lambda pr: pr.set_emission(_light(pr.scene), (5.0, 5.0, 5.0)),
    "emitter-direct": lambda pr: setattr(pr.scene, "environment", (0.1, 0.1, 0.1)),
    "geometry": lambda pr: pr.set_meshes([dataclasses.replace(m, positions=m.positions + 0.01)
                                          if m.name == "small-box" else m for m in pr.scene.meshes]),
    "geometry-direct": lambda pr: pr.scene.meshes[0].positions.__setitem__((0, 1), 0.25),
    "resolution": lambda pr: pr.set_resolution(12, 10),
}


def _light(scene) -> int:
    return next(i for i, m in enumerate(scene.meshes) if m.emission is not None)


@pytest.mark.parametrize("change", list(CHANGES))
def test_auto_reset_on_scene_change(change):
    scene = pyclpt.load("cornell-box")  # a private copy: the changes mutate it
    pr = pyclpt.ProgressiveRenderer(scene, seed=2, **SIZE)
    pr.step(3)
    CHANGES[change](pr)
    pr.step(2)  # direct mutations are found by the fingerprint before the next frame
    kind = change.split("-")[0]
    assert pr.reset_count == 1 and pr.last_reset_reason == kind
    assert pr.frame_count == 2 and pr.sample_index == 2
    # the accumulation restarted from sample 0 of the changed scene
    w, h = (12, 10) if kind == "resolution" else (16, 16)
    fresh = pyclpt.Renderer(scene, width=w, height=h, max_depth=3).render(2, seed=2, progress=False)
    assert np.array_equal(pr.image(), fresh)


def test_auto_reset_off_keeps_accumulating(cornell_box):
    scene = pyclpt.load("cornell-box")
    pr = pyclpt.ProgressiveRenderer(scene, seed=2, auto_reset=False, **SIZE)
    pr.step(2)
    pr.set_material(0, pyclpt.Diffuse((0.9, 0.1, 0.1)))
    pr.step(2)
    assert pr.reset_count == 0 and pr.frame_count == 4 and pr.sample_index == 4
    pr.set_resolution(8, 8)  # buffers change size: this always resets
    assert pr.reset_count == 1 and pr.frame_count == 0


def test_explicit_reset_restarts_at_sample_zero(cornell_box):
    pr = pyclpt.ProgressiveRenderer(cornell_box, seed=4, **SIZE)
    pr.step(3)
    first = pr.image()
    pr.reset()
    assert pr.frame_count == 0 and pr.sample_index == 0 and pr.last_reset_reason == "explicit"
    pr.step(3)
    assert np.array_equal(pr.image(), first)


def test_progressive_max_frames(cornell_box):
    stop = pyclpt.ProgressiveRenderer(cornell_box, seed=6, max_frame_count=3, **SIZE)
    assert stop.step(5) == 3  # no frame is rendered once the accumulation has stopped
    assert stop.frame_count == 3 and stop.accumulator.ignored_frames == 2
    ref = pyclpt.Renderer(cornell_box, **SIZE)
    assert np.array_equal(stop.image(), ref.render(3, seed=6, progress=False))
    # reset: the sample index goes on, so the second round averages new samples
    again = pyclpt.ProgressiveRenderer(cornell_box, seed=6, max_frame_count=3, overflow="reset", **SIZE)
    assert again.step(6) == 6
    assert again.frame_count == 3 and again.sample_index == 6
    assert np.array_equal(again.image(), ref.render(3, seed=6, first_sample=3, progress=False))


def test_setters_refuse_bad_values(cornell_box):
    pr = pyclpt.ProgressiveRenderer(cornell_box, **SIZE)
    with pytest.raises(IndexError, match="material index 99"):
        pr.set_material(99, pyclpt.Diffuse())
    with pytest.raises(KeyError, match="no mesh named 'nope'"):
        pr.set_emission("nope", 1.0)
    with pytest.raises(ValueError, match="width must be an integer in 1..65536, got 0"):
        pr.set_resolution(0, 8)
    with pytest.raises(TypeError, match="Camera"):
        pr.set_camera("front")
    with pytest.raises(AccumulatorError, match="never act"):
        pyclpt.ProgressiveRenderer(cornell_box, overflow="ema", **SIZE)
    assert pr.reset_count == 0


def test_renderer_accumulates_in_double_by_default(cornell_box):
    r = pyclpt.Renderer(cornell_box, **SIZE)
    r.render(2, progress=False)
    assert r.stats.accumulation["precision"] == "double"
    assert r.stats.accumulation["frame_count"] == 2


# -- command line ---------------------------------------------------------------------------------

def test_cli_accumulation_options(tmp_path, capsys):
    out = tmp_path / "a.exr"
    rc = main(["render", "cornell-box", "--frames", "5", "--precision", "compensated", "--max-frames", "3",
               "--overflow", "ema", "--width", "8", "--height", "8", "--max-depth", "2", "-o", str(out),
               "--stats-json", str(tmp_path / "a.json"), "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0
    lines = text.splitlines()
    assert lines == [line for line in lines if line.startswith(f"{out}: ")]  # one line says it all
    assert lines[0].startswith(f"{out}: 8x8, 5 frames rendered, the image their exponential moving average over a "
                               f"window of 3 frames (--overflow ema), max depth 2")
    stats = json.loads((tmp_path / "a.json").read_text())
    acc = stats["accumulation"]
    assert acc["precision"] == "compensated" and acc["frame_count"] == 5 and acc["overflow"] == "ema"
    assert pyclpt.read_image(out).shape == (8, 8, 3)


def test_cli_frames_default_and_stop(tmp_path, capsys):
    out = tmp_path / "b.exr"
    rc = main(["render", "cornell-box", "--spp", "4", "--max-frames", "2", "--width", "8", "--height", "8",
               "--max-depth", "2", "-o", str(out), "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0
    assert ", 2 spp of the 4 asked (--max-frames 2 stopped the accumulation)," in text.splitlines()[0]
    ref = pyclpt.render("cornell-box", spp=2, width=8, height=8, max_depth=2, progress=False)
    np.testing.assert_array_equal(pyclpt.read_image(out), ref)


@pytest.mark.parametrize("args, needle", [
    (["--overflow", "reset"], "--max-frames > 0"),
    (["--frames", "3", "--spp", "4"], "disagree"),
])
def test_cli_refuses_bad_accumulation(tmp_path, capsys, args, needle):
    rc = main(["render", "cornell-box", "-o", str(tmp_path / "x.exr"), *args])
    assert rc == 1
    assert needle in capsys.readouterr().err


@pytest.mark.parametrize("args, needle", [(["--precision", "half"], "'half'"), (["--overflow", "x"], "'x'"),
                                          (["--max-frames", "-1"], "got -1")])
def test_cli_bad_accumulation_values_exit_2(tmp_path, capsys, args, needle):
    with pytest.raises(SystemExit) as info:
        main(["render", "cornell-box", "-o", str(tmp_path / "x.exr"), *args])
    assert info.value.code == 2
    assert needle in capsys.readouterr().err

