"""Compile pyclpt's OpenCL programs for GPU instruction sets, without a GPU, and read what each kernel costs.

The recipe (docs/gpu.md), for one program text and its build options:

* NVIDIA ``sm_90``: ``clang -x cl -target nvptx64-nvidia-nvcl -O3 -emit-llvm`` → ``llvm-link`` with libclc's
  ``nvptx64--nvidiacl.bc`` (``-only-needed``) → ``opt -O3`` → ``llc -march=nvptx64`` (PTX) →
  ``ptxas -arch=sm_90 -v``, whose report gives each kernel's registers, stack frame and spills.
* AMD ``gfx1030`` / ``gfx90a``: the same front end with ``-target amdgcn-amd-amdhsa -mcpu=...
  -nogpulib``, libclc's ``amdgcn--amdhsa.bc``, ``llc -march=amdgcn``; the assembly's comments and
  code-object metadata give VGPRs (and AGPRs), SGPRs, scratch, spills and LLVM's occupancy.

clang, llvm-link, opt, llc and libclc come from one LLVM release (Debian: ``clang-15 llvm-15
libclc-15``); ptxas from the CUDA toolkit or PyPI's ``nvidia-cuda-nvcc`` wheel (the ``gpu`` extra).
``-DINLINE_MATH`` (PoCL's inline math, cl/core/math.h) is dropped from the options: a GPU driver
never gets it. What differs on the real drivers: NVIDIA's OpenCL compiler is its own front end and
AMD's runtime its own LLVM; libclc stands in for their builtins (docs/gpu.md).
"""
from __future__ import annotations

import logging
import os
import re
import shutil
import subprocess
import sysconfig
import tempfile
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from pyclpt.device.program import NV_REGISTER_CAP, REGISTER_CAPPED, kernel_names
from pyclpt.gpu.targets import TARGETS, Target, occupancy, resident_slots, target

log = logging.getLogger("pyclpt.gpu.isa")

#: LLVM releases tried, newest first, for a complete set of versioned tools (clang-N, llvm-link-N, ...).
LLVM_VERSIONS = tuple(range(21, 14, -1))
#: Where libclc's bitcode libraries are looked for (Debian's libclc-N puts them in /usr/lib/clc).
LIBCLC_DIRS = ("/usr/lib/clc", "/usr/share/clc", "/usr/local/lib/clc")
#: Options that exist only for CPU runtimes and never reach a GPU driver.
CPU_ONLY_OPTIONS = ("-DINLINE_MATH",)
#: Seconds one tool may take on one program (the megakernel takes about one).
TOOL_TIMEOUT_S = 300


PTXAS_MISSING = ("the GPU ISA check for sm_90 needs ptxas: pip install 'pyclpt[gpu]' (PyPI's nvidia-cuda-nvcc) "
                 "or the CUDA toolkit")


class ToolchainMissing(RuntimeError):
    """A tool of the GPU ISA check is not installed; the message says which and how to get it."""


class IsaCompileError(RuntimeError):
    """A program failed to compile for a GPU target; the message names the program, target and tool."""


@dataclass(frozen=True)
class Toolchain:
    clang: str
    llvm_link: str
    opt: str
    llc: str
    libclc: Path
    ptxas: str | None  # None: the NVIDIA target cannot be assembled
    llvm_version: str

    def describe(self) -> str:
        return (f"LLVM {self.llvm_version} (clang {self.clang}, libclc {self.libclc}), "
                f"ptxas {self.ptxas or 'missing'}")


def _ptxas() -> str | None:
    """ptxas from PATH, the CUDA toolkit, or PyPI's nvidia-cuda-nvcc wheel (nvidia/*/bin/ptxas)."""
    found = shutil.which("ptxas") or shutil.which("ptxas", path="/usr/local/cuda/bin")
    if found:
        return found
    for root in {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}:
        for candidate in sorted(Path(root).glob("nvidia/*/bin/ptxas")):
            if os.access(candidate, os.X_OK):
                return str(candidate)
    return None


def find_toolchain() -> Toolchain:
    """The newest complete LLVM toolchain with libclc, and ptxas; :class:`ToolchainMissing` otherwise."""
    libclc = next((Path(d) for d in LIBCLC_DIRS if (Path(d) / "amdgcn--amdhsa.bc").is_file()), None)
    for v in LLVM_VERSIONS:
        tools = [shutil.which(f"{name}-{v}") for name in ("clang", "llvm-link", "opt", "llc")]
        if all(tools) and libclc is not None:
            return Toolchain(*tools, libclc=libclc, ptxas=_ptxas(), llvm_version=str(v))  # type: ignore[misc]
    missing = "libclc (amdgcn--amdhsa.bc in " + ", ".join(LIBCLC_DIRS) + ")" if libclc is None else \
        "a versioned clang/llvm-link/opt/llc set (clang-15 ... clang-21)"
    raise ToolchainMissing(f"the GPU ISA check needs {missing}: on Debian or Ubuntu, "
                           "apt-get install clang-15 llvm-15 libclc-15")


@dataclass(frozen=True)
class KernelCost:
    """What one kernel costs on one target."""

    program: str          # the program's label (its .cl file's stem)
    kernel: str
    target: str
    registers: int        # NVIDIA: registers per thread; AMD: VGPRs (+ AGPRs on gfx90a) per lane
    sgprs: int            # AMD scalar registers (0 on NVIDIA)
    stack: int            # bytes per thread: NVIDIA stack frame, AMD scratch
    spill_stores: int     # NVIDIA: bytes spilled; AMD: VGPRs + SGPRs spilled
    spill_loads: int
    slots: int            # resident warps per SM / waves per SIMD (targets.resident_slots)
    occupancy: float      # slots over the hardware's
    llvm_occupancy: int | None = None  # AMD: LLVM's own figure, for the cross-check
    scenes: tuple[str, ...] = ()   # scenes that build the program (pyclpt.gpu.check)
    options: tuple[str, ...] = ()  # its build options
    register_cap: int | None = None  # NVIDIA: the cap ptxas was given (register_cap: what the driver gets)
    uncapped_registers: int | None = None  # ... and the registers ptxas takes without it

    @property
    def spills(self) -> bool:
        return self.spill_stores > 0 or self.spill_loads > 0

    def as_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> KernelCost:
        return cls(**{**data, "scenes": tuple(data.get("scenes", ())), "options": tuple(data.get("options", ()))})


def gpu_options(options: list[str] | tuple[str, ...]) -> list[str]:
    """The build options a GPU driver would get: the CPU-only ones dropped."""
    return [o for o in options if o not in CPU_ONLY_OPTIONS]


def _run(cmd: list[str], what: str, cwd: Path | None = None) -> str:
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=TOOL_TIMEOUT_S, cwd=cwd)
    except subprocess.TimeoutExpired:
        raise IsaCompileError(f"{what}: {Path(cmd[0]).name} ran past {TOOL_TIMEOUT_S} s") from None
    if proc.returncode != 0:
        log_text = (proc.stderr or proc.stdout).strip()
        raise IsaCompileError(f"{what}: {Path(cmd[0]).name} failed (exit {proc.returncode}):\n{log_text}")
    return proc.stderr + proc.stdout


_PTXAS_ENTRY = re.compile(r"Compiling entry function '([^']+)'")
_PTXAS_PROPS = re.compile(r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads")
_PTXAS_USED = re.compile(r"Used (\d+) registers")


def parse_ptxas(report: str, program: str, t: Target) -> list[KernelCost]:
    """Per kernel, from ``ptxas -v``'s report: registers, stack frame and spills."""
    costs, name, props = [], None, (0, 0, 0)
    for line in report.splitlines():
        if m := _PTXAS_ENTRY.search(line):
            name, props = m.group(1), (0, 0, 0)
        elif (m := _PTXAS_PROPS.search(line)) and name:
            props = tuple(int(x) for x in m.groups())  # type: ignore[assignment]
        elif (m := _PTXAS_USED.search(line)) and name:
            regs = int(m.group(1))
            costs.append(KernelCost(program, name, t.name, regs, 0, props[0], props[1], props[2],
                                    resident_slots(t, regs), occupancy(t, regs)))
            name = None
    return costs


def _field(block: str, key: str) -> int:
    m = re.search(rf"^\s*;\s*{key}:\s*(\d+)", block, re.M)
    return int(m.group(1)) if m else 0


def parse_amdgcn(asm: str, program: str, t: Target) -> list[KernelCost]:
    """Per kernel, from llc's AMDGPU assembly: the comment block after each kernel's code (NumVgprs,
    NumAgprs, NumSgprs, ScratchSize, Occupancy) and the code object's spill counts."""
    kernels = re.findall(r"^\s*\.amdhsa_kernel\s+(\S+)", asm, re.M)
    spills: dict[str, tuple[int, int]] = {}
    for m in re.finditer(r"^\s*-\s*\.args:.*?(?=^\s*-\s*\.args:|\Z)", asm, re.M | re.S):
        meta = m.group(0)
        if name := re.search(r"^\s*\.name:\s*(\S+)", meta, re.M):
            sg = re.search(r"\.sgpr_spill_count:\s*(\d+)", meta)
            vg = re.search(r"\.vgpr_spill_count:\s*(\d+)", meta)
            spills[name.group(1)] = (int(sg.group(1)) if sg else 0, int(vg.group(1)) if vg else 0)
    costs = []
    for name in kernels:
        start = asm.find(f"-- Begin function {name}")
        end = asm.find("-- End function", start)
        block = asm[end:asm.find("-- Begin function", end) if asm.find("-- Begin function", end) >= 0 else len(asm)]
        total = _field(block, "TotalNumVgprs")
        vgprs = total or (_field(block, "NumVgprs") + _field(block, "NumAgprs"))
        sgpr_spill, vgpr_spill = spills.get(name, (0, 0))
        costs.append(KernelCost(program, name, t.name, vgprs, _field(block, "NumSgprs"), _field(block, "ScratchSize"),
                                vgpr_spill + sgpr_spill, vgpr_spill + sgpr_spill, resident_slots(t, vgprs),
                                occupancy(t, vgprs), _field(block, "Occupancy") or None))
    return costs


def front_end(text: str, options: list[str] | tuple[str, ...], t: Target, tc: Toolchain, folder: Path,
              what: str) -> bytes:
    """clang's OpenCL front end for ``t`` (at -O3, so that unused inline functions are gone): the module's
    bitcode, written to ``folder/k.bc`` and returned. The source is compiled as ``k.cl`` in ``folder``,
    so the same code gives the same bytes in any folder (what :mod:`pyclpt.gpu.check` deduplicates by)."""
    (folder / "k.cl").write_text(text)
    cmd = [tc.clang, "-x", "cl", *gpu_options(list(options)), "-Xclang", "-finclude-default-header",
           "-target", t.triple, "-O3", "-emit-llvm", "-c", "k.cl", "-o", "k.bc"]
    if t.vendor == "amd":
        cmd[1:1] = ["-nogpulib", f"-mcpu={t.name}"]
    _run(cmd, what, cwd=folder)
    return (folder / "k.bc").read_bytes()


def register_cap(program: str, t: Target) -> int | None:
    """The register cap the driver of ``t`` builds ``program`` (a .cl file's stem) with: NVIDIA's
    ``-cl-nv-maxrregcount`` for the programs of REGISTER_CAPPED (pyclpt.device.program.register_cap_options),
    which ptxas gets as ``--maxrregcount``; None elsewhere."""
    return NV_REGISTER_CAP if t.vendor == "nvidia" and program in REGISTER_CAPPED else None


def back_end(t: Target, tc: Toolchain, folder: Path, what: str, program: str, *,
             uncapped: bool = True) -> list[KernelCost]:
    """libclc linked in, optimised, code generated (and for NVIDIA assembled by ptxas, under the register cap
    the driver builds ``program`` with: register_cap) from ``folder/k.bc``: the cost of each kernel.
    ``uncapped``: for a capped program, also assemble it without the cap (KernelCost.uncapped_registers); the
    suite's check leaves that second ptxas run out (docs/testing.md)."""
    d = folder
    _run([tc.llvm_link, str(d / "k.bc"), str(tc.libclc / t.libclc), "-only-needed", "-o", str(d / "l.bc")], what)
    _run([tc.opt, "-O3", str(d / "l.bc"), "-o", str(d / "o.bc")], what)
    if t.vendor == "nvidia":
        _run([tc.llc, *t.llc_args, str(d / "o.bc"), "-o", str(d / "k.ptx")], what)
        cap = register_cap(program, t)

        def assemble(*options: str) -> list[KernelCost]:
            return parse_ptxas(_run([tc.ptxas, f"-arch={t.name}", "-v", *options, str(d / "k.ptx"), "-o",
                                     str(d / "k.cubin")], what), program, t)

        if cap is None:
            return assemble()
        free = {c.kernel: c.registers for c in assemble()} if uncapped else {}
        return [replace(c, register_cap=cap, uncapped_registers=free.get(c.kernel))
                for c in assemble(f"--maxrregcount={cap}")]
    _run([tc.llc, *t.llc_args, str(d / "o.bc"), "-o", str(d / "k.s")], what)
    return parse_amdgcn((d / "k.s").read_text(), program, t)


def check_kernels(costs: list[KernelCost], text: str, what: str) -> list[KernelCost]:
    """``costs``, after checking that they name exactly the program's kernels."""
    kernels = kernel_names(text)
    if kernels and {c.kernel for c in costs} != kernels:
        raise IsaCompileError(f"{what}: the report names kernels {sorted(c.kernel for c in costs)}, "
                              f"the source {sorted(kernels)}")
    return costs


def compile_program(text: str, options: list[str] | tuple[str, ...], t: Target | str, *,
                    program: str = "<source>", toolchain: Toolchain | None = None,
                    workdir: str | Path | None = None) -> list[KernelCost]:
    """Compile one assembled program (as pyclpt.device.program builds it) for target ``t``; the cost of
    each of its kernels. :class:`IsaCompileError` names the program, the target and the failing tool."""
    t = target(t) if isinstance(t, str) else t
    tc = toolchain or find_toolchain()
    if t.vendor == "nvidia" and tc.ptxas is None:
        raise ToolchainMissing(PTXAS_MISSING)
    what = f"{program} for {t.name}"
    with tempfile.TemporaryDirectory(prefix="pyclpt-isa-", dir=workdir) as tmp:
        front_end(text, options, t, tc, Path(tmp), what)
        return check_kernels(back_end(t, tc, Path(tmp), what, program), text, what)


def all_targets() -> list[Target]:
    return list(TARGETS.values())
