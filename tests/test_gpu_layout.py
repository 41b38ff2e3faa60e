"""The BVH layout per device class (Device.device_class, PYCLPT_DEVICE_CLASS; docs/bvh.md "Layouts per device
class"): CPUs keep the 8-wide BVH with leaf packets, GPUs get a binary BVH whose traversal stack holds node
indices only (-DBVH_STACK_DISTANCES=0). Run here on PoCL with the GPU layout forced."""
from __future__ import annotations

import numpy as np
import pytest

import pyclpt
from pyclpt.accel import bvh as bvh_mod
from pyclpt.accel.bvh import FlatBVH, build_bvh, layout_settings, leaf_packet_buffer
from pyclpt.buffers.scene import SceneBuffers, pack_scene
from pyclpt.common.cache import cache_dir
from pyclpt.common.env import EnvironmentVariableError
from pyclpt.device.program import build_program
from pyclpt.integrators.wavefront import STAGES
from scenes import material_zoo

CLASS_ENV = "PYCLPT_DEVICE_CLASS"


@pytest.fixture(autouse=True)
def _own_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("PYCLPT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(CLASS_ENV, raising=False)


def test_device_class_and_its_setting(device, monkeypatch):
    """PoCL is a CPU device; the setting overrides the class (any case); a bad value is an error naming the
    setting and the value, also from a render."""
    assert device.device_class == "cpu"
    monkeypatch.setenv(CLASS_ENV, " GPU ")
    assert device.device_class == "gpu"
    monkeypatch.setenv(CLASS_ENV, "cpu")
    assert device.device_class == "cpu"
    monkeypatch.setenv(CLASS_ENV, "tpu")
    with pytest.raises(EnvironmentVariableError, match=r"PYCLPT_DEVICE_CLASS='tpu': expected one of cpu, gpu"):
        _ = device.device_class
    with pytest.raises(EnvironmentVariableError, match=r"PYCLPT_DEVICE_CLASS='tpu'"):
        pyclpt.render(pyclpt.load("cornell-box"), spp=1, width=4, height=4, device=device)


def test_device_class_picks_the_layout_and_the_cache_entry(cornell_box, device, monkeypatch):
    """A CPU and a GPU build of one scene are different BVHs (widths 8 and 2) and different cache entries;
    only the GPU class passes BVH_STACK_DISTANCES (0) and DEVICE_CLASS_GPU, so CPU programs keep their options."""
    cpu, gpu = pack_scene(cornell_box, "cpu"), pack_scene(cornell_box, "gpu")
    assert (cpu.bvh.width, gpu.bvh.width) == (8, 2)
    assert cpu.defines["BVH_LEAF_PACKETS"] and not gpu.defines["BVH_LEAF_PACKETS"]
    assert cpu.defines["BVH_STACK_DISTANCES"] is None and gpu.defines["BVH_STACK_DISTANCES"] == 0
    assert cpu.defines["DEVICE_CLASS_GPU"] is None and gpu.defines["DEVICE_CLASS_GPU"] is True
    assert layout_settings("cpu") is bvh_mod.DEFAULT_SETTINGS and layout_settings("gpu").width == 2
    assert len(list(cache_dir("bvh").glob("*.npz"))) == 2  # one entry each
    again = pack_scene(cornell_box, "gpu")  # from the cache: the GPU entry, not the CPU one
    assert again.bvh.build_seconds == 0.0 and again.bvh.width == 2
    np.testing.assert_array_equal(again.bvh.nodes, gpu.bvh.nodes)
    with pytest.raises(ValueError, match="device_class must be one of cpu, gpu"):
        pack_scene(cornell_box, "tpu")
    monkeypatch.setenv(CLASS_ENV, "gpu")  # a device's buffers follow its class
    assert SceneBuffers(cornell_box, device).arrays.bvh.width == 2
    monkeypatch.delenv(CLASS_ENV)
    assert SceneBuffers(cornell_box, device).arrays.bvh.width == 8


def _relmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean((a - b) ** 2) / np.mean(b**2))


@pytest.mark.parametrize("scene_name", ["cornell-box", "material_zoo"])
def test_gpu_layout_renders(scene_name, cornell_box, device, monkeypatch):
    """Under the GPU layout the megakernel and the wavefront agree bit for bit; the image is the binary BVH's
    with the CPU's stack of distances (here, bit for bit: the node-only stack changes which boxes are tested,
    not which hit is found), and agrees with the CPU layout's as renders of different node widths do
    (docs/bvh.md): identical but where a tie between two triangles hit within 2 ulp is broken the other way
    and the path goes elsewhere. The material zoo (alpha masks, bump maps, textures, coplanar faces) has such
    ties: at 2 spp 2.4 % of its pixels differ between widths 2 and 8 (relMSE 2.8e-3, falling with spp:
    6e-4 at 32 spp), as between the CPU widths 4 and 8."""
    scene = cornell_box if scene_name == "cornell-box" else material_zoo()
    kw = dict(spp=2, max_depth=6, width=24, height=24, seed=4, device=device)
    cpu = pyclpt.render(scene, integrator="megakernel", **kw)
    monkeypatch.setattr(bvh_mod, "DEFAULT_SETTINGS", bvh_mod.BuildSettings(width=2))
    binary = pyclpt.render(scene, integrator="megakernel", **kw)
    monkeypatch.setenv(CLASS_ENV, "gpu")
    mega = pyclpt.render(scene, integrator="megakernel", **kw)
    wave = pyclpt.render(scene, integrator="wavefront", **kw)
    assert mega.max() > 0
    np.testing.assert_array_equal(wave, mega)
    np.testing.assert_array_equal(mega, binary)
    differ = np.mean(np.abs(mega - cpu).max(-1) > 1e-4)
    if scene_name == "cornell-box":  # no ties: the same image
        assert differ == 0
    else:
        assert _relmse(mega, cpu) < 1e-2 and differ < 0.05
        np.testing.assert_allclose(mega.mean((0, 1)), cpu.mean((0, 1)), rtol=0.05)


@pytest.mark.parametrize("scene_name", ["material_zoo", "twosided-pair", "anisotropy"])
def test_gpu_shading_steps_give_the_megakernels_image_and_gbuffer(scene_name, device, monkeypatch):
    """On GPUs process_hit and sample_bsdf run in steps that rebuild the surface after a store (the kept shading
    normal, the G-buffer at the end, light sampling in two steps through the shadow ray's slots; docs/gpu.md, "The
    shading stages in steps"): the megakernel's image and G-buffer bit for bit, with bump maps and textures (the
    zoo), two-sided materials with a back (the normal that picks the side is the kept one) and anisotropic frames
    (no normal kept: the surface rebuilt whole), over several bounces (and the AoS path state with the zoo, whose steps
    keep the most state); and the CPU's single-pass stages' image and G-buffer on the same binary BVH."""
    from pathlib import Path

    data = Path(__file__).parent / "data"
    scene = material_zoo(16) if scene_name == "material_zoo" else pyclpt.load(data / f"{scene_name}.xml")
    kw = dict(spp=2, max_depth=6, width=20, height=16, seed=7, device=device, aovs=True)
    monkeypatch.setattr(bvh_mod, "DEFAULT_SETTINGS", bvh_mod.BuildSettings(width=2))
    cpu, cpu_aovs = pyclpt.render(scene, integrator="wavefront", **kw)
    monkeypatch.setenv(CLASS_ENV, "gpu")
    mega, mega_aovs = pyclpt.render(scene, integrator="megakernel", **kw)
    assert mega.max() > 0
    np.testing.assert_array_equal(mega, cpu)
    for name in cpu_aovs:
        np.testing.assert_array_equal(mega_aovs[name], cpu_aovs[name], err_msg=f"CPU {name}")
    for layout in ("soa", "aos") if scene_name == "material_zoo" else ("soa",):
        wave, wave_aovs = pyclpt.render(scene, integrator="wavefront", layout=layout, **kw)
        np.testing.assert_array_equal(wave, mega)
        assert wave_aovs.keys() == mega_aovs.keys()
        for name in mega_aovs:
            np.testing.assert_array_equal(wave_aovs[name], mega_aovs[name], err_msg=f"{layout} {name}")


def test_gpu_layout_instanced_scene(monkeypatch):
    """Two-level traversal with the node-only stacks (bottom and top level): the flattened scene's image within
    noise, megakernel == wavefront."""
    from test_instances import _scene

    from pyclpt.scene.mitsuba_dict import load_dict

    monkeypatch.setenv(CLASS_ENV, "gpu")
    scene = load_dict(_scene(2))
    assert pack_scene(scene, "gpu").defines["BVH_WIDTH"] == 2
    a = pyclpt.render(scene, spp=8, seed=1)
    b = pyclpt.render(scene.flattened(), spp=8, seed=1)
    assert _relmse(a, b) < 2e-3
    np.testing.assert_array_equal(pyclpt.render(scene, spp=1, seed=5, integrator="wavefront"),
                                  pyclpt.render(scene, spp=1, seed=5))


TRAVERSAL = r"""
#include "scene/bvh.h"
__kernel void trace_closest(__global const float* nodes, __global const float* tris, __global const float* org,
                            __global const float* dir, float tmax, __global float* out_t, __global int* out_prim) {
    int i = get_global_id(0);
    Hit h;
    bool ok = bvh_closest(nodes, tris, load3(org, i), load3(dir, i), tmax, &h);
    out_t[i] = h.t;
    out_prim[i] = ok ? h.prim : -1;
}
__kernel void trace_any(__global const float* nodes, __global const float* tris, __global const float* org,
                        __global const float* dir, float tmax, __global int* out_any) {
    int i = get_global_id(0);
    out_any[i] = bvh_any(nodes, tris, load3(org, i), load3(dir, i), tmax) ? 1 : 0;
}
"""


def _trace(device, defines: dict, bvh: FlatBVH, org, dirs, tmax):
    import pyopencl as cl

    prog = build_program(device, source=TRAVERSAL, name="test_gpu_layout_trace", defines=defines)
    mf = cl.mem_flags
    n = len(org)

    def ro(a):
        return cl.Buffer(device.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a))

    t, prim, anyhit = np.empty(n, np.float32), np.empty(n, np.int32), np.empty(n, np.int32)
    bufs = [cl.Buffer(device.context, mf.WRITE_ONLY, a.nbytes) for a in (t, prim, anyhit)]
    ins = [ro(bvh.nodes), ro(bvh.tris), ro(org), ro(dirs)]
    cl.Kernel(prog, "trace_closest")(device.queue, (n,), None, *ins, np.float32(tmax), *bufs[:2])
    cl.Kernel(prog, "trace_any")(device.queue, (n,), None, *ins, np.float32(tmax), bufs[2])
    for a, b in zip((t, prim, anyhit), bufs):
        cl.enqueue_copy(device.queue, a, b)
    device.queue.finish()
    return t, np.where(prim >= 0, bvh.tri_order[np.maximum(prim, 0)], -1), anyhit.astype(bool)


def test_node_only_stack_finds_the_closest_hits(device):
    """The GPU traversal (binary, node-only stack) against the binary traversal with distances on the same
    tree and against the CPU layout (8 wide, leaf packets), on a soup of overlapping triangles, unbounded and
    with a finite tmax: the same hit or miss and the same t (ties aside: tests/test_bvh.py's tolerances for
    node widths), any-hit agreeing with closest-hit."""
    rng = np.random.default_rng(3)
    v0 = rng.random((3000, 3)) * 10
    pos = np.concatenate([v0, v0 + rng.normal(scale=0.6, size=(3000, 3)),
                          v0 + rng.normal(scale=0.6, size=(3000, 3))]).astype(np.float32)
    idx = np.arange(9000).reshape(3, 3000).T.copy()
    bvh = build_bvh(pos, idx, use_cache=False, settings=layout_settings("gpu"))
    wide = build_bvh(pos, idx, use_cache=False, settings=layout_settings("cpu"))
    packed = FlatBVH(nodes=leaf_packet_buffer(wide), tris=wide.tris, tri_order=wide.tri_order, build_seconds=0.0)
    n = 20000
    org = (rng.random((n, 3)) * 14 - 2).astype(np.float32)
    d = rng.normal(size=(n, 3))
    dirs = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    for tmax in (np.inf, 3.0):
        t, tri, anyhit = _trace(device, {"BVH_WIDTH": 2, "BVH_STACK_DISTANCES": 0}, bvh, org, dirs, tmax)
        np.testing.assert_array_equal(anyhit, tri >= 0)
        for defines, tree in [({"BVH_WIDTH": 2}, bvh), ({"BVH_WIDTH": 8, "BVH_LEAF_PACKETS": True}, packed)]:
            ref_t, ref_tri, _ = _trace(device, defines, tree, org, dirs, tmax)
            assert 0.05 < np.mean(ref_tri >= 0) < 0.95
            with np.errstate(invalid="ignore"):
                close = (t == ref_t) | (np.abs(t - ref_t) <= 2 * np.spacing(np.abs(ref_t)))
            assert np.mean(close & ((tri >= 0) == (ref_tri >= 0))) >= 0.999, defines
            assert np.mean((t == ref_t) & (tri == ref_tri)) >= 0.98, defines


def test_gpu_compaction_gives_the_same_queues(device, monkeypatch):
    """The GPU class compacts with a work-group per block (-DCOMPACT_GROUP): over several blocks of 1024 entries
    (a 96x64 image: 6 blocks) and every bounce, its queues are the one-work-item compaction's, so the
    wavefront's per-bounce counts equal the megakernel-checked CPU compaction's and the image is the
    megakernel's bit for bit."""
    from pyclpt.integrators.wavefront import COMPACT_BLOCK, COMPACT_GROUP
    from pyclpt.rendering.renderer import Renderer

    scene = material_zoo(8)
    size = dict(width=96, height=64, max_depth=6, device=device)
    assert 96 * 64 > 4 * COMPACT_BLOCK and COMPACT_BLOCK % COMPACT_GROUP == 0
    monkeypatch.setenv(CLASS_ENV, "gpu")
    wave = Renderer(scene, integrator="wavefront", tail_paths=0, **size)
    assert wave.integrator.compact_group == COMPACT_GROUP
    image = wave.render(1, seed=4)
    mega = Renderer(scene, integrator="megakernel", **size).render(1, seed=4)
    np.testing.assert_array_equal(image, mega)
    from pyclpt.integrators import wavefront as wavefront_mod

    monkeypatch.setattr(wavefront_mod, "COMPACT_GROUP", 0)  # the GPU layout with the CPU's compaction
    single = Renderer(scene, integrator="wavefront", tail_paths=0, **size)
    assert single.integrator.compact_group == 0
    np.testing.assert_array_equal(single.render(1, seed=4), image)
    assert wave.stats.bounces == single.stats.bounces  # the same queues, bounce by bounce


def test_gpu_diagnostics_run_on_any_device(device, tmp_path):
    """bench/gpu/diagnostics.py (docs/gpu.md, "Measured on an NVIDIA H200") measures launch costs, the
    wavefront's variants and the driver's program binaries on whatever device runs it; on PoCL its binaries are
    no PTX, so ptxas is not asked."""
    from bench.gpu import diagnostics as gd

    costs = gd.launch_costs(device, n=40)
    assert set(costs) == {"profiling", "plain"}
    assert all(v > 0 for row in costs.values() for v in row.values())
    rows = gd.variants("cornell-box", 8, 8, depths=(2,), frames=1)
    assert [(r["integrator"], r["options"]) for r in rows] == list(gd.VARIANTS)
    assert all(r["wall_ms"] > 0 and r["device_ms"] > 0 for r in rows)
    assert {r["wave"] for r in rows if r["options"].get("wave_size")} == {64 * 8 * 8}  # the 8x8 film's batch
    ptx = gd.driver_ptx("cornell-box", tmp_path)
    assert {r["kernel"] for r in ptx} == {"megakernel", *STAGES}
    assert all((tmp_path / "cornell-box" / f"{r['kernel']}.ptx").stat().st_size > 0 for r in ptx)


def test_register_cap_only_where_nvidia_takes_it(device):
    """-cl-nv-maxrregcount=64 for the megakernel, finish_paths and the two shading stages on a driver with
    cl_nv_compiler_options (docs/gpu.md, "Register caps"); nothing for other programs, CPUs or other GPUs, so
    CPU programs keep their options (and PoCL's kernel cache its entries)."""
    from types import SimpleNamespace

    from pyclpt.device.program import NV_REGISTER_CAP, REGISTER_CAPPED, register_cap_options

    nvidia = SimpleNamespace(is_cpu=False, has_nv_compiler_options=True)
    other_gpu = SimpleNamespace(is_cpu=False, has_nv_compiler_options=False)
    assert set(REGISTER_CAPPED) == {"megakernel", "finish_paths", "process_hit", "sample_bsdf"}
    for name in REGISTER_CAPPED:
        assert register_cap_options(nvidia, name) == [f"-cl-nv-maxrregcount={NV_REGISTER_CAP}"]
        assert register_cap_options(other_gpu, name) == [] and register_cap_options(device, name) == []
    for name in ("intersect", "shadow_test", "path_init", "compact_scatter", "accumulate_frame"):
        assert register_cap_options(nvidia, name) == []
    assert not device.has_nv_compiler_options
