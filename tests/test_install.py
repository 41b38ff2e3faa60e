"""What a user installs (issue 27): the package without extras renders in a fresh virtual environment
(matplotlib stays out of it, and ``pyclpt bench`` names the extra that brings it); the installed package
carries its OpenCL sources and built-in scenes, so rendering works from another directory (skipped when
pyclpt is not installed in this Python, e.g. when the tests run from a checkout through PYTHONPATH); the
licence ships; PoCL is required only where it has wheels, and a machine without any OpenCL driver gets an
error naming what to install; the cache folder is the platform's."""
from __future__ import annotations

import builtins
import configparser
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import platformdirs
import pyopencl as cl
import pytest

from pyclpt.cli import main
from pyclpt.common.cache import cache_root
from pyclpt.device import context
from pyclpt.device.context import DeviceError, install_hint

REPO = Path(__file__).resolve().parent.parent


def run(code: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300)


def test_installed_package_renders_from_another_directory(tmp_path):
    where = run("import pyclpt; print(pyclpt.__file__)", tmp_path)
    if where.returncode != 0:
        pytest.skip("pyclpt is not installed in this Python")
    pkg = Path(where.stdout.strip()).resolve().parent
    if (pkg.parent / "setup.cfg").is_file() and (pkg.parent / "cl").is_dir():  # this checkout or another one
        pytest.skip(f"pyclpt is installed in editable mode from the checkout {pkg.parent}")
    assert (pkg / "cl" / "integrators" / "megakernel.cl").is_file()
    assert (pkg / "scenes" / "cornell-box.json").is_file()
    out = run("import pyclpt, numpy as np; "
              "img = pyclpt.render('cornell-box', spp=1, width=8, height=8, progress=False); "
              "assert img.shape == (8, 8, 3) and np.isfinite(img).all() and img.max() > 0", tmp_path)
    assert out.returncode == 0, out.stderr


def _setup_cfg() -> configparser.ConfigParser:
    cfg = configparser.ConfigParser()
    cfg.read(REPO / "setup.cfg")
    return cfg


def _requirements(value: str) -> list[str]:
    return [line.strip() for line in value.splitlines() if line.strip() and not line.strip().startswith("#")]


def test_licence_is_mit_and_shipped():
    text = (REPO / "LICENSE").read_text()
    assert text.startswith("MIT License") and "Copyright (c) 2026 the pyclpt developers" in text
    meta = _setup_cfg()["metadata"]
    assert meta["license"] == "MIT"
    assert "LICENSE" in meta["license_files"].split()


def test_core_dependencies_are_lean():
    cfg = _setup_cfg()
    core = _requirements(cfg["options"]["install_requires"])
    assert not [r for r in core if r.startswith("matplotlib")], core
    assert any(r.startswith("platformdirs") for r in core), core
    (pocl,) = [r for r in core if r.startswith("pocl-binary-distribution")]
    assert pocl.split(";", 1)[1].strip() == 'platform_system == "Linux" and platform_machine == "x86_64"'
    extras = cfg["options.extras_require"]
    for extra in ("bench", "test"):
        assert any(r.startswith("matplotlib") for r in _requirements(extras[extra])), extra


@pytest.mark.parametrize("no_driver", ["raises", "empty"])
def test_no_opencl_platform_names_what_to_install(monkeypatch, no_driver):
    def raises():
        raise cl.LogicError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")

    monkeypatch.setattr(cl, "get_platforms", raises if no_driver == "raises" else list)
    monkeypatch.setattr(context, "_default", None)  # the default device is made afresh (and restored after)
    monkeypatch.delenv("PYCLPT_DEVICE", raising=False)
    with pytest.raises(DeviceError) as info:
        context.default_device()
    msg = str(info.value)
    assert "no OpenCL platform" in msg and context.INSTALL_HINT in msg
    assert context.INSTALL_HINT == install_hint()
    assert "Traceback" not in msg


def test_install_hint_names_pocl_on_linux_x86_64_and_a_vendor_driver_elsewhere():
    linux = install_hint("Linux", "x86_64")
    assert "pip install pocl-binary-distribution" in linux
    for system, machine in [("Darwin", "arm64"), ("Windows", "AMD64"), ("Linux", "aarch64")]:
        other = install_hint(system, machine)
        assert "pip install pocl-binary-distribution" not in other
        assert f"not for {system} {machine}" in other
        assert "OpenCL driver of your GPU's or CPU's vendor" in other and "ICD loader" in other
        assert "docs/devices.md" in other


def test_cache_folder_is_the_platforms_unless_pyclpt_cache_dir_is_set(monkeypatch, tmp_path):
    monkeypatch.setenv("PYCLPT_CACHE_DIR", str(tmp_path / "mine"))
    assert cache_root() == tmp_path / "mine"
    monkeypatch.delenv("PYCLPT_CACHE_DIR")
    assert cache_root() == Path(platformdirs.user_cache_dir("pyclpt"))
    if sys.platform.startswith("linux"):  # platformdirs follows the XDG variable: no hard-coded ~/.cache
        monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
        assert cache_root() == tmp_path / "xdg" / "pyclpt"


def test_bench_without_matplotlib_names_the_extra(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib raises ImportError
    assert main(["bench", "--quick"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("pyclpt: error: pyclpt bench draws its plots with matplotlib")
    assert 'pip install "pyclpt[bench]"' in err and "Traceback" not in err


def test_gpu_isa_plot_without_matplotlib_names_the_extra(monkeypatch):
    from pyclpt.gpu import report

    real_import = builtins.__import__

    def no_matplotlib(name, *args, **kwargs):
        if name == "matplotlib" or name.startswith("matplotlib."):
            raise ImportError(f"No module named {name!r}")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_matplotlib)
    with pytest.raises(ImportError, match=r'pip install "pyclpt\[gpu\]"'):
        report._matplotlib()


# -- a fresh virtual environment --------------------------------------------------------------------

COPY_IGNORE = shutil.ignore_patterns(".git", ".venv", "build", "dist", "*.egg-info", "__pycache__", ".pytest_cache",
                                     ".ruff_cache", "out", "*.exr", "*.png")


def _child_env(tmp_path: Path) -> dict[str, str]:
    """The environment of a user's fresh shell: none of this test run's Python or OpenCL settings."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYCLPT_DEVICE", "PYCLPT_DEVICE_CLASS", "OCL_ICD_VENDORS")}
    env["PYCLPT_CACHE_DIR"] = str(tmp_path / "cache")
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    return env


def _run(cmd: list, tmp_path: Path, timeout: float) -> subprocess.CompletedProcess:
    return subprocess.run([str(c) for c in cmd], cwd=tmp_path, env=_child_env(tmp_path), capture_output=True,
                          text=True, timeout=timeout)


@pytest.mark.slow
def test_fresh_venv_without_extras_renders(tmp_path):
    """``pip install .`` (no extras, not editable) into a new virtual environment, then the README's first
    command, small. pip's cache is warm in CI (README's test command installed the same dependencies)."""
    start = time.perf_counter()
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    bindir = venv / ("Scripts" if os.name == "nt" else "bin")
    python = bindir / "python"
    probe = _run([python, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "-d", tmp_path / "probe",
                  "numpy"], tmp_path, timeout=600)
    if probe.returncode != 0:
        pytest.skip(f"pip cannot download packages here (no network and no pip cache): {probe.stderr[-500:]}")
    src = tmp_path / "src"  # a clean copy: no stale build/ of the checkout can leak into the wheel
    shutil.copytree(REPO, src, ignore=COPY_IGNORE)
    # --no-compile: no .pyc files written for every installed module up front (pip ignores their errors
    # anyway); Python compiles what the commands below import, as it would after a plain install
    install = _run([python, "-m", "pip", "install", "--no-compile", src], tmp_path, timeout=1800)
    assert install.returncode == 0, install.stdout[-3000:] + install.stderr[-3000:]
    installed = time.perf_counter()

    no_mpl = _run([python, "-c", "import matplotlib"], tmp_path, timeout=120)
    assert no_mpl.returncode != 0 and "No module named 'matplotlib'" in no_mpl.stderr, no_mpl.stderr

    pyclpt = bindir / "pyclpt"
    render = _run([pyclpt, "render", "cornell-box", "--spp", "1", "--width", "16", "--height", "16", "-o", "x.png"],
                  tmp_path, timeout=900)
    assert render.returncode == 0, render.stdout + render.stderr
    image = _run([python, "-c", "import pyclpt; im = pyclpt.read_image('x.png'); print(im.shape, im.max())"],
                 tmp_path, timeout=300)
    assert image.returncode == 0, image.stderr
    shape, peak = image.stdout.split(")")
    assert shape.startswith("(16, 16") and float(peak) > 0, image.stdout

    bench = _run([pyclpt, "bench", "--quick"], tmp_path, timeout=300)
    assert bench.returncode == 1 and 'pip install "pyclpt[bench]"' in bench.stderr, bench.stdout + bench.stderr
    print(f"fresh venv: install {installed - start:.0f} s, checks {time.perf_counter() - installed:.0f} s")
