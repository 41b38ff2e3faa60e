"""The installed package carries its OpenCL sources and built-in scenes: rendering works
from another directory, with the source tree out of sight (skipped when pyclpt is not
installed in this Python, e.g. when the tests run from a checkout through PYTHONPATH)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

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
    if pkg == REPO / "pyclpt":
        pytest.skip("pyclpt is installed in editable mode from this checkout")
    assert (pkg / "cl" / "integrators" / "megakernel.cl").is_file()
    assert (pkg / "scenes" / "cornell-box.json").is_file()
    out = run("import pyclpt, numpy as np; "
              "img = pyclpt.render('cornell-box', spp=1, width=8, height=8, progress=False); "
              "assert img.shape == (8, 8, 3) and np.isfinite(img).all() and img.max() > 0", tmp_path)
    assert out.returncode == 0, out.stderr
