"""The GPU instruction sets pyclpt's kernels are checked against, and each one's occupancy rule.

A target is a compilation recipe (clang's OpenCL front end, libclc's builtins, LLVM's code generator,
and for NVIDIA the PTX assembler ``ptxas``) plus the documented register file of one architecture,
from which the theoretical occupancy of a kernel follows: how many warps (NVIDIA) or waves (AMD) of
it can be resident at once, as a fraction of the hardware's slots. More resident warps hide more
memory latency; that is the streaming paper's argument for small kernels (docs/gpu.md).

Sources of the numbers:

* ``sm_90`` (NVIDIA Hopper, H100): CUDA C++ Programming Guide, "Compute Capabilities" table for
  9.0: 64 K 32-bit registers per SM, at most 64 resident warps per SM, 255 registers per thread;
  CUDA's occupancy calculator: registers are allocated per warp in units of 256 (8 per thread), and
  the register file is split among the SM's 4 warp schedulers (16 K each).
* ``gfx1030`` (AMD RDNA2, RX 6800/6900): RDNA2 ISA guide and LLVM's AMDGPU backend
  (``AMDGPUBaseInfo``): wave32, 1024 VGPRs per SIMD lane-slice, allocated in granules of 16 in wave32
  mode on GFX10.3, at most 16 waves per SIMD.
* ``gfx90a`` (AMD CDNA2, MI200): CDNA2 ISA guide and LLVM's AMDGPU backend: wave64, a unified file of
  512 VGPRs + AGPRs per lane, allocated in granules of 8, at most 8 waves per SIMD.

LLVM prints its own occupancy for AMD kernels (``; Occupancy:``); :func:`occupancy` computes the same
from the register count, and the tests check that the two agree.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Target:
    """One GPU instruction set: how to compile for it, and its register file."""

    name: str             # "sm_90", "gfx1030", "gfx90a"
    vendor: str           # "nvidia" or "amd"
    architecture: str     # what the name stands for, for reports
    triple: str           # clang's target triple for the OpenCL front end
    libclc: str           # libclc's builtins library (a file in libclc's folder)
    llc_args: tuple[str, ...]  # llc's target options
    lanes: int            # threads a warp / lanes a wave
    registers: int        # registers per SM (NVIDIA: 32-bit registers) or VGPRs per lane (AMD)
    granule: int          # allocation granule: registers per thread (NVIDIA) or VGPRs per lane (AMD)
    max_slots: int        # resident warps per SM (NVIDIA) or waves per SIMD (AMD)
    partitions: int = 1   # the register file's slices (NVIDIA: one per warp scheduler)

    @property
    def slot_word(self) -> str:
        return "warps/SM" if self.vendor == "nvidia" else "waves/SIMD"


TARGETS: dict[str, Target] = {
    "sm_90": Target("sm_90", "nvidia", "NVIDIA Hopper (H100)", "nvptx64-nvidia-nvcl", "nvptx64--nvidiacl.bc",
                    ("-march=nvptx64", "-mcpu=sm_80", "-mattr=+ptx75"), lanes=32, registers=65536, granule=8,
                    max_slots=64, partitions=4),
    "gfx1030": Target("gfx1030", "amd", "AMD RDNA2 (RX 6800/6900)", "amdgcn-amd-amdhsa", "amdgcn--amdhsa.bc",
                      ("-march=amdgcn", "-mcpu=gfx1030"), lanes=32, registers=1024, granule=16, max_slots=16),
    "gfx90a": Target("gfx90a", "amd", "AMD CDNA2 (MI210/MI250)", "amdgcn-amd-amdhsa", "amdgcn--amdhsa.bc",
                     ("-march=amdgcn", "-mcpu=gfx90a"), lanes=64, registers=512, granule=8, max_slots=8),
}


def target(name: str) -> Target:
    """The target called ``name`` (a clear error naming the known ones otherwise)."""
    try:
        return TARGETS[name]
    except KeyError:
        raise ValueError(f"unknown GPU target {name!r}: expected one of {', '.join(TARGETS)}") from None


def _round_up(n: int, unit: int) -> int:
    return -(-n // unit) * unit


def resident_slots(t: Target, registers: int) -> int:
    """Warps per SM (NVIDIA) or waves per SIMD (AMD) that fit ``registers`` per thread / VGPRs per lane
    (AMD: VGPRs plus AGPRs), limited by the register file and the hardware's slots."""
    if registers <= 0:
        return t.max_slots
    per = _round_up(registers, t.granule)
    if t.vendor == "nvidia":
        per_warp = per * t.lanes
        fit = t.partitions * ((t.registers // t.partitions) // per_warp)
    else:
        fit = t.registers // per
    return max(0, min(t.max_slots, fit))


def occupancy(t: Target | str, registers: int) -> float:
    """Theoretical occupancy: resident warps/waves over the hardware's slots, 0..1."""
    t = target(t) if isinstance(t, str) else t
    return resident_slots(t, registers) / t.max_slots
