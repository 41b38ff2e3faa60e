"""``pyclpt warmup``: after it, a first render in a fresh process compiles nothing.

Both commands run as subprocesses with caches of their own (``XDG_CACHE_HOME``: PoCL's kernel cache,
pyopencl's binary cache; ``POCL_CACHE_DIR``; ``PYCLPT_CACHE_DIR``), so the developer's caches neither
help nor suffer; the device is the suite's (PoCL, tests/conftest.py). What the drivers compiled is
read off those folders: the render must add no file but PoCL's empty lock/temp files.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from pyclpt.rendering.warmup import VARIANTS, variants, warm_up

REPO = Path(__file__).resolve().parent.parent


def _env(tmp_path: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    env["POCL_CACHE_DIR"] = str(tmp_path / "xdg" / "pocl" / "kcache")
    env["PYCLPT_CACHE_DIR"] = str(tmp_path / "pyclpt")
    return env


def _compiled(root: Path) -> set[str]:
    """The drivers' cache entries under ``root`` (PoCL's temporary files left out)."""
    return {str(p.relative_to(root)) for p in root.rglob("*") if p.is_file() and not p.name.startswith("tempfile")}


def _pyclpt(tmp_path: Path, *args: str) -> str:
    proc = subprocess.run([sys.executable, "-m", "pyclpt", *args], capture_output=True, text=True, timeout=120,
                          env=_env(tmp_path), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def test_warmup_then_a_first_render_compiles_nothing(tmp_path):
    out = _pyclpt(tmp_path, "warmup", "--scenes", "cornell-box")
    assert re.search(r"cornell-box megakernel: \d+ programs \(\d+ new\), compile [\d.]+ s", out), out
    assert "warmed up 1 scene variant in" in out
    cache = tmp_path / "xdg"
    before = _compiled(cache)
    assert any(name.endswith(".so") for name in before), "PoCL compiled nothing: is its cache elsewhere?"
    # the README's first command (fewer samples): the scene's own resolution, as the warm-up rendered it
    out = _pyclpt(tmp_path, "render", "cornell-box", "--spp", "2", "--quiet", "-o", str(tmp_path / "box.png"))
    assert re.search(r"compile [\d.]+ s", out), out
    assert _compiled(cache) - before == set(), "the render compiled what the warm-up did not"


def test_warmup_variants():
    assert variants() == ["megakernel"]
    assert variants(wavefront=True) == ["megakernel", "wavefront"]
    assert variants(all_variants=True) == list(VARIANTS)
    with pytest.raises(ValueError, match="unknown warm-up variant 'gpu'"):
        warm_up(["cornell-box"], variant_names=["gpu"])


def test_warmup_help_lists_the_options():
    from pyclpt.cli import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    text = sub.choices["warmup"].format_help()
    for option in ("--scenes", "--device", "--wavefront", "--all"):
        assert option in text
