"""The package layout: layers along the data flow, checked by import-linter's contract in setup.cfg;
each subpackage says what it holds and what it may import; cl/ mirrors the package; a wavefront
stage has one name for its .cl file, its kernel and the Python method that launches it; the
project's own code is ruff-clean."""
from __future__ import annotations

import configparser
import importlib
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import pyclpt
from pyclpt.device.program import cl_dir
from pyclpt.integrators.wavefront import STAGES, Wavefront

ROOT = Path(__file__).resolve().parent.parent
SETUP_CFG = ROOT / "setup.cfg"


def _layers() -> list[list[str]]:
    """The layers of the contract, top first; each a list of sibling names (optional ones unwrapped)."""
    cfg = configparser.ConfigParser()
    cfg.read(SETUP_CFG)
    text = cfg["importlinter:contract:layers"]["layers"]
    return [[name.strip().strip("()") for name in line.split("|")] for line in text.strip().splitlines()]


def _present(name: str) -> bool:
    try:
        importlib.import_module(f"pyclpt.{name}")
    except ModuleNotFoundError:
        return False
    return True


def test_import_contract_is_kept():
    pytest.importorskip("importlinter")
    # In a subprocess: import-linter disables the loggers that exist in its process.
    code = ("import sys; from importlinter.cli import lint_imports; "
            f"sys.exit(lint_imports(config_filename={str(SETUP_CFG)!r}))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "broken" in proc.stdout and "0 broken" in proc.stdout, proc.stdout


def test_contract_covers_every_subpackage():
    """A subpackage missing from the contract would escape the layer rules."""
    layered = {name for layer in _layers() for name in layer}
    package = Path(pyclpt.__file__).resolve().parent
    subpackages = {p.parent.name for p in package.glob("*/__init__.py")}
    subpackages -= {"cl", "scenes"}  # data, no Python
    assert subpackages, package
    assert subpackages <= layered, f"not in setup.cfg's layers: {sorted(subpackages - layered)}"


def test_layers_are_not_vacuous():
    """The contract is checked against real imports: the renderer does import the integrators and the
    scene buffers, which import the scene model, the BVH and the device layer."""
    grimp = pytest.importorskip("grimp")
    graph = grimp.build_graph("pyclpt")
    assert graph.direct_import_exists(importer="pyclpt.rendering.renderer",
                                      imported="pyclpt.integrators.megakernel")
    assert graph.direct_import_exists(importer="pyclpt.buffers.scene", imported="pyclpt.accel.bvh")
    assert graph.direct_import_exists(importer="pyclpt.integrators.megakernel", imported="pyclpt.device.program")
    # and nothing of the scene layer reaches OpenCL
    assert not graph.chain_exists(importer="pyclpt.scene.model", imported="pyclpt.device.context")


@pytest.mark.parametrize("name", [n for layer in _layers() for n in layer if n not in ("cli", "__main__")])
def test_subpackage_docstring_says_what_it_may_import(name):
    if not _present(name):
        pytest.skip(f"pyclpt.{name} has not landed yet (an optional layer)")
    module = importlib.import_module(f"pyclpt.{name}")
    doc = module.__doc__ or ""
    assert len(doc.split()) >= 15, f"pyclpt.{name} needs a docstring saying what it holds"
    assert "may import" in doc.lower() or "imports nothing" in doc.lower(), \
        f"pyclpt.{name}'s docstring must say which layers it may import"


def test_cl_tree_mirrors_the_package():
    root = cl_dir()
    for folder in ("core", "scene", "integrators", "integrators/wavefront", "film", "denoise", "gradients"):
        assert (root / folder).is_dir(), folder
    assert not list(root.glob("*.h")) and not list(root.glob("*.cl")), "sources belong in a subfolder of cl/"


def test_every_include_is_root_relative_and_exists():
    root = cl_dir()
    generated = {"path_state.h"}
    for src in list(root.rglob("*.h")) + list(root.rglob("*.cl")):
        for lineno, line in enumerate(src.read_text().splitlines(), 1):
            m = re.match(r'\s*#\s*include\s+"([^"]+)"', line)
            if m and m.group(1) not in generated:
                assert (root / m.group(1)).is_file(), f"{src.relative_to(root)}:{lineno}: {m.group(1)}"


@pytest.mark.parametrize("stage", STAGES)
def test_stage_has_one_name(stage):
    """The stage's .cl file, its kernel and the Python method that launches it share a name."""
    src = cl_dir() / "integrators" / "wavefront" / f"{stage}.cl"
    assert src.is_file()
    text = src.read_text()
    assert re.search(rf"__kernel\s+(?:SCALAR_KERNEL\s+)?void\s+{stage}\s*\(", text), f"{src}: no kernel named {stage}"
    assert "Consumes:" in text.split("*/")[0] and "Produces:" in text.split("*/")[0], \
        f"{src}: the header comment says what the kernel consumes and produces"
    assert callable(getattr(Wavefront, stage, None)), f"Wavefront.{stage}"


@pytest.mark.parametrize("src", sorted(p.name for p in (cl_dir() / "denoise").glob("*.cl")))
def test_denoiser_pass_has_one_name(src):
    """A denoiser pass: its .cl file under cl/denoise/, its kernel and the method of pyclpt.denoise's
    Svgf or Blend that launches it share a name."""
    from pyclpt.denoise.blend import Blend
    from pyclpt.denoise.svgf import Svgf

    name = src[:-3]
    text = (cl_dir() / "denoise" / src).read_text()
    assert re.search(rf"__kernel\s+void\s+{name}\s*\(", text), f"cl/denoise/{src}: no kernel named {name}"
    assert callable(getattr(Svgf, name, None)) or callable(getattr(Blend, name, None)), f"no Svgf/Blend.{name}"


@pytest.mark.parametrize("src", sorted(p.name for p in (cl_dir() / "gradients").glob("*.cl")))
def test_gradient_kernel_has_one_name(src):
    """A gradient kernel: its .cl file under cl/gradients/, its kernel and the PathReplay method that
    launches it share a name."""
    from pyclpt.gradients.replay import PathReplay

    name = src[:-3]
    text = (cl_dir() / "gradients" / src).read_text()
    assert re.search(rf"__kernel\s+(?:SCALAR_KERNEL\s+)?void\s+{name}\s*\(", text), f"cl/gradients/{src}"
    assert callable(getattr(PathReplay, name, None)), f"no PathReplay.{name}"


def test_kernel_files_say_what_they_consume_and_produce():
    for src in cl_dir().rglob("*.cl"):
        head = src.read_text().split("*/")[0]
        assert "Consumes:" in head and "Produces:" in head, src


def test_ruff_is_clean():
    ruff = shutil.which("ruff") or shutil.which("ruff", path=str(Path(sys.executable).parent))
    if ruff is None:
        pytest.skip("ruff is not installed (pip install '.[test]')")
    paths = [str(ROOT / p) for p in ("pyclpt", "bench", "tests") if (ROOT / p).is_dir()]
    proc = subprocess.run([ruff, "check", "--no-cache", *paths], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_bench_is_organised_by_question():
    """bench/ (issue 27, item 8): every script in a folder by kind of question, run as
    ``python -m bench.<folder>.<name>`` (none changes ``sys.path``); every study states its question, the
    answer and the doc that quotes its figure in its docstring's first paragraph; the report generator
    imports no other folder (it is the one installed)."""
    bench = ROOT / "bench"
    if not bench.is_dir():
        pytest.skip("no bench/ beside pyclpt/ (an installed package)")
    folders = {"report", "peers", "evaluations", "cluster", "timing", "gpu", "studies", "tools"}
    assert folders <= {p.name for p in bench.iterdir() if (p / "__init__.py").is_file()}
    assert {p.stem for p in bench.glob("*.py")} <= {"__init__"}
    for p in bench.rglob("*.py"):
        if p.parent != bench:
            assert "sys.path" not in p.read_text(), f"{p.relative_to(ROOT)} changes sys.path"
    for p in (bench / "report").glob("*.py"):
        assert not re.search(r"^\s*(from|import) bench\.(?!report)", p.read_text(), re.M), p
    for p in (bench / "studies").glob("[!_]*.py"):
        first = p.read_text().split('"""')[1].split("\n\n")[0]
        assert "?" in first and "docs/" in first, f"{p.relative_to(ROOT)}: question, answer, figure first"


def test_the_files_started_first_exist():
    """conftest.FIRST_FILES (handed to a pytest-xdist worker first) names test files that exist: a renamed file
    would silently lose its place at the front."""
    from conftest import FIRST_FILES

    here = Path(__file__).parent
    assert FIRST_FILES and all((here / name).is_file() for name in FIRST_FILES), FIRST_FILES
