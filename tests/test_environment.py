"""pyclpt's environment variables (pyclpt.common.env): every bad value is an error or a warning
that names the variable and its value; an unusable cache folder turns caching off (one warning)."""
from __future__ import annotations

import logging
import os
import re
import uuid
from pathlib import Path

import numpy as np
import pytest

import pyclpt
import pyclpt.bench
from pyclpt.accel.bvh import build_bvh
from pyclpt.cli import main
from pyclpt.common import env
from pyclpt.common.cache import cache_dir, cache_path
from pyclpt.common.env import EnvironmentVariableError
from pyclpt.device.context import DeviceError, open_device
from pyclpt.device.program import build_program
from pyclpt.film.accumulator import Accumulator
from pyclpt.scene.library import scenes_root
from pyclpt.scene.mesh_io import load_mesh

PACKAGE = Path(pyclpt.__file__).resolve().parent
# bench/ is installed as pyclpt.bench; in an editable install it stays at the repository root
SOURCES = sorted({*PACKAGE.rglob("*.py"), *Path(pyclpt.bench.__file__).resolve().parent.rglob("*.py")})


def _warnings(caplog, needle: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING and needle in r.getMessage()]


def test_every_variable_is_read_through_env():
    """One module reads the environment, so that every variable is listed and checked in one place."""
    offenders = []
    for path in SOURCES:
        if path.name == "env.py" and path.parent.name == "common":
            continue
        for lineno, line in enumerate(path.read_text().splitlines(), 1):
            if re.search(r"os\.environ|os\.getenv|getenv\(", line):
                offenders.append(f"{path.parent.name}/{path.name}:{lineno}: {line.strip()}")
    assert not offenders, "read environment variables through pyclpt.common.env:\n" + "\n".join(offenders)
    names = set(re.findall(r'"(PYCLPT_[A-Z0-9_]+)"', "\n".join(p.read_text() for p in SOURCES)))
    assert names <= set(env.VARIABLES), names - set(env.VARIABLES)
    with pytest.raises(KeyError, match="PYCLPT_NOPE is not one of pyclpt's environment variables"):
        env.get("PYCLPT_NOPE")


def test_flags(monkeypatch):
    for value, expected in [("", False), ("0", False), ("off", False), ("No", False), ("1", True), (" TRUE ", True),
                            ("yes", True)]:
        monkeypatch.setenv("PYCLPT_EMULATE_FP64", value)
        assert env.flag("PYCLPT_EMULATE_FP64") is expected
    monkeypatch.delenv("PYCLPT_EMULATE_FP64")
    assert env.flag("PYCLPT_EMULATE_FP64") is False


def test_bad_flags_name_the_variable(device, monkeypatch):
    monkeypatch.setenv("PYCLPT_EMULATE_FP64", "maybe")
    with pytest.raises(EnvironmentVariableError, match=r"PYCLPT_EMULATE_FP64='maybe': expected one of 1, true"):
        Accumulator(device, 4, 3, precision="double")
    monkeypatch.setenv("PYCLPT_BVH_PY_BOUNDS", "2")
    with pytest.raises(EnvironmentVariableError, match=r"PYCLPT_BVH_PY_BOUNDS='2'"):
        build_bvh(np.eye(3, dtype=np.float32), np.array([[0, 1, 2]]), use_cache=False)


def test_device_variable_naming_no_device(monkeypatch):
    monkeypatch.setenv("PYCLPT_DEVICE", "no-such-device-xyz")
    with pytest.raises(DeviceError, match=r"PYCLPT_DEVICE='no-such-device-xyz' \(the default device\): no OpenCL "
                                          r"device matches 'no-such-device-xyz'; found: .*set PYCLPT_DEVICE"):
        open_device(None)
    assert open_device("pocl").is_pocl  # an explicit selector does not read the variable


def test_scenes_variable_naming_a_missing_folder(tmp_path, monkeypatch, caplog):
    missing = tmp_path / "no-such-folder"
    monkeypatch.setenv("PYCLPT_SCENES", str(missing))
    with caplog.at_level(logging.WARNING):
        assert scenes_root() == missing
        assert scenes_root() == missing
    (warning,) = _warnings(caplog, "PYCLPT_SCENES")
    assert f"PYCLPT_SCENES={str(missing)!r}: no such folder" in warning
    with pytest.raises(FileNotFoundError, match="PYCLPT_SCENES"):
        pyclpt.load("cornell-bunny")


def test_dump_kernels_variable_naming_an_unusable_place(device, tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    source = f"/* {uuid.uuid4()} */ __kernel void k(__global float* a) {{ a[0] = 1.0f; }}\n"
    for bad in (blocker, blocker / "sub"):
        monkeypatch.setenv("PYCLPT_DUMP_KERNELS", str(bad))
        with pytest.raises(EnvironmentVariableError, match=rf"PYCLPT_DUMP_KERNELS={re.escape(repr(str(bad)))}: "
                                                           r"cannot create the folder"):
            build_program(device, source=source, name="dump-test.cl")
    if os.geteuid() != 0:  # root writes anywhere
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        monkeypatch.setenv("PYCLPT_DUMP_KERNELS", str(locked))
        with pytest.raises(EnvironmentVariableError, match="PYCLPT_DUMP_KERNELS=.*not writable"):
            build_program(device, source=source, name="dump-test.cl")


OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n"


@pytest.mark.parametrize("kind", ["a file", "inside a file"])
def test_unusable_cache_folder_turns_caching_off_with_one_warning(device, tmp_path, monkeypatch, caplog, capsys,
                                                                   kind):
    """It used to make every render fail ([Errno 20] Not a directory: '.../bvh'), naming no variable."""
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    bad = blocker if kind == "a file" else blocker / "cache"
    monkeypatch.setenv("PYCLPT_CACHE_DIR", str(bad))
    (tmp_path / "tri.obj").write_text(OBJ)
    with caplog.at_level(logging.WARNING):
        assert cache_dir("bvh") is None and cache_path("mesh", "0" * 40) is None
        image = pyclpt.render("cornell-box", spp=1, width=8, height=6, device=device)  # the BVH cache
        mesh = load_mesh(tmp_path / "tri.obj")  # the mesh cache
        assert load_mesh(tmp_path / "tri.obj").indices.shape == mesh.indices.shape == (2, 3)
        assert main(["render", "cornell-box", "--spp", "1", "--width", "8", "--height", "6", "--quiet",
                     "-o", str(tmp_path / "out.exr")]) == 0
    assert image.shape == (6, 8, 3) and (tmp_path / "out.exr").is_file()
    (warning,) = _warnings(caplog, "PYCLPT_CACHE_DIR")
    assert f"PYCLPT_CACHE_DIR={str(bad)!r} cannot be used as the cache folder" in warning
    assert "caching of meshes and BVHs is off" in warning and "\n" not in warning
    assert [m for m in _warnings(caplog, "cache") if "PYCLPT_CACHE_DIR" not in m] == []


def test_usable_cache_folder_is_made_on_demand(tmp_path, monkeypatch):
    monkeypatch.setenv("PYCLPT_CACHE_DIR", str(tmp_path / "new" / "cache"))
    path = cache_path("bvh", "abc")
    assert path == tmp_path / "new" / "cache" / "bvh" / "abc.npz" and path.parent.is_dir()
    build_bvh(np.eye(3, dtype=np.float32), np.array([[0, 1, 2]]))
    assert len(list(path.parent.glob("*.npz"))) == 1
