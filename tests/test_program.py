"""Program assembly and building: includes, #line markers, build errors, defines, caching, dumps."""
from __future__ import annotations

import re

import numpy as np
import pyopencl as cl
import pytest

from pyclpt.device.program import KernelBuildError, assemble, build_program, cl_dir, compile_seconds, define_options


def _unique(tag: str) -> str:
    """A comment that makes a source text unique to one test, so that it is really built (not found in
    the device's in-process cache); fixed text, so PoCL's on-disk cache does not grow run after run."""
    return f"/* tests/test_program.py: {tag} */\n"


# -- assemble ------------------------------------------------------------------


def test_assemble_generated_include_exact_output():
    text = assemble(source='A\n#include "x.h"\nB\n#include "x.h"\nC\n', source_name="t.cl",
                    generated={"x.h": "X1\nX2\n"})
    assert text == (
        '#line 1 "t.cl"\n'
        "A\n"
        '#line 1 "<generated x.h>"\n'
        "X1\n"
        "X2\n"
        '#line 3 "t.cl"\n'
        "B\n"
        '#line 5 "t.cl"\n'  # the second include of x.h emits nothing but the marker
        "C\n"
    )


def test_assemble_again_after_a_file_changes(tmp_path, monkeypatch):
    """assemble() keeps its texts, but an edited source (or header) is read again."""
    import os

    import pyclpt.device.program as program

    monkeypatch.setattr(program, "cl_dir", lambda: tmp_path)
    (tmp_path / "k.cl").write_text('#include "h.h"\nK\n')
    (tmp_path / "h.h").write_text("H1\n")
    first = assemble(["k.cl"])
    assert "H1" in first and assemble(["k.cl"]) is first  # kept
    (tmp_path / "h.h").write_text("H2\n")
    st = (tmp_path / "h.h").stat()
    os.utime(tmp_path / "h.h", ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    again = assemble(["k.cl"])
    assert "H2" in again and "H1" not in again


def test_assemble_resolves_each_header_once_in_dependency_order():
    text = assemble(["integrators/megakernel.cl"])
    lines = text.splitlines()
    markers = [m.group(1) for m in (re.match(r'#line 1 "([^"]+)"$', ln) for ln in lines) if m]
    # every file starts exactly once
    assert len(markers) == len(set(markers)), markers
    assert markers[0] == "cl/integrators/megakernel.cl"
    for header in ("cl/core/common.h", "cl/integrators/path.h", "cl/scene/bsdf.h", "cl/core/sampling.h",
                   "cl/core/rng.h"):
        assert header in markers
    # common.h (included by everything) comes before the headers that include it
    assert markers.index("cl/core/common.h") < markers.index("cl/scene/bsdf.h")
    assert markers.index("cl/core/sampling.h") < markers.index("cl/scene/bsdf.h")
    # no include directive survives
    assert not any(re.match(r'\s*#\s*include\s+"', ln) for ln in lines)
    # the common.h body appears once
    assert text.count("#define PYCLPT_COMMON_H") == 1


def test_assemble_line_marker_after_include_points_at_next_line():
    text = assemble(["integrators/megakernel.cl"])
    src = (cl_dir() / "integrators/megakernel.cl").read_text().splitlines()
    inc_line = next(i for i, ln in enumerate(src, start=1) if re.match(r'\s*#\s*include\s+"', ln))
    assert f'#line {inc_line + 1} "cl/integrators/megakernel.cl"' in text.splitlines()


def test_assemble_shared_header_across_files_and_source():
    text = assemble(["core/common.h"], source='#include "core/common.h"\n#include "core/sampling.h"\nint x;\n')
    assert text.count("#define PYCLPT_COMMON_H") == 1
    assert text.count('#line 1 "cl/core/sampling.h"') == 1
    assert text.rstrip().endswith("int x;")


def test_assemble_missing_include_names_file_and_line():
    with pytest.raises(KernelBuildError, match=r'mine\.cl:2: cannot find include "nope\.h"'):
        assemble(source='int a;\n#include "nope.h"\n', source_name="mine.cl")


def test_assemble_missing_file():
    with pytest.raises(KernelBuildError, match="no_such_file.cl"):
        assemble(["no_such_file.cl"])


# -- build errors name the real file and line ------------------------------------


def test_build_error_in_source_names_file_and_line(device):
    src = _unique("bad") + "__kernel void k(__global float* a)\n{\n  a[0] = 1.0f +;\n}\n"
    # the unique comment is line 1, so the syntax error is on line 4
    with pytest.raises(KernelBuildError) as info:
        build_program(device, source=src, name="tests/bad.cl")
    msg = str(info.value)
    assert "bad.cl:4" in msg
    assert "tests/bad.cl" in msg


def test_build_error_in_generated_header_names_header(device):
    header = "float f(void) {\n  return 1.0f\n}\n"  # missing ';' on line 2
    src = _unique("gen") + '#include "x.h"\n__kernel void k(__global float* a) { a[0] = f(); }\n'
    with pytest.raises(KernelBuildError) as info:
        build_program(device, source=src, name="tests/uses_x.cl", generated={"x.h": header})
    assert "<generated x.h>:2" in str(info.value)


def test_build_error_in_cl_header_names_cl_header(device):
    # Break a function definition inside cl/core/common.h with a macro defined before the include.
    lines = (cl_dir() / "core/common.h").read_text().splitlines()
    lineno, fname = next((i, m.group(1)) for i, ln in enumerate(lines, start=1)
                         if (m := re.match(r"\s*static inline \w+ (\w+)\(", ln)))
    src = _unique("hdr") + f'#define {fname} 1 +\n#include "core/common.h"\n__kernel void k(__global float* a) {{}}\n'
    with pytest.raises(KernelBuildError) as info:
        build_program(device, source=src, name="tests/hdr.cl")
    assert f"cl/core/common.h:{lineno}" in str(info.value)


# -- defines ------------------------------------------------------------------------


def test_define_options():
    opts = define_options({"FLAG": True, "OFF": False, "NONE": None, "N": 3, "F": 1.5, "TINY": 1e-5})
    assert opts == ["-DF=1.5f", "-DFLAG", "-DN=3", "-DTINY=1e-05f"]
    assert define_options(None) == []
    assert define_options({"TWO": 2.0}) == ["-DTWO=2.0f"]


def test_defines_reach_the_kernel(device):
    src = _unique("defs") + (
        "__kernel void k(__global float* a) {\n"
        "#ifdef FLAG\n  a[0] = VAL * (float)N;\n#else\n  a[0] = -1.0f;\n#endif\n}\n")
    out = np.zeros(1, np.float32)
    buf = cl.Buffer(device.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    for defines, want in (({"FLAG": True, "VAL": 1.5, "N": 3}, 4.5), ({"FLAG": False, "VAL": 1.5, "N": 3}, -1.0)):
        prog = build_program(device, source=src, name="tests/defs.cl", defines=defines)
        prog.k(device.queue, (1,), None, buf)
        cl.enqueue_copy(device.queue, out, buf)
        assert out[0] == pytest.approx(want)


# -- caching, dumps, compile time -----------------------------------------------------


def test_program_cache_returns_same_object(device):
    src = _unique("cache") + "__kernel void k(__global float* a) { a[0] = X; }\n"
    a = build_program(device, source=src, defines={"X": 1.0})
    b = build_program(device, source=src, defines={"X": 1.0})
    c = build_program(device, source=src, defines={"X": 2.0})
    assert a is b
    assert c is not a


def test_compile_seconds_grows(device):
    before = compile_seconds()
    build_program(device, source=_unique("time") + "__kernel void k(__global int* a) { a[0] = 1; }\n")
    assert compile_seconds() > before
    # a cache hit costs no build time
    again = compile_seconds()
    src = _unique("time2") + "__kernel void k(__global int* a) { a[0] = 2; }\n"
    build_program(device, source=src)
    after_build = compile_seconds()
    assert after_build > again
    build_program(device, source=src)
    assert compile_seconds() == after_build


def test_dump_kernels_writes_assembled_source(device, tmp_path, monkeypatch):
    dump = tmp_path / "dump"
    monkeypatch.setenv("PYCLPT_DUMP_KERNELS", str(dump))
    marker = "dump-test-marker-7f3a"
    src = f"/* {marker} */\n" + '#include "core/common.h"\n__kernel void k(__global float* a) { a[0] = PI_F; }\n'
    build_program(device, source=src, name="tests/dumped.cl", defines={"SOMETHING": 3})
    files = list(dump.glob("dumped-*.cl"))
    assert len(files) == 1, list(dump.iterdir())
    text = files[0].read_text()
    assert text.startswith("// options: -cl-std=CL1.2")
    assert "-DSOMETHING=3" in text.splitlines()[0]
    assert marker in text
    assert '#line 1 "tests/dumped.cl"' in text
    assert '#line 1 "cl/core/common.h"' in text
    assert "#define PI_F" in text  # the header is inlined, not included
