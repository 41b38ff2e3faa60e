"""The wavefront integrator against the megakernel: same estimator, same random numbers,
same image; queues conserve paths; the launch sequence is the design's."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pyopencl as cl
import pytest
from closed_forms import emitter_pixels

import pyclpt
from pyclpt.buffers import scene as scene_buffers
from pyclpt.buffers.scene import pack_scene
from pyclpt.integrators.megakernel import MEGAKERNEL_LAUNCH
from pyclpt.integrators.path_state import FIELDS, bytes_per_path, opencl_header, record_words
from pyclpt.integrators.wavefront import (
    DEFAULT_WAVE_SIZE,
    GPU_WAVE_SIZE,
    QUEUE_BYTES_PER_PATH,
    STAGES,
    default_wave_size,
)
from scenes import interior_furnace, material_zoo, sensor


def render(scene, **kw):
    r = pyclpt.Renderer(scene, **{k: kw.pop(k) for k in list(kw) if k in (
        "integrator", "layout", "max_depth", "width", "height", "wave_size", "device", "tail_paths", "schedule")})
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


def test_repeat_runs_are_bit_identical(cornell_box):
    kw = dict(spp=4, max_depth=-1, width=32, height=32, seed=5)
    a, _ = render(cornell_box, integrator="wavefront", **dict(kw))
    b, _ = render(cornell_box, integrator="wavefront", **dict(kw))
    assert np.array_equal(a, b)


@pytest.mark.parametrize("schedule", ["readback", "pipelined", "capacity"])
def test_queue_conservation(cornell_box, schedule):
    """Every path ends exactly once; counts add up at every bounce (every bounce through the queues:
    tail_paths=0)."""
    scene = cornell_box
    r = pyclpt.Renderer(scene, integrator="wavefront", max_depth=-1, width=32, height=32, tail_paths=0)
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


@pytest.mark.parametrize("name, max_depth", [("cornell-box", 6), ("cornell-bunny", 8)])
@pytest.mark.parametrize("schedule", ["readback", "pipelined", "capacity"])
def test_queue_counts_equal_those_of_the_megakernels_paths(name, max_depth, schedule, shared_scenes):
    """The order-preserving compaction routes the paths the megakernel follows: each bounce's rays, hits, misses,
    shadow rays and unoccluded ones over three waves equal the counts of the instrumented megakernel's trace of
    the same samples (pyclpt.gpu.simt; it replaced a table of the atomic queues' counts, main at 5f14a23, when
    the random numbers' blocks changed)."""
    from pyclpt.gpu.simt import trace_paths

    scene = pyclpt.load(name)
    r = pyclpt.Renderer(scene, integrator="wavefront", max_depth=max_depth, width=24, height=16,
                        wave_size=300, tail_paths=0)
    r.integrator.schedule = schedule
    r.render(2, seed=4, progress=False)
    keys = ("rays", "hits", "misses", "shadow_rays", "unoccluded")
    rows = [tuple(row[k] for k in keys) for row in r.stats.bounces]
    traced = trace_paths(scene, spp=2, max_depth=max_depth, width=24, height=16, seed=4)
    want = [tuple(row[k] for k in keys) for row in traced.counts()]
    assert rows == want
    assert len(rows) >= 5 and rows[0][0] == 24 * 16 * 2


def read_queue(r, buf, count):
    import pyopencl as cl

    out = np.empty(r.integrator.capacity, np.int32)
    cl.enqueue_copy(r.device.queue, out, buf)
    return out[:count]


@pytest.mark.parametrize("schedule", ["readback", "capacity"])
def test_queues_list_slots_in_ascending_order(cornell_box, schedule):
    """After every bounce each queue lists distinct slots in strictly ascending order, and each is the
    subsequence of its source the stage chose: hits and misses partition the rays, shadow rays are hits,
    unoccluded rays are shadow rays, the next rays are hits."""
    import pyopencl as cl

    from pyclpt.integrators.wavefront import Q_COUNT

    r = pyclpt.Renderer(cornell_box, integrator="wavefront", max_depth=-1, width=40, height=30, wave_size=1000,
                        tail_paths=0)
    w = r.integrator
    w.schedule = schedule
    w.warm_up()
    q = r.device.queue
    cl.enqueue_fill_buffer(q, w.counters, np.int32(0), 0, w._counts.nbytes)
    w.path_init(1000, 7, 0, 100)
    bounces = 0
    for bounce in range(12):
        cl.enqueue_copy(q, w._counts, w.counters)
        rays = int(w._counts[bounce, 0])
        if rays == 0:
            break
        w.bounce(rays if schedule == "readback" else w.capacity, bounce, 7, 0)
        cl.enqueue_copy(q, w._counts, w.counters)
        n_ray, n_hit, n_miss, n_shadow, n_light = (int(c) for c in w._counts[bounce, :Q_COUNT])
        assert n_ray == rays
        ray = read_queue(r, w.ray_queues[bounce % 2], n_ray)
        hit = read_queue(r, w.hit_queue, n_hit)
        miss = read_queue(r, w.miss_queue, n_miss)
        shadow = read_queue(r, w.shadow_queue, n_shadow)
        light = read_queue(r, w.light_queue, n_light)
        nxt = read_queue(r, w.ray_queues[(bounce + 1) % 2], int(w._counts[bounce + 1, 0]))
        for queue in (ray, hit, miss, shadow, light, nxt):
            assert np.all(np.diff(queue) > 0), (bounce, queue)
            assert queue.size == 0 or (queue[0] >= 0 and queue[-1] < w.capacity)
        if bounce == 0:
            assert np.array_equal(ray, np.arange(1000))
        assert np.array_equal(np.union1d(hit, miss), ray) and np.intersect1d(hit, miss).size == 0
        assert np.all(np.isin(shadow, hit)) and np.all(np.isin(light, shadow)) and np.all(np.isin(nxt, hit))
        if bounce == 0:  # every queue has entries to order
            assert 0 < n_light < n_shadow < n_hit and 0 < n_miss
        bounces += 1
    assert bounces >= 4


def test_dropped_samples_are_counted_alike_by_both_integrators():
    """Some samples (the object's) overflow to inf, the sky's do not: every integrator and wave size
    counts the same number of dropped samples, accumulated over frames, and draws the same image."""
    from scenes import object_under_sky

    scene = object_under_sky({"type": "diffuse", "reflectance": 0.9}, radiance=3.0e38)
    scene.meshes[0].emission = (3.0e38, 3.0e38, 3.0e38)
    counts, images = [], []
    for integrator, kw in (("megakernel", {}), ("wavefront", {}), ("wavefront", {"wave_size": 100}),
                           ("wavefront", {"layout": "aos"})):
        r = pyclpt.Renderer(scene, integrator=integrator, max_depth=3, width=20, height=20, **kw)
        images.append(r.render(3, seed=5, progress=False))
        counts.append(r.stats.dropped_samples)
        assert r.film.dropped_samples() == counts[-1]
    assert 20 < counts[0] < 20 * 20 * 3 and len(set(counts)) == 1, counts
    assert all(np.array_equal(img, images[0]) for img in images)


def test_no_path_ends_by_roulette_before_rr_depth():
    """Inside a closed diffuse sphere every ray hits and every BSDF sample is valid, so until Russian
    roulette starts (on rays of bounce RR_DEPTH = 3, docs/architecture.md) every path is alive; from
    there on paths end (half of them at once: the test below)."""
    rr_depth = 3
    r = pyclpt.Renderer(interior_furnace(0.5), integrator="wavefront", max_depth=-1, width=16, height=16,
                        tail_paths=0)
    r.render(4, seed=3, progress=False)
    rows = r.stats.bounces
    paths = 16 * 16 * 4
    for b in range(rr_depth):
        assert rows[b]["rays"] == rows[b]["hits"] == paths, (b, rows[b])
    assert rows[rr_depth]["rays"] < 0.6 * paths, rows[rr_depth]


def _survival(albedo: float, bounces: int, factor: float = 2.0, first: bool = True) -> list[float]:
    """path.h's roulette inside a closed diffuse sphere, where every bounce multiplies the throughput by exactly
    the albedo: the probability that a path on a ray of bounce b (3 <= b < bounces) goes on, given it reached b.
    ``first``: the throughput relative to the first bounce's (pyclpt); False: the throughput alone (Mitsuba's)."""
    beta, out = 1.0, []
    for b in range(1, bounces):
        beta *= albedo
        if b >= 3:
            q = min(factor * beta / (albedo if first else 1.0), 0.95)
            out.append(q)
            beta /= q
    return out


@pytest.mark.parametrize("albedo", [0.3, 0.5, 0.8])
def test_roulette_keeps_paths_by_their_throughput_relative_to_the_first_bounce(albedo):
    """The roulette (from bounce RR_DEPTH = 3) keeps a path with probability min(RR_FACTOR * beta / beta_1 *
    eta^2, 0.95), RR_FACTOR 2 and beta_1 the throughput after the first bounce (path.h, docs/architecture.md
    "Russian roulette"). Inside a closed diffuse sphere beta = albedo^b exactly, so the share of paths that go on
    at bounces 3 and 4 is known: for albedo 0.3 / 0.5 / 0.8, 0.18 / 0.5 / 0.95 at bounce 3 (the throughput
    alone, Mitsuba's rule with factor 1, kept 0.027 / 0.125 / 0.512)."""
    r = pyclpt.Renderer(interior_furnace(albedo), integrator="wavefront", max_depth=-1, width=32, height=32,
                        tail_paths=0)
    r.render(4, seed=5, progress=False)
    rows = r.stats.bounces
    paths = 32 * 32 * 4
    q3, q4 = _survival(albedo, 5)
    assert q3 != pytest.approx(_survival(albedo, 4, factor=1.0, first=False)[0], abs=0.05)
    assert rows[2]["rays"] == paths
    assert rows[3]["rays"] / paths == pytest.approx(q3, abs=0.03), rows[3]
    assert rows[4]["rays"] / rows[3]["rays"] == pytest.approx(q4, abs=0.06), rows[4]


def test_launch_sequence_per_bounce(cornell_box):
    r = pyclpt.Renderer(cornell_box, integrator="wavefront", max_depth=3, width=8, height=8, tail_paths=0)
    r.render(1, progress=False)
    seq = r.integrator.profile.sequence
    compact = ["compact_count", "compact_scatter"]
    per_bounce = ["intersect", *compact, "miss", "process_hit", *compact, "shadow_test", *compact,
                  "light_contribution", "sample_bsdf", *compact]
    assert seq == ["path_init"] + per_bounce * 3
    table = {row["kernel"]: row for row in r.stats.kernels}
    assert set(table) == set(STAGES) - {"finish_paths"}  # tail_paths=0: the stages do every bounce
    for name, row in table.items():  # the table counts what was launched, and shares the time it measured
        assert row["launches"] == seq.count(name) == {"path_init": 1, "compact_count": 12,
                                                       "compact_scatter": 12}.get(name, 3)
        assert row["mean_ms"] == pytest.approx(row["total_ms"] / row["launches"])
        assert row["share"] == pytest.approx(row["total_ms"] / sum(x["total_ms"] for x in table.values()))
    # the readback schedule stops when no path is left: under a sky, with the only shape behind the
    # camera, every camera ray misses, so there is one bounce of launches whatever max_depth allows;
    # both samples of the 8x8 image are in one wave (a batch of two frames)
    sky = pyclpt.load_dict({"type": "scene", "sensor": sensor([{"look_at": {
        "origin": [0, 0, 0], "target": [0, 0, -1], "up": [0, 1, 0]}}], size=8),
        "sky": {"type": "constant", "radiance": 1.0},
        "behind": {"type": "rectangle", "to_world": [{"translate": [0, 0, 5]}]}})
    r = pyclpt.Renderer(sky, integrator="wavefront", max_depth=5, width=8, height=8, tail_paths=0)
    assert np.all(r.render(2, progress=False) == 1.0)
    assert r.film.batch == 64 and r.integrator.capacity == 64 * 64  # 64 frames of 8x8 pixels
    assert r.integrator.profile.sequence == ["path_init"] + per_bounce


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
    assert r.stats.memory == {"wave_size": 512, "bytes_per_path": bytes_per_path() + 25,
                              "path_state_bytes": 512 * bytes_per_path()}


def test_material_zoo_wavefront_equals_megakernel():
    """Every material kind, texture, bump map, mask and emitter kind (tests/scenes.py: material_zoo):
    every branch of the shading code gives the megakernel's image in the wavefront's stages."""
    kw = dict(spp=2, max_depth=6, width=24, height=24, seed=6)
    mega, _ = render(material_zoo(), integrator="megakernel", **dict(kw))
    soa, _ = render(material_zoo(), integrator="wavefront", layout="soa", **dict(kw))
    aos, _ = render(material_zoo(), integrator="wavefront", layout="aos", **dict(kw))
    assert mega.max() > 0
    np.testing.assert_array_equal(soa, mega)
    np.testing.assert_array_equal(aos, mega)


def test_specialisation_masks(cornell_box):
    """-DSCENE_MATERIALS / -DSCENE_LIGHTS list the kinds a scene has; -DSCENE_HAS_TEXTURES whether a
    reflectance or transmittance is textured (pyclpt/buffers/scene.py)."""
    box = pack_scene(cornell_box).defines
    assert (box["SCENE_MATERIALS"], box["SCENE_LIGHTS"], box["SCENE_HAS_TEXTURES"]) == (1, 1, False)
    zoo = pack_scene(material_zoo()).defines
    assert zoo["SCENE_MATERIALS"] == 0xFF  # all eight kinds (bits MAT_*)
    assert zoo["SCENE_LIGHTS"] == 0b111  # triangle, point, constant (bits LIGHT_*)
    assert zoo["SCENE_HAS_TEXTURES"] and zoo["SCENE_HAS_MASKS"] and zoo["SCENE_HAS_BUMPMAPS"]


@pytest.mark.parametrize("integrator", ["megakernel", "wavefront"])
def test_specialisation_changes_no_pixel(cornell_box, monkeypatch, integrator):
    """Compiling only the scene's material and emitter kinds (and no texture lookups where there are
    none) removes code no path can reach: the image is bit-identical to the one from kernels built with
    every kind."""
    kw = dict(spp=4, max_depth=6, width=24, height=24, seed=2, integrator=integrator)
    specialised, _ = render(cornell_box, **dict(kw))

    def general(scene, device_class="cpu"):
        arrays = pack_scene(scene, device_class)
        arrays.defines = {k: v for k, v in arrays.defines.items() if k not in ("SCENE_MATERIALS", "SCENE_LIGHTS")}
        arrays.defines["SCENE_HAS_TEXTURES"] = True
        return arrays

    monkeypatch.setattr(scene_buffers, "pack_scene", general)
    every_kind, _ = render(cornell_box, **dict(kw))
    assert specialised.max() > 0
    np.testing.assert_array_equal(specialised, every_kind)


@pytest.mark.parametrize("tail_paths", [0, 40, 10_000])
def test_finish_paths_gives_the_megakernels_image(cornell_box, tail_paths, each_device):
    """finish_paths runs the megakernel's loop (path_continue) on the paths a wave has left: the image is
    the megakernel's, bit for bit, whether it takes over at the second bounce (10_000), later (40) or
    never (0)."""
    kw = dict(spp=4, max_depth=-1, width=24, height=24, seed=7, device=each_device)
    mega, _ = render(cornell_box, integrator="megakernel", **dict(kw))
    wave, r = render(cornell_box, integrator="wavefront", tail_paths=tail_paths, **dict(kw))
    assert mega.max() > 0
    np.testing.assert_array_equal(wave, mega)
    tails = [row["tail"] for row in r.stats.bounces if row["tail"]]
    assert (len(tails) > 0) == (tail_paths > 0)
    if tail_paths == 10_000:
        assert r.stats.bounces[1]["tail"] == r.stats.bounces[1]["rays"]  # all of them from bounce 1


@pytest.mark.parametrize("tail_paths", [0, 40, 10_000])
def test_pipelined_schedule_waits_on_no_bounce(cornell_box, tail_paths, monkeypatch, each_device):
    """The pipelined schedule sizes bounce b by bounce b - 1's ray count, read without blocking while bounce
    b - 1's launches queue behind it: the host never waits for a bounce's own count, and the image is the
    megakernel's bit for bit, in several waves, with the tail from the second bounce, later or never (its test
    on the count expected from the two bounces before)."""
    from pyclpt.integrators.wavefront import Wavefront

    kw = dict(spp=3, max_depth=-1, width=24, height=24, seed=7, device=each_device, wave_size=700)
    mega, _ = render(cornell_box, integrator="megakernel", **dict(kw))
    blocking = []
    read_count = Wavefront._read_count
    monkeypatch.setattr(Wavefront, "_read_count", lambda self, *a: blocking.append(a) or read_count(self, *a))
    wave, r = render(cornell_box, integrator="wavefront", schedule="pipelined", tail_paths=tail_paths, **dict(kw))
    assert r.integrator.schedule == "pipelined" and blocking == []
    np.testing.assert_array_equal(wave, mega)
    rows = r.stats.bounces
    assert rows[0]["rays"] == 24 * 24 * 3
    tails = {b: row["tail"] for b, row in enumerate(rows) if row["tail"]}
    assert (len(tails) > 0) == (tail_paths > 0)
    if tail_paths == 10_000:  # every wave's n paths bound the second bounce: the tail takes them all there
        assert tails == {1: rows[1]["rays"]}
    if tail_paths == 40:  # never before the third bounce: the first two are sized by the wave
        assert min(tails) >= 2
    ended = sum(row["misses"] + row["hits"] - nxt["rays"] for row, nxt in zip(rows, [*rows[1:], {"rays": 0}]))
    assert ended + sum(tails.values()) == 24 * 24 * 3


def test_every_path_ends_once_with_a_tail(cornell_box):
    """With finish_paths taking the last paths: the paths the stages ended plus those the tail took are
    all the paths, the tail's bounce launches no stage, and the megakernel's image comes out."""
    r = pyclpt.Renderer(cornell_box, integrator="wavefront", max_depth=-1, width=32, height=32, tail_paths=100)
    r.render(1, seed=2, progress=False)
    rows = r.stats.bounces
    tail = rows[-1]
    assert tail["tail"] == tail["rays"] > 0 and tail["hits"] == tail["misses"] == tail["shadow_rays"] == 0
    assert all(row["tail"] == 0 for row in rows[:-1]) and rows[-2]["rays"] > 100 >= tail["rays"]
    ended = sum(row["misses"] + row["hits"] - nxt["rays"] for row, nxt in zip(rows[:-1], rows[1:]))
    assert ended + tail["tail"] == 32 * 32
    assert r.integrator.profile.sequence.count("finish_paths") == 1


@pytest.mark.parametrize("integrator", ["megakernel", "wavefront"])
def test_batches_of_frames_change_no_pixel(cornell_box, integrator):
    """A small image renders several samples per wave or launch (a batch of frames: film slot f is pixel
    f % pixels of sample first + f / pixels, pyclpt/film/film.py). The image is bit-identical to the
    one rendered a frame at a time: the same paths, and the frames added in sample order."""
    kw = dict(integrator=integrator, max_depth=5, width=20, height=12)
    one = pyclpt.Renderer(cornell_box, wave_size=240, **kw)  # 240 paths: one frame of 20x12 at a time
    many = pyclpt.Renderer(cornell_box, **kw)
    assert one.film.batch == 1 and many.film.batch == 64
    a = one.render(70, seed=3, first_sample=5, progress=False)  # a batch of 64 frames, then one of 6
    b = many.render(70, seed=3, first_sample=5, progress=False)
    assert a.max() > 0 and one.film.frames == many.film.frames == 70
    np.testing.assert_array_equal(a, b)


def test_path_state_component_buffers(cornell_box):
    """PathStorage.component names an SoA buffer by its component, as the accessors do."""
    r = pyclpt.Renderer(cornell_box, integrator="wavefront", width=8, height=8)
    paths = r.integrator.paths
    names = [c for f in FIELDS for c in ([f.name] if f.width == 1 else [f"{f.name}_{a}" for a in "xyz"])]
    assert [paths.component(n) for n in names] == paths.buffers
    with pytest.raises(KeyError, match="no path state component 'pixel'"):
        paths.component("pixel")
    aos = pyclpt.Renderer(cornell_box, integrator="wavefront", layout="aos", width=8, height=8)
    with pytest.raises(ValueError, match="keeps records"):
        aos.integrator.paths.component("hit_prim")


class _FakeDevice:
    """What default_wave_size reads of a device."""

    def __init__(self, is_cpu: bool, global_mem: int, max_alloc: int) -> None:
        self.is_cpu, self.global_mem, self.max_alloc = is_cpu, global_mem, max_alloc


def test_default_wave_size_per_device_class():
    """CPUs keep 2^18 paths a wave; GPUs get a whole 1920x1080 frame (2^21) unless an eighth of their memory or
    their largest buffer holds fewer paths, and never fewer than a CPU's."""
    per_path = bytes_per_path() + QUEUE_BYTES_PER_PATH
    assert default_wave_size(_FakeDevice(True, 1 << 40, 1 << 40)) == DEFAULT_WAVE_SIZE == 1 << 18
    assert default_wave_size(_FakeDevice(False, 141 << 30, 35 << 30)) == GPU_WAVE_SIZE == 1 << 21
    assert GPU_WAVE_SIZE >= 1920 * 1080
    assert default_wave_size(_FakeDevice(False, 2 << 30, 1 << 30)) == (2 << 30) // 8 // per_path
    assert default_wave_size(_FakeDevice(False, 64 << 30, 128 << 20)) == (128 << 20) // bytes_per_path()
    assert default_wave_size(_FakeDevice(False, 256 << 20, 64 << 20)) == DEFAULT_WAVE_SIZE
    # a renderer on a CPU device uses the CPU default, the megakernel's launch size stays its own
    r = pyclpt.Renderer(pyclpt.load("cornell-box"), integrator="megakernel", width=600, height=500)
    assert r.integrator.wave_size == MEGAKERNEL_LAUNCH


def test_launches_set_only_the_arguments_that_changed(cornell_box, monkeypatch):
    """A stage's kernel keeps its arguments between launches: a launch sets those that differ from the
    stage's last launch (the bounce, the queue, a seed), not the scene's ~40 buffers again; a changed buffer
    or value is set, so the image follows the seed and the scene."""
    calls = {"set_args": 0, "set_arg": 0}
    set_args, set_arg = cl.Kernel.set_args, cl.Kernel.set_arg

    def counting_set_args(self, *a):
        calls["set_args"] += 1
        return set_args(self, *a)

    def counting_set_arg(self, i, a):
        calls["set_arg"] += 1
        return set_arg(self, i, a)

    monkeypatch.setattr(cl.Kernel, "set_args", counting_set_args)
    monkeypatch.setattr(cl.Kernel, "set_arg", counting_set_arg)
    r = pyclpt.Renderer(cornell_box, integrator="wavefront", max_depth=3, width=16, height=16, tail_paths=0)
    wf = r.integrator
    first = r.render(1, seed=3, progress=False)
    launches, whole = len(wf.profile.sequence), calls["set_args"]
    assert whole == len(STAGES)  # warm_up set every stage's arguments once, nothing since
    total_args = sum(len(a) for a in wf._args_set.values())
    calls["set_arg"] = 0
    other = r.render(1, seed=4, progress=False)
    again = r.render(1, seed=3, progress=False)
    assert calls["set_args"] == whole  # never all of them again
    assert 0 < calls["set_arg"] < total_args  # a few per launch, far fewer than all
    assert calls["set_arg"] <= 3 * 2 * launches
    assert np.array_equal(first, again) and not np.array_equal(first, other)
    # against a fresh renderer (every argument set once): the same image
    fresh = pyclpt.Renderer(cornell_box, integrator="wavefront", max_depth=3, width=16, height=16, tail_paths=0)
    assert np.array_equal(fresh.render(1, seed=4, progress=False), other)


def test_stages_share_a_program_where_the_defines_they_read_agree(cornell_box):
    """Each stage is built with the scene's and film's defines its code reads (STAGE_DEFINES, checked against the
    compiled code by tests/test_gpu_isa.py): compact_count and compact_scatter know queues only
    (cl/integrators/wavefront/compact.h) and light_contribution the path state only, so every scene and film of a
    layout shares them; the box with another material shares the traversal stages and path_init, not the shading
    ones; the zoo (masks, other lights, a G-buffer) shares path_init alone."""
    import copy

    from pyclpt.device.context import open_device
    from pyclpt.device.program import record_programs

    device = open_device("pocl")  # its own: the dry programs (recorded, not compiled) never meet a renderer's

    def wavefront(scene, **kw):
        with record_programs(dry=True) as programs:
            pyclpt.Renderer(scene, integrator="wavefront", max_depth=3, width=8, height=8, device=device, **kw)
        return {Path(p.label).stem: p.key for p in programs}

    metal = copy.deepcopy(cornell_box)
    metal.materials[0] = pyclpt.Conductor()
    box, other, zoo = wavefront(cornell_box), wavefront(metal), wavefront(material_zoo(4), aovs=True)
    aos = wavefront(material_zoo(4), layout="aos", aovs=True)
    assert set(STAGES) <= set(box)

    def same(a, b, stage):  # the same program: the same source and options (the device's cache key)
        return a[stage] == b[stage]

    for stage in ("compact_count", "compact_scatter"):
        assert same(box, zoo, stage) and same(box, aos, stage), stage
    assert same(box, zoo, "light_contribution") and not same(zoo, aos, "light_contribution")  # the layouts' state
    for stage in ("path_init", "intersect", "miss", "shadow_test", "light_contribution"):
        assert same(box, other, stage), stage
    for stage in ("miss", "process_hit", "sample_bsdf", "finish_paths"):
        assert not same(box, zoo, stage), stage
    for stage in ("process_hit", "sample_bsdf", "finish_paths"):
        assert not same(box, other, stage), stage
    assert same(box, zoo, "path_init") and not same(box, zoo, "intersect")
