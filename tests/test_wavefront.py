"""The wavefront integrator against the megakernel: same estimator, same random numbers,
same image; queues conserve paths; the launch sequence is the design's."""
from __future__ import annotations

import numpy as np
import pytest
from closed_forms import emitter_pixels

import pyclpt
from pyclpt.integrators.path_state import FIELDS, bytes_per_path, opencl_header, record_words
from pyclpt.integrators.wavefront import STAGES
from scenes import interior_furnace, sensor


def render(scene, **kw):
    r = pyclpt.Renderer(scene, **{k: kw.pop(k) for k in list(kw) if k in (
        "integrator", "layout", "max_depth", "width", "height", "wave_size", "device")})
    img = r.render(kw.pop("spp"), seed=kw.pop("seed", 0), progress=False)
    return img, r


def assert_same_image(a, b):
    rel = np.abs(a - b) / np.maximum(np.abs(b), 1e-3)
    assert rel.max() < 1e-4, rel.max()


@pytest.mark.parametrize("max_depth", [1, 3, -1])
def test_wavefront_equals_megakernel_cornell_box(cornell_box, max_depth, each_device):
    """Same estimator (path.h), same random numbers: the same image, on every device (PoCL, Intel's
    CPU runtime). Equality cannot see a bug the two share; the independent checks of both integrators
    are tests/test_analytic.py (closed forms) and, here, the depth-1 image, which ray casting in numpy
    predicts exactly away from the light's edges."""
    kw = dict(spp=16, max_depth=max_depth, width=32, height=32, seed=9, device=each_device)
    mega, _ = render(cornell_box, integrator="megakernel", **dict(kw))
    soa, _ = render(cornell_box, integrator="wavefront", layout="soa", **dict(kw))
    aos, _ = render(cornell_box, integrator="wavefront", layout="aos", **dict(kw))
    assert mega.max() > 0
    assert_same_image(soa, mega)
    assert_same_image(aos, mega)
    # on the same device and compiler they are in fact bit-identical
    assert np.array_equal(soa, mega) and np.array_equal(aos, mega)
    if max_depth == 1:
        expected, certain = emitter_pixels(cornell_box, 32, 32)
        assert certain.sum() > 32 * 32 - 16
        np.testing.assert_allclose(soa[certain], expected[certain], rtol=1e-6)
        le = expected.reshape(-1, 3).max(0)  # at the light's edges: a mix of the light and black
        assert np.all(soa[~certain] <= le * (1 + 1e-6)) and soa[~certain].max() > 0


def test_wavefront_equals_megakernel_cornell_bunny(shared_scenes):
    """Glass, a rough metal floor, a 69k-triangle mesh with shading normals."""
    scene = pyclpt.load("cornell-bunny")
    kw = dict(spp=4, max_depth=16, width=32, height=32, seed=3)
    mega, _ = render(scene, integrator="megakernel", **dict(kw))
    soa, _ = render(scene, integrator="wavefront", layout="soa", **dict(kw))
    aos, _ = render(scene, integrator="wavefront", layout="aos", **dict(kw))
    assert_same_image(soa, mega)
    assert_same_image(aos, mega)


def test_small_waves_give_the_same_image(cornell_box):
    """The wave size bounds the paths in flight; it must not change the image."""
    kw = dict(spp=4, max_depth=-1, width=24, height=20, seed=1)
    whole, r1 = render(cornell_box, integrator="wavefront", **dict(kw))
    chunked, r2 = render(cornell_box, integrator="wavefront", wave_size=100, **dict(kw))
    assert r2.integrator.capacity == 100
    assert np.array_equal(whole, chunked)


def test_repeat_runs_are_bit_identical_despite_atomics(cornell_box):
    kw = dict(spp=4, max_depth=-1, width=32, height=32, seed=5)
    a, _ = render(cornell_box, integrator="wavefront", **dict(kw))
    b, _ = render(cornell_box, integrator="wavefront", **dict(kw))
    assert np.array_equal(a, b)


@pytest.mark.parametrize("schedule", ["readback", "capacity"])
def test_queue_conservation(cornell_box, schedule):
    """Every path ends exactly once; counts add up at every bounce."""
    scene = cornell_box
    r = pyclpt.Renderer(scene, integrator="wavefront", max_depth=-1, width=32, height=32)
    r.integrator.schedule = schedule
    spp = 3
    r.render(spp, seed=2, progress=False)
    rows = r.stats.bounces
    paths = 32 * 32 * spp
    assert rows[0]["rays"] == paths
    ended = 0
    for b, row in enumerate(rows):
        assert row["rays"] == row["hits"] + row["misses"]
        assert row["shadow_rays"] <= row["hits"]
        assert row["unoccluded"] <= row["shadow_rays"]
        nxt = rows[b + 1]["rays"] if b + 1 < len(rows) else 0
        assert nxt <= row["hits"]
        ended += row["misses"] + (row["hits"] - nxt)
    assert ended == paths
    # occupancy falls: roulette and escapes shrink the queues
    assert rows[-1]["rays"] < rows[0]["rays"]


def test_every_pixel_is_committed_once_per_sample(cornell_box):
    """Every path writes its pixel: a frame filled with NaN comes back finite. And exactly once: in a
    scene where every sample overflows to inf, each commit counts one dropped sample, so the dropped
    count equals pixels x spp (a path committed twice or never would change it), in waves too."""
    r = pyclpt.Renderer(cornell_box, integrator="wavefront", max_depth=-1, width=16, height=16)
    r.film.clear()
    import pyopencl as cl

    cl.enqueue_fill_buffer(r.device.queue, r.film.frame, np.float32(np.nan), 0, 4 * 3 * 256)
    r.integrator.render_frame(0, 0)
    frame = r.film.read_frame()
    assert np.isfinite(frame).all()

    # camera inside an emissive sphere of radiance 3e38: emission seen directly plus one light sample
    # already exceeds FLT_MAX, so every path's radiance is inf (or NaN) when it ends, whatever its length
    scene = interior_furnace(0.9, radiance=3.0e38)
    for integrator, wave_size in (("wavefront", None), ("wavefront", 100), ("megakernel", None)):
        kw = {} if wave_size is None else {"wave_size": wave_size}
        r = pyclpt.Renderer(scene, integrator=integrator, max_depth=-1, width=12, height=10, **kw)
        img = r.render(3, seed=1, progress=False)
        assert r.stats.dropped_samples == 12 * 10 * 3, (integrator, wave_size)
        assert np.all(img == 0.0)


def test_no_path_ends_by_roulette_before_rr_depth():
    """Inside a closed diffuse sphere every ray hits and every BSDF sample is valid, so until Russian
    roulette starts (on rays of bounce RR_DEPTH = 3, docs/architecture.md) every path is alive; from
    there on paths end (throughput 0.5^3, so most of them at once)."""
    rr_depth = 3
    r = pyclpt.Renderer(interior_furnace(0.5), integrator="wavefront", max_depth=-1, width=16, height=16)
    r.render(4, seed=3, progress=False)
    rows = r.stats.bounces
    paths = 16 * 16 * 4
    for b in range(rr_depth):
        assert rows[b]["rays"] == rows[b]["hits"] == paths, (b, rows[b])
    assert rows[rr_depth]["rays"] < 0.3 * paths, rows[rr_depth]


def test_launch_sequence_per_bounce(cornell_box):
    r = pyclpt.Renderer(cornell_box, integrator="wavefront", max_depth=3, width=8, height=8)
    r.render(1, progress=False)
    seq = r.integrator.profile.sequence
    per_bounce = ["intersect", "miss", "process_hit", "shadow_test", "light_contribution", "sample_bsdf"]
    assert seq == ["path_init"] + per_bounce * 3
    table = {row["kernel"]: row for row in r.stats.kernels}
    assert set(table) == set(STAGES)
    for name, row in table.items():  # the table counts what was launched, and shares the time it measured
        assert row["launches"] == seq.count(name) == (1 if name == "path_init" else 3)
        assert row["mean_ms"] == pytest.approx(row["total_ms"] / row["launches"])
        assert row["share"] == pytest.approx(row["total_ms"] / sum(x["total_ms"] for x in table.values()))
    # the readback schedule stops when no path is left: under a sky, with the only shape behind the
    # camera, every camera ray misses, so there is one bounce of launches whatever max_depth allows
    sky = pyclpt.load_dict({"type": "scene", "sensor": sensor([{"look_at": {
        "origin": [0, 0, 0], "target": [0, 0, -1], "up": [0, 1, 0]}}], size=8),
        "sky": {"type": "constant", "radiance": 1.0},
        "behind": {"type": "rectangle", "to_world": [{"translate": [0, 0, 5]}]}})
    r = pyclpt.Renderer(sky, integrator="wavefront", max_depth=5, width=8, height=8)
    assert np.all(r.render(2, progress=False) == 1.0)
    assert r.integrator.profile.sequence == (["path_init"] + per_bounce) * 2


def test_path_state_is_declared_once():
    words = record_words()
    assert words == sum(f.width for f in FIELDS)
    assert bytes_per_path() == 4 * words
    soa, aos = opencl_header("soa"), opencl_header("aos")
    for f in FIELDS:
        assert f"path_get_{f.name}(" in soa and f"path_get_{f.name}(" in aos
        assert f"path_set_{f.name}(" in soa and f"path_set_{f.name}(" in aos
    # SoA: one buffer per scalar component; AoS: a single record buffer
    assert soa.count("__global float* ps_") + soa.count("__global int* ps_") == words
    assert "ps_records" in aos
    with pytest.raises(ValueError):
        opencl_header("aosoa")


def test_wavefront_memory_does_not_grow_with_image_or_spp(cornell_box):
    r = pyclpt.Renderer(cornell_box, integrator="wavefront", width=64, height=64, wave_size=512)
    assert r.integrator.capacity == 512
    assert r.integrator.paths.nbytes == 512 * bytes_per_path()
    r.render(1, progress=False)
    assert r.stats.memory == {"wave_size": 512, "bytes_per_path": bytes_per_path() + 24,
                              "path_state_bytes": 512 * bytes_per_path()}
