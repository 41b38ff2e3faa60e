"""PoCL's vectorizer remarks per kernel: what LLVM's loop vectorizer said about each kernel's work-item loop.

PoCL vectorizes a kernel across work-items by vectorizing the work-item loop it wraps around the kernel
body, and with ``POCL_VECTORIZER_REMARKS=1`` it prints LLVM's remarks on stdout while it compiles a
kernel, which happens at the kernel's first launch. :func:`collect` runs a render with every kernel's
first launch framed by markers and sorts the remarks by kernel. PoCL's kernel cache must be off
(``POCL_KERNEL_CACHE=0``), or nothing is compiled and nothing is said. Used by
``bench/timing/stage_profile.py remarks`` and ``bench/studies/inline_math.py remarks``.
"""
from __future__ import annotations

import os
import re
import sys
import threading
from collections import defaultdict
from collections.abc import Callable

import pyopencl as cl

_Kernel = cl.Kernel


class _MarkedKernel(_Kernel):
    """A kernel whose first launch (when PoCL compiles it) is framed by markers on stdout."""

    def __call__(self, *args, **kwargs):  # type: ignore[override]
        first = not getattr(self, "_marked", False)
        if first:
            os.write(1, f"\n@@KERNEL {self.function_name}\n".encode())
            self._marked = True
        ev = _Kernel.__call__(self, *args, **kwargs)
        if first:
            args[0].finish()  # PoCL compiles the work-group function when the launch runs
            os.write(1, b"\n@@KERNEL ?\n")
        return ev


def _is_remark(line: str) -> bool:
    return "vectoriz" in line and ("loop" in line or "cost-model" in line)


def collect(render: Callable[[], None]) -> dict[str, dict[str, int]]:
    """Run ``render`` (which must build and launch its kernels inside the call) and return, per kernel,
    each vectorizer remark (its first 160 characters) with its count."""
    read, write = os.pipe()
    sys.stdout.flush()
    saved = os.dup(1)  # PoCL prints LLVM's remarks on stdout: read them back through a pipe
    os.dup2(write, 1)
    os.close(write)
    chunks: list[bytes] = []

    def drain() -> None:
        while data := os.read(read, 1 << 16):
            chunks.append(data)

    reader = threading.Thread(target=drain)
    reader.start()
    cl.Kernel = _MarkedKernel  # type: ignore[misc]
    try:
        render()
    finally:
        cl.Kernel = _Kernel  # type: ignore[misc]
        os.dup2(saved, 1)
        os.close(saved)
        reader.join()
        os.close(read)
    text = b"".join(chunks).decode(errors="replace").replace("<unknown>:0:0: ", "\n")
    verdicts: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    kernel = "?"
    for line in text.splitlines():
        m = re.match(r"@@KERNEL (\w+)", line)
        if m:
            kernel = m.group(1)
        elif kernel != "?" and _is_remark(line):
            verdicts[kernel][line.strip()[:160]] += 1
    return {k: dict(v) for k, v in verdicts.items()}
