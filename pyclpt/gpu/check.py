"""The GPU ISA check: every program the renderer builds, compiled for every GPU target, and a table of
what each kernel costs (docs/gpu.md).

Every program goes through each target's front end; variants whose optimised bitcode is the same (a
define that a stage never reads, another scene with the same specialisation) are carried through the
rest of the recipe once. The rest are compiled in parallel,
one process per core. A failure is recorded with the program, the scenes that build it, the target
and the compiler's message, and the check goes on, so one report lists every failure.
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import tempfile
from collections.abc import Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from pyclpt.device.program import ProgramSource
from pyclpt.gpu.isa import (
    PTXAS_MISSING,
    IsaCompileError,
    KernelCost,
    Toolchain,
    ToolchainMissing,
    back_end,
    check_kernels,
    find_toolchain,
    front_end,
    gpu_options,
)
from pyclpt.gpu.targets import TARGETS, Target, target

log = logging.getLogger("pyclpt.gpu.check")


@dataclass
class Failure:
    program: str
    target: str
    scenes: list[str]
    options: list[str]
    message: str


@dataclass
class IsaReport:
    """Every kernel's cost on every target, for the programs of some scenes."""

    toolchain: str
    scenes: list[str]
    programs: int                 # distinct programs collected
    compiled: dict[str, int]      # target -> distinct (preprocessed) programs compiled for it
    costs: list[KernelCost] = field(default_factory=list)
    failures: list[Failure] = field(default_factory=list)

    def worst(self) -> dict[tuple[str, str], KernelCost]:
        """Per (kernel, target), the variant with the most registers (then the largest stack, then the most
        spilled bytes: under a register cap, the variants that reach it are told apart by what they spill)."""
        out: dict[tuple[str, str], KernelCost] = {}

        def size(c: KernelCost) -> tuple[int, int, int]:
            return c.registers, c.stack, c.spill_stores

        for c in self.costs:
            k = (c.kernel, c.target)
            if k not in out or size(c) > size(out[k]):
                out[k] = c
        return out

    def to_json(self) -> dict:
        return {"toolchain": self.toolchain, "scenes": self.scenes, "programs": self.programs,
                "compiled": self.compiled, "costs": [c.as_dict() for c in self.costs],
                "failures": [asdict(f) for f in self.failures]}

    @classmethod
    def from_json(cls, data: dict) -> IsaReport:
        return cls(data["toolchain"], data["scenes"], data["programs"], data["compiled"],
                   [KernelCost.from_dict(c) for c in data["costs"]], [Failure(**f) for f in data["failures"]])

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_json(), indent=1) + "\n")


def check_programs(programs: Sequence[tuple[ProgramSource, list[str]]], targets: Iterable[str | Target] = TARGETS,
                   *, jobs: int | None = None, toolchain: Toolchain | None = None,
                   uncapped: bool = True) -> IsaReport:
    """Compile ``programs`` (collect_programs' list) for ``targets``; an IsaReport of every kernel.

    Every program goes through the target's front end; programs whose optimised bitcode is the same
    (a define that a stage never reads, another scene with the same specialisation) are linked, code
    generated and assembled once. ``uncapped``: also assemble the programs NVIDIA's driver builds under a register
    cap without it (:func:`pyclpt.gpu.isa.back_end`)."""
    tc = toolchain or find_toolchain()
    ts = [target(t) if isinstance(t, str) else t for t in targets]
    if any(t.vendor == "nvidia" for t in ts) and tc.ptxas is None:
        raise ToolchainMissing(PTXAS_MISSING)
    jobs = jobs or os.cpu_count() or 1
    scenes = list(dict.fromkeys(s for _, names in programs for s in names))
    report = IsaReport(tc.describe(), scenes, len(programs), {t.name: 0 for t in ts})
    with tempfile.TemporaryDirectory(prefix="pyclpt-isa-") as tmp, ThreadPoolExecutor(jobs) as pool:
        root = Path(tmp)
        work = [(i, t) for t in ts for i in range(len(programs))]

        def folder(i: int, t: Target) -> Path:
            return root / f"{t.name}-{i}"

        def front(item: tuple[int, Target]) -> tuple[str | None, Failure | None]:
            i, t = item
            p, names = programs[i]
            folder(i, t).mkdir()
            try:
                bc = front_end(p.text, p.options, t, tc, folder(i, t), f"{p.label} for {t.name}")
                return hashlib.sha1(bc).hexdigest(), None
            except IsaCompileError as exc:
                return None, Failure(p.label, t.name, list(names), list(p.options), str(exc))

        unique: dict[tuple[str, str], tuple[int, Target]] = {}
        for (i, t), (digest, failure) in zip(work, pool.map(front, work)):
            if failure is not None:
                report.failures.append(failure)
            elif (t.name, digest) not in unique:
                unique[(t.name, digest)] = (i, t)

        def back(item: tuple[int, Target]) -> tuple[list[KernelCost], Failure | None]:
            i, t = item
            p, names = programs[i]
            what = f"{p.label} for {t.name}"
            try:
                costs = check_kernels(back_end(t, tc, folder(i, t), what, p.label, uncapped=uncapped), p.text, what)
                return [replace(c, scenes=tuple(names), options=tuple(gpu_options(p.options))) for c in costs], None
            except IsaCompileError as exc:
                return [], Failure(p.label, t.name, list(names), list(p.options), str(exc))

        for (_, t), (costs, failure) in zip(unique.values(), pool.map(back, unique.values())):
            report.compiled[t.name] += 1
            report.costs.extend(costs)
            if failure is not None:
                report.failures.append(failure)
    log.info("GPU ISA check: %d programs (%s after deduplication), %d kernels' costs, %d failures", len(programs),
             ", ".join(f"{n} for {t}" for t, n in report.compiled.items()), len(report.costs), len(report.failures))
    return report
