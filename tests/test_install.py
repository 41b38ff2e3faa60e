"""The installed package carries its OpenCL sources and built-in scenes: rendering works
from another directory (skipped when pyclpt is imported from a source checkout)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import pyclpt

REPO = Path(__file__).resolve().parent.parent


def test_installed_package_renders_from_another_directory(tmp_path):
    pkg = Path(pyclpt.__file__).resolve().parent
    if REPO in pkg.parents:
        pytest.skip("pyclpt is imported from the source tree, not installed")
    assert (pkg / "cl" / "megakernel.cl").is_file()
    assert (pkg / "scenes" / "cornell-box.json").is_file()
    code = (
        "import pyclpt, numpy as np; "
        "img = pyclpt.render('cornell-box', spp=1, width=8, height=8, progress=False); "
        "assert img.shape == (8, 8, 3) and np.isfinite(img).all() and img.max() > 0; "
        "print(pyclpt.__file__)"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    assert str(REPO) not in out.stdout
