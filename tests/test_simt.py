"""The SIMT model of the streaming paper's claim (pyclpt/gpu/simt.py): the instrumented megakernel renders
the plain image bit for bit and its trace gives the wavefront's queues; the warp-level accounting
(utilisation, 128-byte lines in SoA and AoS) against hand-computed values."""
from __future__ import annotations

import numpy as np
import pytest

import pyclpt
from pyclpt.gpu.simt import (
    ALIVE,
    COMPONENTS,
    CONTINUED,
    ENV_LIT,
    HIT,
    LIT,
    RECORD_WORDS,
    STAGE_ACCESS,
    PathTrace,
    hand_utilisation,
    line_ids,
    simulate,
    state_traffic,
    trace_paths,
    warp_cost,
)
from pyclpt.integrators.path_state import record_words

SIZE = 16


@pytest.fixture(scope="module")
def box():
    return pyclpt.load("cornell-box")


@pytest.fixture(scope="module")
def traced(box):
    return trace_paths(box, spp=2, max_depth=8, width=SIZE, height=SIZE, seed=5)


def test_instrumented_render_is_bit_identical(box, traced):
    plain = pyclpt.Renderer(box, integrator="megakernel", max_depth=8, width=SIZE, height=SIZE).render(2, seed=5)
    assert traced.image.dtype == plain.dtype
    assert np.array_equal(traced.image, plain)


def test_trace_alive_counts_are_the_wavefronts_queues(box, traced):
    r = pyclpt.Renderer(box, integrator="wavefront", max_depth=8, width=SIZE, height=SIZE, tail_paths=0)
    r.render(2, seed=5)
    stats = r.stats.bounces
    assert [b["rays"] for b in stats] == [int(n) for n in traced.alive_counts() if n]
    for mine, theirs in zip(traced.counts(), stats):
        for key in ("rays", "hits", "misses", "shadow_rays", "unoccluded"):
            assert mine[key] == theirs[key], (mine, theirs)


def test_trace_marks_the_deferred_environment_samples(box, traced):
    """ENV_LIT (the unoccluded shadow rays whose contribution shadow_test multiplies by the environment's radiance:
    ENV_DEFERRED) marks every lit sample of a scene lit by an environment map alone, none of the box's, and the
    instrumented render stays the plain one."""
    assert not (traced.flags & ENV_LIT).any()
    scene = pyclpt.load_dict({"type": "scene", "sensor": {"type": "perspective", "fov": 40,
                                                          "film": {"type": "hdrfilm", "width": SIZE, "height": SIZE}},
                              "ball": {"type": "sphere", "bsdf": {"type": "diffuse"}},
                              "floor": {"type": "rectangle", "to_world": np.diag([4.0, 4.0, 1.0, 1.0]) @
                                        np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -1.2], [0, 0, 0, 1.0]])},
                              "sky": {"type": "envmap", "data": np.linspace(0.2, 3.0, 8 * 16 * 3).reshape(8, 16, 3)
                                      .astype(np.float32)}})
    scene.camera.to_world = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 5.0], [0, 0, 0, 1.0]])
    t = trace_paths(scene, spp=2, max_depth=4, width=SIZE, height=SIZE, seed=3)
    lit, env = (t.flags & LIT) != 0, (t.flags & ENV_LIT) != 0
    assert lit.sum() > 100 and np.array_equal(lit, env)
    plain = pyclpt.Renderer(scene, integrator="megakernel", max_depth=4, width=SIZE, height=SIZE).render(2, seed=3)
    assert np.array_equal(t.image, plain)


def test_trace_is_consistent(traced):
    f = traced.flags
    assert traced.slots == SIZE * SIZE * 2
    assert (traced.alive[0]).all()
    hit = (f & HIT) != 0
    assert not (hit & ~traced.alive).any()
    # a path is alive at b + 1 exactly when it continued at b
    assert np.array_equal(traced.alive[1:], traced.has(16)[:-1][: traced.bounces - 1])
    assert ((traced.material >= 0) == hit).all()
    assert (traced.closest_nodes[traced.alive] >= 1).all()  # the root at least
    assert not traced.shadow_nodes[~traced.has(4)].any()


def test_truncated_trace_is_a_shallower_render(box, traced):
    shallow = trace_paths(box, spp=2, max_depth=3, width=SIZE, height=SIZE, seed=5)
    cut = traced.truncated(3)
    for name in ("flags", "material", "closest_nodes", "closest_prims", "shadow_nodes", "shadow_prims"):
        assert np.array_equal(getattr(cut, name), getattr(shallow, name)), name


def test_utilisation_is_one_for_equal_work():
    steps = np.full(128, 7)
    assert hand_utilisation(steps, np.ones(128, bool)) == 1.0


def test_utilisation_of_a_divergent_warp():
    # one warp of 32: lane 0 takes 10 steps, the others 2; a second warp: 16 lanes alive with 4 steps
    steps = np.concatenate([[10], np.full(31, 2), np.full(32, 4)])
    alive = np.ones(64, bool)
    alive[48:] = False
    expected = (10 + 31 * 2 + 16 * 4) / (32 * 10 + 32 * 4)
    assert hand_utilisation(steps, alive) == pytest.approx(expected)
    # wave64: one wavefront holding both: its longest lane is 10
    assert hand_utilisation(steps, alive, width=64) == pytest.approx((10 + 31 * 2 + 16 * 4) / (64 * 10))


def test_warp_cost_terms():
    valid = np.ones((1, 4), bool)
    mask = np.array([[True, False, True, False]])
    kinds = np.array([[3, 0, 5, 0]])
    w, lane = warp_cost([("any", mask, 10.0), ("kinds", mask, (kinds, 7.0)), ("max", valid, np.array([[1., 2, 3, 4]]))],
                        valid)
    assert w[0] == 10 + 2 * 7 + 4
    assert lane[0] == 2 * 10 + 2 * 7 + 10


def test_record_words_match_the_declaration():
    assert RECORD_WORDS == record_words() == 31
    for accesses in STAGE_ACCESS.values():
        for _, mode, names in accesses:
            assert mode in "rw"
            for n in names:
                assert n in COMPONENTS or f"{n}_x" in COMPONENTS


def test_line_counts_of_a_hand_made_queue():
    # a warp of 32 queue entries: slots 0..15 and 100..115 (two runs), reading org (words 3..5)
    slots = np.concatenate([np.arange(16), np.arange(100, 116)]).reshape(1, 32)
    masks = {"all": np.ones((1, 32), bool)}
    access = [("all", "r", ("org",))]
    # SoA: each component is its own array; 16 consecutive ints fill half a 128-byte line: slots 0..15 are in
    # line 0, 100..115 in lines 3 (96..127): one line each, per component: 2 x 3
    lines, requests = state_traffic(slots, masks, access, "soa")
    assert lines[0] == 6 and requests[0] == 6
    # AoS: 124-byte records; org_x of slot s at byte 124 s + 12; hand-computed set of lines
    expected = set()
    per_instr = 0
    for k in (3, 4, 5):
        ls = {(124 * s + 4 * k) // 128 for s in slots[0]}
        per_instr += len(ls)
        expected |= ls
    lines, requests = state_traffic(slots, masks, access, "aos")
    assert lines[0] == len(expected) and requests[0] == per_instr
    # and a dense warp: 32 consecutive slots, one component: SoA 1 line, AoS ~31
    dense = np.arange(32).reshape(1, 32)
    assert state_traffic(dense, masks, [("all", "r", ("depth",))], "soa")[0][0] == 1
    assert state_traffic(dense, masks, [("all", "r", ("depth",))], "aos")[0][0] == len(
        {(124 * s + 4) // 128 for s in range(32)})
    assert line_ids(np.array([32]), 0, "soa") - line_ids(np.array([0]), 0, "soa") == 1


def test_simulate_gives_finite_ratios(traced):
    p = simulate(traced, target_slots=4 * traced.slots,
                 wavefronts={"soa": {"layout": "soa"}, "aos": {"layout": "aos"},
                             "scan": {"layout": "soa", "compaction": "scan", "indexing": "queue"},
                             "tail": {"layout": "soa", "tail": 0.25}})
    for k, v in p.times_ms.items():
        assert np.isfinite(v) and v > 0, k
    assert 0 < p.utilisation["megakernel"]["megakernel"] <= 1
    for stage, u in p.utilisation["soa"].items():
        assert 0 < u <= 1, stage
    # the same paths in both layouts: same compute, different traffic
    assert p.utilisation["soa"] == p.utilisation["aos"]
    assert [b["rays"] for b in p.per_bounce["soa"]] == [int(n) for n in traced.alive_counts() if n]


def test_synthetic_trace_with_equal_work_has_full_lanes():
    n, b = 64, 2
    flags = np.full((b, n), ALIVE, np.int32)  # every path traces one ray, 3 nodes, and misses
    flags[1] = 0
    zeros = np.zeros((b, n), np.int32)
    steps = np.full((b, n), 3, np.int32)
    tr = PathTrace(flags, np.full((b, n), -1, np.int16), steps, zeros, zeros, zeros, max_depth=2)
    p = simulate(tr)
    assert p.utilisation["megakernel"]["megakernel"] == pytest.approx(1.0)
    assert p.utilisation["wavefront_soa"]["intersect"] == pytest.approx(1.0)
    assert p.utilisation["wavefront_soa"]["miss"] == pytest.approx(1.0)


def test_the_gpu_builds_compaction_and_schedule():
    """The GPU class's compaction (a work-group of 256 lanes a block of 1,024 entries, each lane 4 entries) and
    the pipelined schedule (launches over the bounce before's ray count, the lanes past a queue exiting), as
    Wavefront runs them: hand-counted warps, the exit warps idle, no readback priced."""
    from pyclpt.gpu.simt import CostModel, _compaction, _expected_rays, _group_compaction, wavefront_work

    c = CostModel()
    count, scatter = _group_compaction(5 * 1024, c, 32, launched=8 * 1024)
    # 5 blocks of 256 lanes (40 warps, every lane 4 entries) and 3 launched blocks past the queue (24 warps)
    assert count.warp.size == scatter.warp.size == 40 + 24
    assert np.all(count.lane[:40] > 0) and np.all(count.lane[40:] == 0) and np.all(count.warp[40:] == c.exit)
    assert count.warp[0] == c.stage + 4 * c.compact_flag + 8 * c.group_scan_step  # a scan of 256 lanes: 8 steps
    # a lane of block k sums its share of the k earlier blocks' counts: more work in later blocks
    assert scatter.warp[39] == scatter.warp[0] + c.compact_block
    # on a GPU the group's longest warp is a few entries long, the CPU's one work-item a block 1,024
    assert count.warp.max() * 20 < _compaction(5 * 1024, c, 32)[0].warp.max()

    n, bounces = 32, 4
    alive = [32, 16, 8, 4]
    flags = np.zeros((bounces, n), np.int32)
    for b, k in enumerate(alive):
        flags[b, :k] = ALIVE | (HIT if b < bounces - 1 else 0)
    zeros = np.zeros((bounces, n), np.int32)
    tr = PathTrace(flags, np.full((bounces, n), -1, np.int16), np.full((bounces, n), 3, np.int32), zeros, zeros,
                   zeros, max_depth=bounces)
    readback, _ = wavefront_work(tr, c, "soa", width=4, compaction="group")
    pipelined, _ = wavefront_work(tr, c, "soa", width=4, compaction="group", schedule="pipelined")
    # intersect's warps of 4 lanes per bounce: the queue's (readback), the bound's (pipelined: the wave at bounces
    # 0 and 1, then the count of the bounce before)
    assert [w.warp.size for w in readback["intersect"]] == [8, 4, 2, 1]
    assert [w.warp.size for w in pipelined["intersect"]] == [8, 8, 4, 2]
    assert np.all(pipelined["intersect"][1].warp[4:] == c.exit) and np.all(pipelined["intersect"][1].lane[4:] == 0)
    # the tail's test under pipelined: the count of the bounce before times the ratio of the two before
    counts = np.array(alive)
    assert [_expected_rays(counts, b, "pipelined", n) for b in range(4)] == [32, 32, 8, 4]
    assert [_expected_rays(counts, b, "readback", n) for b in range(4)] == alive
    p = simulate(tr, wavefronts={"r": {"compaction": "group"}, "p": {"compaction": "group", "schedule": "pipelined"}})
    # the host waits for none of the four bounces' counts; the exit warps cost a little
    saved = p.times_ms["r"] - p.times_ms["p"]
    assert 0 < saved <= 4 * c.readback_us / 1e3 and saved == pytest.approx(4 * c.readback_us / 1e3, rel=0.05)
    with pytest.raises(ValueError, match="unknown schedule 'eager'"):
        wavefront_work(tr, c, "soa", schedule="eager")


def _lengths_trace(lengths: list[int], bounces: int) -> PathTrace:
    """Paths that each trace ``lengths[i]`` rays, each hitting, the last one ending the path."""
    n = len(lengths)
    flags = np.zeros((bounces, n), np.int32)
    for p, k in enumerate(lengths):
        flags[:k - 1, p] = ALIVE | HIT | CONTINUED
        flags[k - 1, p] = ALIVE | HIT
    zeros = np.zeros((bounces, n), np.int32)
    return PathTrace(flags, np.full((bounces, n), -1, np.int16), np.full((bounces, n), 3, np.int32), zeros, zeros,
                     zeros, max_depth=bounces)


def test_regeneration_keeps_the_pool_full_in_slot_order():
    """The regeneration design (regenerating_work): every step runs a bounce of every slot of the pool while the
    stream lasts, ended paths replaced by the stream's next ones and the ray queue in slot order; only the steps
    after the pool's first turn-over are priced, with the paths that ended in them."""
    from pyclpt.gpu.simt import CostModel, regenerating_work

    c = CostModel()
    one = _lengths_trace([1] * 16, 2)  # every path a single ray: the whole pool is replaced each step
    launches, info = regenerating_work(one, c, "soa", width=4, pool=4, passes=3)
    assert [s["rays"] for s in info["steps"]] == [4] * 11 and [s["new"] for s in info["steps"]] == [4] * 11
    assert info["window"] == (1, 11) and info["paths"] == 40  # 48 paths, the first pool's 4 and 4 more unpriced
    assert len(launches["intersect"]) == len(launches["path_init"]) == 10
    assert all(w.warp.size == 1 and w.utilisation(w.compute) == 1.0 for w in launches["intersect"])
    # 3 compactions between the stages, 2 over the pool (its free slots, its live ones) a step
    assert len(launches["compact_count"]) == 5 * 10

    mixed = _lengths_trace([1, 3] * 64, 3)
    launches, info = regenerating_work(mixed, c, "soa", width=8, pool=64, passes=4)
    first, end = info["window"]
    assert all(s["rays"] == 64 for s in info["steps"])  # full while the stream lasts
    assert sum(s["ended"] for s in info["steps"][first:end]) == info["paths"]
    # the ray queue is the pool in slot order: a warp's 8 lanes read each component from one 128-byte line
    assert {w.lines for w in launches["intersect"]} == {launches["intersect"][0].lines}
    p = simulate(mixed, wavefronts={"slots": {"layout": "soa", "tail": 0.25},
                                    "regen": {"layout": "soa", "regenerate": 0.5, "passes": 4}})
    assert np.isfinite(p.times_ms["regen"]) and p.times_ms["regen"] > 0
    with pytest.raises(ValueError, match="pool must be 1..128"):
        regenerating_work(mixed, c, pool=129)
