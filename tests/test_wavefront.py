"""The wavefront integrator against the megakernel: same estimator, same random numbers,
same image; queues conserve paths; the launch sequence is the design's."""
from __future__ import annotations

import numpy as np
import pytest

import pyclpt
from pyclpt.integrators.path_state import FIELDS, bytes_per_path, opencl_header, record_words
from pyclpt.integrators.wavefront import STAGES


def render(scene, **kw):
    r = pyclpt.Renderer(scene, **{k: kw.pop(k) for k in list(kw) if k in (
        "integrator", "layout", "max_depth", "width", "height", "wave_size")})
    img = r.render(kw.pop("spp"), seed=kw.pop("seed", 0), progress=False)
    return img, r


def assert_same_image(a, b):
    rel = np.abs(a - b) / np.maximum(np.abs(b), 1e-3)
    assert rel.max() < 1e-4, rel.max()


@pytest.mark.parametrize("max_depth", [1, 3, -1])
def test_wavefront_equals_megakernel_cornell_box(cornell_box, max_depth):
    kw = dict(spp=16, max_depth=max_depth, width=32, height=32, seed=9)
    mega, _ = render(cornell_box, integrator="megakernel", **dict(kw))
    soa, _ = render(cornell_box, integrator="wavefront", layout="soa", **dict(kw))
    aos, _ = render(cornell_box, integrator="wavefront", layout="aos", **dict(kw))
    assert mega.max() > 0
    assert_same_image(soa, mega)
    assert_same_image(aos, mega)
    # on the same device and compiler they are in fact bit-identical
    assert np.array_equal(soa, mega) and np.array_equal(aos, mega)


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
    r = pyclpt.Renderer(cornell_box, integrator="wavefront", max_depth=-1, width=16, height=16)
    r.film.clear()
    import pyopencl as cl

    cl.enqueue_fill_buffer(r.device.queue, r.film.frame, np.float32(np.nan), 0, 4 * 3 * 256)
    r.integrator.render_frame(0, 0)
    frame = r.film.read_frame()
    assert np.isfinite(frame).all()


def test_launch_sequence_per_bounce(cornell_box):
    r = pyclpt.Renderer(cornell_box, integrator="wavefront", max_depth=3, width=8, height=8)
    r.render(1, progress=False)
    seq = r.integrator.profile.sequence
    per_bounce = ["intersect", "miss", "process_hit", "shadow_test", "light_contribution", "sample_bsdf"]
    assert seq == ["path_init"] + per_bounce * 3
    table = {row["kernel"]: row for row in r.stats.kernels}
    assert set(table) == set(STAGES)
    assert table["intersect"]["launches"] == 3
    assert sum(row["share"] for row in table.values()) == pytest.approx(1.0)


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
