"""Per-kernel timing from OpenCL profiling events (launches, total, mean, share)."""
from __future__ import annotations

from dataclasses import dataclass, field

import pyopencl as cl


@dataclass
class KernelProfile:
    events: dict[str, list[cl.Event]] = field(default_factory=dict)
    sequence: list[str] = field(default_factory=list)  # kernel names in launch order
    enabled: bool = True

    def record(self, name: str, event: cl.Event) -> None:
        if self.enabled:
            self.events.setdefault(name, []).append(event)
            self.sequence.append(name)

    def clear(self) -> None:
        self.events.clear()
        self.sequence.clear()

    def table(self) -> list[dict[str, float | int | str]]:
        """One row per kernel: launches, total_ms, mean_ms, share (of all kernels' time)."""
        rows = []
        for name, evs in self.events.items():
            total = sum((e.profile.end - e.profile.start) for e in evs) * 1e-6
            rows.append({"kernel": name, "launches": len(evs), "total_ms": total,
                         "mean_ms": total / max(len(evs), 1)})
        grand = sum(r["total_ms"] for r in rows) or 1.0
        for r in rows:
            r["share"] = r["total_ms"] / grand
        return rows
