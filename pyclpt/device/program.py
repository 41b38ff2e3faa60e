"""Assembling and building OpenCL programs from the sources in ``cl/``.

A program is assembled in Python: ``#include "x.h"`` lines are resolved from
``cl/`` (each header once, in dependency order) and every piece is preceded by
a ``#line`` directive, so a compiler message names the real file and line
(``cl/scene/bsdf.h:42``) although the device compiles one self-contained string. That
string is what PoCL's kernel cache hashes, so an unchanged program is loaded
from the cache instead of being compiled; ``PYCLPT_DUMP_KERNELS=DIR`` writes it
to ``DIR`` for inspection. Specialisations are ``-D`` options; on PoCL devices ``-DINLINE_MATH`` makes
cl/core/math.h map its functions to clang builtins that PoCL inlines (:func:`device_options`).

Build times are logged (logger ``pyclpt.device.program``) and kept apart from render
times: :func:`compile_seconds` reports the total spent building. A build that is not served from
the device's in-process cache, inside a :func:`compile_notice` block (a renderer's programs for a
scene), logs "compiling kernels for SCENE (first use, cached afterwards)…" if the block is still
running :data:`NOTICE_AFTER_S` later (logger ``pyclpt.notice``, INFO: the command line shows it).
"""
from __future__ import annotations

import hashlib
import logging
import re
import threading
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pyopencl as cl

from pyclpt.common import env
from pyclpt.common.logs import NOTICE_LOGGER
from pyclpt.device.context import Device
from pyclpt.device.vendors import VECTORIZER_ENV

log = logging.getLogger("pyclpt.device.program")
notice_log = logging.getLogger(NOTICE_LOGGER)

#: The compile message appears once programs have been compiling this long (seconds): a program
#: the drivers' caches hold builds in a fraction of it.
NOTICE_AFTER_S = 1.0
NOTICE = "compiling kernels for %s (first use, cached afterwards)…"

DUMP_ENV = "PYCLPT_DUMP_KERNELS"

_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$')


class KernelBuildError(RuntimeError):
    """An OpenCL program failed to build; the message holds the build log."""


def cl_dir() -> Path:
    """The folder of pyclpt's OpenCL sources (inside the installed package or the source tree)."""
    package = Path(__file__).resolve().parent.parent
    for candidate in (package / "cl", package.parent / "cl"):
        if (candidate / "core" / "common.h").is_file():
            return candidate
    raise FileNotFoundError(f"pyclpt's OpenCL sources (cl/core/common.h) are missing next to {package}")


def _display_name(path: Path) -> str:
    try:
        return f"cl/{path.relative_to(cl_dir()).as_posix()}"
    except ValueError:
        return path.as_posix()


# assemble()'s texts by their arguments, with the modification times of the files they read: a renderer
# made again (a tile, a scene change) reads and splices its sources once, not every time
_assembled: dict[tuple, tuple[str, dict[Path, int]]] = {}


def assemble(files: Sequence[str] = (), source: str | None = None, source_name: str = "<source>",
             generated: Mapping[str, str] | None = None) -> str:
    """Concatenate ``files`` (names under cl/) and ``source``, resolving includes, with #line markers.

    ``generated`` maps include names to text made by Python (e.g. the path-state accessors);
    such an include is emitted under the name ``<generated NAME>``. The text is made again when a
    file it read has changed since."""
    key = (str(cl_dir()), tuple(files), source, source_name, tuple(sorted((generated or {}).items())))
    hit = _assembled.get(key)
    if hit is not None and all(path.stat().st_mtime_ns == t for path, t in hit[1].items()):
        return hit[0]
    text, read = _assemble(files, source, source_name, generated)
    _assembled[key] = (text, {path: path.stat().st_mtime_ns for path in read})
    return text


def _assemble(files: Sequence[str], source: str | None, source_name: str,
              generated: Mapping[str, str] | None) -> tuple[str, set[Path]]:
    """assemble()'s text, and the files it read."""
    root = cl_dir()
    seen: set[Path] = set()
    seen_generated: set[str] = set()
    out: list[str] = []

    def emit(text: str, name: str, origin: Path | None) -> None:
        out.append(f'#line 1 "{name}"')
        for lineno, line in enumerate(text.splitlines(), start=1):
            m = _INCLUDE.match(line)
            if m and generated and m.group(1) in generated:
                if m.group(1) not in seen_generated:
                    seen_generated.add(m.group(1))
                    emit(generated[m.group(1)], f"<generated {m.group(1)}>", None)
                out.append(f'#line {lineno + 1} "{name}"')
            elif m:
                base = origin.parent if origin is not None else root
                inc = (base / m.group(1)).resolve()
                if not inc.is_file():
                    inc = (root / m.group(1)).resolve()
                if not inc.is_file():
                    raise KernelBuildError(f"{name}:{lineno}: cannot find include \"{m.group(1)}\" in {root}")
                if inc not in seen:
                    seen.add(inc)
                    emit(inc.read_text(), _display_name(inc), inc)
                out.append(f'#line {lineno + 1} "{name}"')
            else:
                out.append(line)

    for f in files:
        path = (root / f).resolve()
        if not path.is_file():
            raise KernelBuildError(f"no OpenCL source {f!r} in {root}")
        if path not in seen:
            seen.add(path)
            emit(path.read_text(), _display_name(path), path)
    if source is not None:
        emit(source, source_name, None)
    return "\n".join(out) + "\n", seen


def define_options(defines: Mapping[str, object] | None) -> list[str]:
    opts = []
    for key, value in sorted((defines or {}).items()):
        if value is True:
            opts.append(f"-D{key}")
        elif value is False or value is None:
            continue
        elif isinstance(value, float):
            opts.append(f"-D{key}={value!r}f")
        else:
            opts.append(f"-D{key}={value}")
    return opts


INLINE_MATH_DEFINE = "INLINE_MATH"


def device_options(device: Device) -> list[str]:
    """Options chosen by the device: PoCL gets ``-DINLINE_MATH`` (see cl/core/math.h). Intel's CPU
    runtime gets a define naming its vectorizer setting (``CL_CONFIG_USE_VECTORIZER``), so that
    pyopencl's binary cache, keyed by source and options, never hands back a binary compiled under
    another setting. Oclgrind (the simulator the tests check kernels with) gets ``-cl-opt-disable``: its
    interpreter cannot create some optimised kernels (``llvm.experimental.noalias.scope.decl``)."""
    if device.is_pocl:
        return [f"-D{INLINE_MATH_DEFINE}"]
    if getattr(device, "is_oclgrind", False):
        return ["-cl-opt-disable"]
    if device.is_intel_cpu:
        setting = re.sub(r"\W", "_", env.get(VECTORIZER_ENV) or "default")
        return [f"-DINTEL_VECTORIZER_{setting}"]
    return []


#: NVIDIA's register cap for the programs that hold a whole path (the megakernel, ``finish_paths``) or the BSDF
#: switch (``process_hit``, ``sample_bsdf``): measured on an H200 (docs/gpu.md, "Register caps"), 64 registers made
#: the megakernel 10-17% faster (device time; more resident warps for a few spills) and the shading stages no
#: slower, with the same images.
NV_REGISTER_CAP = 64
REGISTER_CAPPED = ("megakernel", "finish_paths", "process_hit", "sample_bsdf")


def register_cap_options(device: Device, program: str) -> list[str]:
    """``-cl-nv-maxrregcount=NV_REGISTER_CAP`` for the programs of REGISTER_CAPPED (by name) on a driver that takes
    NVIDIA's build options (``cl_nv_compiler_options``); nothing elsewhere."""
    if program not in REGISTER_CAPPED or device.is_cpu or not device.has_nv_compiler_options:
        return []
    return [f"-cl-nv-maxrregcount={NV_REGISTER_CAP}"]


@dataclass(frozen=True)
class ProgramSource:
    """One program as :func:`build_program` assembled it: its label (the .cl file's stem), the text and
    the build options. What :func:`record_programs` collects, and what pyclpt.gpu compiles for GPUs."""

    label: str
    text: str
    options: tuple[str, ...]

    @property
    def key(self) -> tuple[str, tuple[str, ...]]:
        return self.text, self.options


# the lists of the open record_programs() blocks, innermost last; and whether the innermost is dry
_recorders: list[tuple[list[ProgramSource], set, bool]] = []


@contextmanager
def record_programs(*, dry: bool = False) -> Iterator[list[ProgramSource]]:
    """Collect every program :func:`build_program` is asked for inside the block, once each, in order,
    whether it was compiled or served from the device's cache.

    ``dry``: the programs are not compiled as written. Each is built with its kernels' bodies emptied
    (:func:`empty_kernels`: the same kernels with the same parameters), so that renderers, films and
    denoisers can be made, and their kernels created and launched, in a fraction of the compile time,
    computing nothing. Such programs are kept apart from the device's cache, but objects made in a dry
    block must not be used after it: pyclpt.gpu makes them on a device of their own."""
    found: list[ProgramSource] = []
    _recorders.append((found, set(), dry))
    try:
        yield found
    finally:
        _recorders.pop()


# A kernel's head up to its parameter list, with its name (kernels return void).
KERNEL_HEAD = re.compile(r"__kernel\b[^;{]*?\bvoid\s+(\w+)\s*\(")


def kernel_names(text: str) -> set[str]:
    """The names of the ``__kernel`` functions of a program text."""
    return set(KERNEL_HEAD.findall(text))


def empty_kernels(text: str) -> str:
    """``text`` with the body of every ``__kernel`` function replaced by ``{}`` (the parameters kept),
    for :func:`record_programs`' dry builds. Braces inside comments are not expected in kernel bodies."""
    out, pos = [], 0
    for m in KERNEL_HEAD.finditer(text):
        if m.start() < pos:
            continue
        open_brace = text.find("{", m.end())
        if open_brace < 0:
            break
        depth, i = 0, open_brace
        while i < len(text):
            depth += {"{": 1, "}": -1}.get(text[i], 0)
            if depth == 0:
                break
            i += 1
        out.append(text[pos:open_brace] + "{}")
        pos = i + 1
    out.append(text[pos:])
    return "".join(out)


def _record(label: str, text: str, opts: list[str]) -> bool:
    """Note a requested program in the open record_programs() blocks; whether the innermost is dry."""
    for found, seen, _ in _recorders:
        key = (text, tuple(opts))
        if key not in seen:
            seen.add(key)
            found.append(ProgramSource(Path(label).stem, text, tuple(opts)))
    return bool(_recorders) and _recorders[-1][2]


_compile_seconds = 0.0

# This thread's open compile_notice() block: {"what": name, "timer": threading.Timer | None}.
_notice = threading.local()


@contextmanager
def compile_notice(what: str) -> Iterator[None]:
    """Programs built inside the block are built for ``what`` (a scene's name): once one of them is not
    in the device's in-process cache, a timer starts, and if the block is still open
    :data:`NOTICE_AFTER_S` later the compile message is logged, once (logger ``pyclpt.notice``, INFO).
    A block inside another adds nothing: the outer one speaks for both."""
    if getattr(_notice, "current", None) is not None:
        yield
        return
    state: dict = {"what": what, "timer": None}
    _notice.current = state
    try:
        yield
    finally:
        _notice.current = None
        if state["timer"] is not None:
            state["timer"].cancel()


def _start_notice(label: str) -> threading.Timer | None:
    """Start the compile message's timer for a build that is not a cache hit: the open block's (kept
    running until the block ends; None returned), or, outside any block, one for this build alone
    (returned, for the caller to cancel)."""
    state = getattr(_notice, "current", None)
    if state is not None and state["timer"] is not None:
        return None
    timer = threading.Timer(NOTICE_AFTER_S, notice_log.info, args=(NOTICE, label if state is None else state["what"]))
    timer.daemon = True
    timer.start()
    if state is not None:
        state["timer"] = timer
        return None
    return timer


def compile_seconds() -> float:
    """Total wall time this process has spent building OpenCL programs."""
    return _compile_seconds


def build_program(
    device: Device,
    files: Sequence[str] = (),
    *,
    source: str | None = None,
    defines: Mapping[str, object] | None = None,
    options: Iterable[str] = (),
    name: str | None = None,
    generated: Mapping[str, str] | None = None,
) -> cl.Program:
    """Build (or fetch from the device's in-process cache) a program from cl/ files and/or source text.

    No fast-math options are ever added here: callers pass the options they need.
    """
    global _compile_seconds
    text = assemble(files, source, source_name=name or "<source>", generated=generated)
    opts = ["-cl-std=CL1.2", *device_options(device), *define_options(defines), *options]
    label = name or (files[0] if files else "<source>")
    dry = _record(label, text, opts)
    if dry:
        text = empty_kernels(text)
    key = ("dry", text, tuple(opts)) if dry else (text, tuple(opts))
    prog = device.programs.get(key)
    if prog is not None:
        return prog
    out = None if dry else env.writable_folder(DUMP_ENV)
    if out is not None:
        digest = hashlib.sha1(repr(key).encode()).hexdigest()[:10]
        stem = re.sub(r"[^A-Za-z0-9_.-]", "_", Path(label).stem)
        try:
            (out / f"{stem}-{digest}.cl").write_text(f"// options: {' '.join(opts)}\n{text}")
        except OSError as exc:
            raise env.error(DUMP_ENV, f"cannot write {stem}-{digest}.cl there ({exc.strerror or exc})") from None
    start = time.perf_counter()
    timer = None if dry else _start_notice(label)
    try:
        prog = cl.Program(device.context, text).build(options=opts)
    except (cl.RuntimeError, cl.Error) as exc:
        # pyopencl's message carries the build log, whose lines name cl/ files through #line.
        raise KernelBuildError(f"OpenCL build of {label} failed on {device.name}:\n{exc}") from None
    finally:
        if timer is not None:
            timer.cancel()
    elapsed = time.perf_counter() - start
    _compile_seconds += elapsed
    log.info("built %s in %.2f s (%s)", label, elapsed, " ".join(opts))
    device.programs[key] = prog
    return prog
