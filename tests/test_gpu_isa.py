"""The GPU ISA check (pyclpt.gpu, docs/gpu.md): every program the renderer builds, over scenes that
switch on every material, light, texture, camera and instancing specialisation, compiles for NVIDIA
sm_90 and AMD gfx1030 and gfx90a; the reports are read right; the occupancy rule matches LLVM's; the
collection sees every program a real render builds. Needs clang, llvm and libclc (Debian's clang-15,
llvm-15, libclc-15) and ptxas (the gpu extra): skipped without them, failed under PYCLPT_REQUIRE_GPU_ISA=1."""
from __future__ import annotations

import numpy as np
import pytest

import pyclpt
from pyclpt.common import env
from pyclpt.device.context import open_device
from pyclpt.device.program import empty_kernels, record_programs
from pyclpt.gpu.check import check_programs
from pyclpt.gpu.collect import collect_programs, merge_specialisations
from pyclpt.gpu.isa import ToolchainMissing, compile_program, find_toolchain, parse_amdgcn, parse_ptxas
from pyclpt.gpu.report import SHADING_STAGES, budgets, markdown
from pyclpt.gpu.targets import TARGETS, occupancy, resident_slots
from pyclpt.rendering.renderer import Renderer
from scenes import material_zoo  # tests/ is on sys.path (conftest.py)

DATA = __import__("pathlib").Path(__file__).parent / "data"
# One scene a specialisation beyond the material zoo's (every material kind, textures, bump map, mask,
# point light, environment, area light): spot and directional lights, textured emitters, instances,
# the orthographic and thin-lens cameras, the sun and sky, anisotropic microfacets.
EXTRA_SCENES = ("delta-emitters", "emitter-textures", "instances", "orthographic", "thinlens", "sunsky", "anisotropy")
# Every kernel the renderer has (a new one must be added here and so to the check).
KERNELS = {"megakernel", "path_init", "intersect", "miss", "process_hit", "shadow_test", "light_contribution",
           "sample_bsdf", "compact_count", "compact_scatter", "finish_paths", "accumulate_frame", "accumulate_batch",
           "resolve", "aov_accumulate", "count_dropped", "demodulate", "reproject", "clip_history", "antilag",
           "variance", "atrous", "conserve", "conserve_gain", "modulate", "deficit", "deficit_gain", "light_change",
           "light_age", "blend",
           "backward", "forward", "edge_radiance", "path_vertices", "vertex_radiance", "delta_shadow_sides",
           "splat_axes", "splat_gather"}


@pytest.fixture(scope="module")
def toolchain():
    try:
        tc = find_toolchain()
        if tc.ptxas is None:
            raise ToolchainMissing("ptxas is missing: pip install 'pyclpt[gpu]'")
    except ToolchainMissing as exc:
        if env.flag("PYCLPT_REQUIRE_GPU_ISA"):
            pytest.fail(f"PYCLPT_REQUIRE_GPU_ISA=1 but {exc}", pytrace=False)
        pytest.skip(str(exc))
    return tc


@pytest.fixture(scope="module")
def report(toolchain):
    """Every variant of the box's programs; the zoo's that hold the most code; the other scenes' megakernel and
    gradient kernels, whose shading and traversal code is the stages' with the same defines. The zoo's and the
    other scenes' programs of one kernel are compiled with their specialisations switched on together
    (merge_specialisations: the kind masks OR-ed, the feature flags' union; the camera kinds apart), so every
    specialisation is compiled in less than half the programs; the box's keep the feature-free code."""
    box = collect_programs(["cornell-box"], device="pocl", every_variant=False)
    zoo = collect_programs([material_zoo(8)], device="pocl", every_variant=False, first_every=False)
    extra = collect_programs([str(DATA / f"{n}.xml") for n in EXTRA_SCENES], device="pocl", every_variant=False,
                             first_every=False, wavefront=False)
    # without the capped programs' second, uncapped ptxas run (reported by `pyclpt gpu-isa`, checked by no test)
    return check_programs(box + merge_specialisations(zoo + extra), toolchain=toolchain, uncapped=False)


def test_every_kernel_compiles_for_every_gpu_target(report):
    assert not report.failures, markdown(report)
    assert len(report.scenes) == 2 + len(EXTRA_SCENES)
    for t in TARGETS:
        assert {c.kernel for c in report.costs if c.target == t} == KERNELS, t
        assert report.compiled[t] > 0


def test_gpu_layout_meets_the_budgets(report):
    """The GPU layout's traversal (binary BVH, a 64-entry node stack, the texture lookup of masks inlined) on
    sm_90: at most 96 registers and 256 bytes of stack in every scene. The shading stages (process_hit and
    sample_bsdf in steps, built with NVIDIA's register cap of 64 as the driver builds them) at most 64 registers
    without spilling in every scene and variant, their stack at most the 16 bytes ptxas may keep around IEEE
    division's slow path under the cap, none on the Cornell box (docs/gpu.md, "The shading stages in steps"); no
    wavefront stage spills on gfx1030 in any scene."""
    traversal = [c for c in report.costs if c.target == "sm_90" and c.kernel in ("intersect", "shadow_test")]
    assert {s for c in traversal for s in c.scenes} >= {"cornell-box", "material-zoo"}
    assert [c for c in traversal if c.registers > 96 or c.stack > 256] == []
    shading = [c for c in report.costs if c.target == "sm_90" and c.kernel in SHADING_STAGES]
    assert {s for c in shading for s in c.scenes} >= {"cornell-box", "material-zoo"}
    assert {c.register_cap for c in shading if c.kernel in ("process_hit", "sample_bsdf")} == {64}
    assert [c for c in shading if c.registers > 64 or c.spills or c.stack > 16] == []
    assert [c for c in shading if "cornell-box" in c.scenes and c.stack] == []
    stages = {"path_init", "intersect", "miss", "process_hit", "shadow_test", "light_contribution", "sample_bsdf",
              "compact_count", "compact_scatter"}
    assert not [c for c in report.costs if c.target == "gfx1030" and c.kernel in stages and c.spills]
    assert "gfx1030 spills among the wavefront stages: none" in budgets(report)
    lines = [b for b in budgets(report) if b.startswith(("process_hit:", "sample_bsdf:"))]
    assert len(lines) == 2 and all(", cap 64 (budget 64 without spills: met" in b for b in lines), lines


def test_occupancy_agrees_with_llvm(report):
    amd = [c for c in report.costs if c.llvm_occupancy is not None]
    assert amd
    assert [(c.kernel, c.target, c.registers, c.slots) for c in amd if c.slots != c.llvm_occupancy] == []


def test_occupancy_rule():
    sm90, rdna2, cdna2 = TARGETS["sm_90"], TARGETS["gfx1030"], TARGETS["gfx90a"]
    # CUDA's occupancy calculator: 8-register granules per thread, the file split over 4 schedulers
    assert [resident_slots(sm90, r) for r in (32, 64, 96, 128, 170, 255)] == [64, 32, 20, 16, 8, 8]
    assert occupancy("sm_90", 64) == 0.5
    # RDNA2 wave32: 1024 VGPRs, granules of 16, at most 16 waves
    assert [resident_slots(rdna2, r) for r in (44, 62, 66, 241, 256)] == [16, 16, 12, 4, 4]
    # CDNA2 wave64: 512 VGPRs+AGPRs, granules of 8, at most 8 waves
    assert [resident_slots(cdna2, r) for r in (64, 72, 284)] == [8, 7, 1]
    with pytest.raises(ValueError, match="unknown GPU target 'sm_75'"):
        occupancy("sm_75", 32)


PTXAS = """ptxas info    : 0 bytes gmem
ptxas info    : Compiling entry function 'intersect' for 'sm_90'
ptxas info    : Function properties for intersect
    256 bytes stack frame, 8 bytes spill stores, 12 bytes spill loads
ptxas info    : Used 47 registers, used 0 barriers, 256 bytes cumulative stack size
ptxas info    : Compiling entry function 'miss' for 'sm_90'
ptxas info    : Function properties for miss
    0 bytes stack frame, 0 bytes spill stores, 0 bytes spill loads
ptxas info    : Used 17 registers, used 0 barriers
"""

AMDGCN = """\t.protected\tmiss ; -- Begin function miss
miss:
\ts_endpgm
\t.amdhsa_kernel miss
\t.end_amdhsa_kernel
; -- End function
; NumSgprs: 14
; NumVgprs: 11
; ScratchSize: 0
; Occupancy: 16
\t.protected\tintersect ; -- Begin function intersect
intersect:
\t.amdhsa_kernel intersect
; -- End function
; NumSgprs: 71
; NumVgprs: 241
; ScratchSize: 1540
; Occupancy: 4
amdhsa.kernels:
  - .args:
    .name:           miss
    .sgpr_spill_count: 0
    .vgpr_spill_count: 0
  - .args:
    .name:           intersect
    .sgpr_spill_count: 2
    .vgpr_spill_count: 5
"""


def test_reports_are_read_right():
    nv = {c.kernel: c for c in parse_ptxas(PTXAS, "p", TARGETS["sm_90"])}
    assert (nv["intersect"].registers, nv["intersect"].stack, nv["intersect"].spill_stores,
            nv["intersect"].spill_loads) == (47, 256, 8, 12)
    assert (nv["miss"].registers, nv["miss"].stack, nv["miss"].spills) == (17, 0, False)
    amd = {c.kernel: c for c in parse_amdgcn(AMDGCN, "p", TARGETS["gfx1030"])}
    assert (amd["intersect"].registers, amd["intersect"].sgprs, amd["intersect"].stack, amd["intersect"].spill_stores,
            amd["intersect"].llvm_occupancy, amd["intersect"].slots) == (241, 71, 1540, 7, 4, 4)
    assert (amd["miss"].registers, amd["miss"].spills, amd["miss"].slots) == (11, False, 16)


BROKEN = """static inline float twice(float x) { return 2.0f * x; }
__kernel void fine(__global float* a) { a[get_global_id(0)] = twice(a[0]); }
__kernel void broken(__global float* a) { a[0] = __builtin_ia32_rsqrtps((float4)(1.0f)).x; }
"""


@pytest.mark.parametrize("target", list(TARGETS))
def test_a_cpu_only_construct_fails_naming_program_and_target(toolchain, target):
    """An x86 builtin outside a -D guard (what the GPU rule forbids) fails the check for every target,
    with the program, the target and the compiler's message; the guarded program compiles."""
    from pyclpt.gpu.isa import IsaCompileError

    with pytest.raises(IsaCompileError, match=rf"(?s)zoo for {target}: clang-\d+ failed .*__builtin_ia32_rsqrtps"):
        compile_program(BROKEN, ["-cl-std=CL1.2"], target, program="zoo", toolchain=toolchain)
    fixed = BROKEN.replace("__builtin_ia32_rsqrtps((float4)(1.0f)).x", "1.0f")
    costs = compile_program(fixed, ["-cl-std=CL1.2"], target, program="zoo", toolchain=toolchain)
    assert {c.kernel for c in costs} == {"fine", "broken"}


# A kernel that holds many values at once: above NVIDIA's cap of 64 registers uncapped.
WIDE = """__kernel void wide(__global float* a) {
    float v[80];
    #pragma unroll
    for (int i = 0; i < 80; ++i) v[i] = a[get_global_id(0) * 80 + i];
    float s = 0.0f;
    #pragma unroll
    for (int i = 0; i < 80; ++i) s = s * v[i] + v[79 - i];
    #pragma unroll
    for (int i = 0; i < 80; ++i) a[get_global_id(0) * 80 + i] = v[i] * s;
}
"""


def test_capped_programs_are_assembled_under_the_drivers_cap(toolchain):
    """A program NVIDIA's driver builds under -cl-nv-maxrregcount (process_hit) is assembled with ptxas's
    --maxrregcount=64, and, unless the check is told to leave it out (the suite's fixture), once more without it for
    the registers it would take (uncapped_registers); another program is assembled once, uncapped."""
    from pyclpt.device.program import ProgramSource

    def check(label: str, uncapped: bool):
        report = check_programs([(ProgramSource(label, WIDE, ("-cl-std=CL1.2",)), ["t"])], ["sm_90"],
                                toolchain=toolchain, uncapped=uncapped)
        assert not report.failures, report.failures
        (cost,) = report.costs
        return cost

    capped = check("process_hit", True)
    assert (capped.register_cap, capped.registers) == (64, min(capped.registers, 64))
    assert capped.uncapped_registers is not None and capped.uncapped_registers > 64
    quick = check("process_hit", False)
    assert (quick.register_cap, quick.registers, quick.uncapped_registers) == (64, capped.registers, None)
    plain = check("zoo", True)
    assert (plain.register_cap, plain.uncapped_registers, plain.registers) == (None, None, capped.uncapped_registers)


def test_merged_specialisations_hold_every_scenes_code():
    """merge_specialisations: one kernel's programs that differ in kind masks and feature flags (the scene's and the
    gradients' kinds) become one, with the masks OR-ed and the flags' union, naming every scene; another camera kind,
    the rigid-geometry switch or other code stays apart."""
    from pyclpt.device.program import ProgramSource

    def p(label, *options, text="k"):
        return ProgramSource(label, text, ("-cl-std=CL1.2", *options))

    merged = merge_specialisations([
        (p("megakernel", "-DSCENE_HAS_TEXTURES", "-DSCENE_LIGHTS=5", "-DSCENE_MATERIALS=1"), ["a"]),
        (p("megakernel", "-DSCENE_HAS_INSTANCES", "-DSCENE_LIGHTS=48", "-DSCENE_MATERIALS=4"), ["b", "c"]),
        (p("megakernel", "-DSCENE_CAMERA=2", "-DSCENE_LIGHTS=1", "-DSCENE_MATERIALS=1"), ["d"]),
        (p("backward", "-DGRAD_COLOR=1", "-DSCENE_LIGHTS=2", "-DSCENE_MATERIALS=1"), ["a"]),
        (p("backward", "-DGRAD_INSTANCES=1", "-DSCENE_HAS_INSTANCES", "-DSCENE_LIGHTS=1", "-DSCENE_MATERIALS=1"),
         ["b"]),
        (p("backward", "-DGEO_NORMALS_FOLLOW_FACES=1", "-DGRAD_GEOMETRY=1", "-DSCENE_LIGHTS=1", "-DSCENE_MATERIALS=1"),
         ["f"]),
        (p("megakernel", "-DSCENE_LIGHTS=2", "-DSCENE_MATERIALS=8", text="other"), ["e"]),
    ])
    assert [(q.label, q.options, names) for q, names in merged] == [
        ("megakernel", ("-cl-std=CL1.2", "-DSCENE_HAS_INSTANCES", "-DSCENE_HAS_TEXTURES", "-DSCENE_LIGHTS=53",
                        "-DSCENE_MATERIALS=5"), ["a", "b", "c"]),
        ("megakernel", ("-cl-std=CL1.2", "-DSCENE_CAMERA=2", "-DSCENE_LIGHTS=1", "-DSCENE_MATERIALS=1"), ["d"]),
        ("backward", ("-cl-std=CL1.2", "-DGRAD_COLOR=1", "-DGRAD_INSTANCES=1", "-DSCENE_HAS_INSTANCES",
                      "-DSCENE_LIGHTS=3", "-DSCENE_MATERIALS=1"), ["a", "b"]),
        ("backward", ("-cl-std=CL1.2", "-DGEO_NORMALS_FOLLOW_FACES=1", "-DGRAD_GEOMETRY=1", "-DSCENE_LIGHTS=1",
                      "-DSCENE_MATERIALS=1"), ["f"]),
        ("megakernel", ("-cl-std=CL1.2", "-DSCENE_LIGHTS=2", "-DSCENE_MATERIALS=8"), ["e"]),
    ]


#: The stage-define check's values: the tuple a define's values cycle through when it is switched (None: not defined;
#: a name not here is a flag, defined or not), and three starting points: every feature on in the GPU class and in the
#: CPU class, and every feature off.
SWITCHED = {"SCENE_MATERIALS": (0xFF, 1), "SCENE_LIGHTS": (0x3F, 1), "SCENE_CAMERA": (None, 1, 2),
            "SCENE_FILTER": (None, 2, 1), "BVH_WIDTH": (2, 4, 8), "BVH_STACK_DISTANCES": (None, 0)}
ALL_ON = {"SCENE_HAS_INSTANCES": True, "SCENE_HAS_MASKS": True, "SCENE_HAS_BUMPMAPS": True, "SCENE_HAS_TEXTURES": True,
          "SCENE_HAS_ANISOTROPY": True, "SCENE_HAS_BACK_MATERIALS": True, "SCENE_HAS_EMITTER_TEXTURES": True,
          "AOVS": True, "FILM_CROP": True, "SCENE_MATERIALS": 0xFF, "SCENE_LIGHTS": 0x3F, "SCENE_CAMERA": 1,
          "SCENE_FILTER": 2}
STARTS = {"gpu": {**ALL_ON, "DEVICE_CLASS_GPU": True, "BVH_STACK_DISTANCES": 0, "BVH_WIDTH": 2},
          "cpu": {**ALL_ON, "BVH_LEAF_PACKETS": True, "BVH_WIDTH": 8},
          "off": {"BVH_LEAF_PACKETS": True, "BVH_WIDTH": 8, "SCENE_MATERIALS": 1, "SCENE_LIGHTS": 1}}
#: The kind masks' kinds (cl/scene/lights.h LIGHT_*, cl/scene/bsdfs/record.h MAT_*): a mask's code can hang on a
#: combination (lights.h's ENV_DEFERRED: an environment and no directional light), so a stage that does not read a
#: mask is also built with each kind alone: against every kind, that switches each kind on its own and each pair.
MASK_KINDS = {"SCENE_LIGHTS": 6, "SCENE_MATERIALS": 8}


def _switched(defines: dict, names) -> dict:
    out = dict(defines)
    for name in names:
        values = SWITCHED.get(name, (None, True))
        out[name] = values[(values.index(defines.get(name)) + 1) % len(values)]
    return out


def test_each_stage_is_built_with_the_defines_it_reads(toolchain, tmp_path):
    """STAGE_DEFINES (pyclpt/integrators/wavefront.py): switching every scene and film define a stage is built without
    (on or off, another value) leaves the front end's optimised code of the stage as it is, from every feature on in
    either device class and from every feature off, and so does each kind alone in the masks it does not read;
    switching the ones it reads changes it. So sharing a stage's program between scenes that differ
    only there gives each the code its own defines would."""
    from concurrent.futures import ThreadPoolExecutor

    from pyclpt.buffers.scene import SCENE_DEFINES
    from pyclpt.device.program import assemble, define_options
    from pyclpt.film.film import FILM_DEFINES
    from pyclpt.gpu.isa import front_end
    from pyclpt.gpu.targets import target
    from pyclpt.integrators.path_state import opencl_header
    from pyclpt.integrators.wavefront import STAGE_DEFINES

    known = SCENE_DEFINES + FILM_DEFINES
    assert set(SWITCHED) | set(ALL_ON) | {"DEVICE_CLASS_GPU", "BVH_LEAF_PACKETS"} == set(known)
    jobs = []
    for stage, reads in STAGE_DEFINES.items():
        unread = [n for n in known if n not in reads]
        if not unread:  # finish_paths: the whole path loop
            continue
        for start, defines in STARTS.items():
            jobs.append((stage, start, "as built", defines))
            jobs.append((stage, start, "unread switched", _switched(defines, unread)))
        if reads:
            jobs.append((stage, "gpu", "read switched", _switched(STARTS["gpu"], reads)))
        masks = [m for m in MASK_KINDS if m in unread]
        for k in range(max((MASK_KINDS[m] for m in masks), default=0)):
            alone = {m: 1 << (k % MASK_KINDS[m]) for m in masks}
            jobs.append((stage, "gpu", f"unread switched: kind {k} alone", {**STARTS["gpu"], **alone}))

    def code(job):
        stage, start, what, defines = job
        folder = tmp_path / f"{stage}-{start}-{''.join(c if c.isalnum() else '-' for c in what)}"
        folder.mkdir()
        text = assemble([f"integrators/wavefront/{stage}.cl"], generated={"path_state.h": opencl_header("soa")})
        return front_end(text, ["-cl-std=CL1.2", *define_options(defines)], target("sm_90"), toolchain, folder,
                         f"{stage} ({start}, {what})")

    with ThreadPoolExecutor() as pool:
        bitcode = {job[:3]: bc for job, bc in zip(jobs, pool.map(code, jobs))}
    assert len(jobs) > 60
    for (stage, start, what), bc in bitcode.items():
        built = bitcode[(stage, start, "as built")]
        if what.startswith("unread switched"):
            assert bc == built, f"{stage} reads a define it is built without ({start}, {what})"
        elif what == "read switched":
            assert bc != built, stage


def test_collection_sees_what_a_render_builds():
    """A real render's programs (megakernel, wavefront, G-buffer, accumulation) are among the collected ones
    for the device's own class: the dry collection does not miss a kernel a user builds."""
    scene = pyclpt.load("cornell-box")
    device = open_device("pocl")
    with record_programs() as built:
        for integrator in ("megakernel", "wavefront"):
            Renderer(scene, integrator=integrator, width=8, height=8, device=device, aovs=True).render(1)
    collected = {p.key for p, _ in collect_programs([scene], device="pocl", device_class=None)}
    assert built and {p.key for p in built} <= collected


def test_dry_builds_compute_nothing_and_stay_apart():
    """A dry record keeps the real programs out of the device's cache, and its kernels keep their
    parameters (their bodies emptied)."""
    text = "static inline int f(int x) { return x + 1; }\n__kernel void k(__global int* a, int n) { a[0] = f(n); }\n"
    assert empty_kernels(text).endswith("__kernel void k(__global int* a, int n) {}\n")
    scene = pyclpt.load("cornell-box")
    device = open_device("pocl")
    with record_programs(dry=True) as programs:
        r = Renderer(scene, width=4, height=4, device=device)
    assert {p.label for p in programs} >= {"megakernel", "accumulate", "count_dropped"}
    assert all(key[0] == "dry" for key in device.programs) and r.device is device
    # a renderer made after it on the same device compiles the real programs: the fresh device's image
    image = Renderer(scene, width=4, height=4, device=device).render(1, seed=3)
    fresh = Renderer(scene, width=4, height=4, device=open_device("pocl")).render(1, seed=3)
    np.testing.assert_array_equal(image, fresh)
    assert image.max() > 0


def test_the_command_writes_the_report(toolchain, tmp_path, monkeypatch, capsys):
    """`pyclpt gpu-isa`: the table on stdout, isa.json, isa.md and isa.png in the folder; exit 1 on a failure."""
    import pyclpt.gpu.collect as collect
    from pyclpt.cli import main
    from pyclpt.device.program import ProgramSource

    def programs(text):
        return lambda scenes, **kw: [(ProgramSource("zoo", text, ("-cl-std=CL1.2",)), ["tiny"])]

    monkeypatch.setattr(collect, "collect_programs", programs(BROKEN.replace("__builtin_ia32_rsqrtps((float4)(1.0f)).x",
                                                                             "1.0f")))
    assert main(["gpu-isa", "tiny", "--targets", "gfx1030", "-o", str(tmp_path)]) == 0
    assert "| fine | - |" in capsys.readouterr().out  # gfx1030 only: sm_90's column empty
    assert {p.name for p in tmp_path.iterdir()} == {"isa.json", "isa.md", "isa.png"}
    assert "| fine |" in (tmp_path / "isa.md").read_text()
    monkeypatch.setattr(collect, "collect_programs", programs(BROKEN))
    assert main(["gpu-isa", "tiny", "--targets", "sm_90", "-o", str(tmp_path)]) == 1
    assert "1 failures" in capsys.readouterr().out


def test_missing_tools_are_named(monkeypatch, capsys):
    import pyclpt.gpu.isa as isa
    from pyclpt.cli import main

    monkeypatch.setattr(isa.shutil, "which", lambda *a, **k: None)
    monkeypatch.setattr(isa, "LIBCLC_DIRS", ("/nonexistent",))
    with pytest.raises(ToolchainMissing, match="apt-get install clang-15 llvm-15 libclc-15"):
        find_toolchain()
    assert main(["gpu-isa", "cornell-box", "-o", "/tmp/never"]) == 1
    assert "pyclpt: error: the GPU ISA check needs libclc" in capsys.readouterr().err
