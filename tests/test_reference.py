"""The documentation site builds, and its API reference covers the public API (issue 27 item 2).

``docs/conf.py`` builds the guide pages (docs/**/*.md, through myst-parser) and the API reference
(``docs/api.rst``: autodoc + napoleon from the docstrings) into one HTML site. Here it is built as CI
builds it, ``sphinx-build -W --keep-going -b html docs OUT``: any warning (a broken docstring, a page
outside the table of contents, a bad directive) fails, and all of them are reported at once. Then:

- every name of ``pyclpt.__all__`` is an object of the site's inventory (``objects.inv``) and an
  anchor of the API page, so a name added to the API without an entry in docs/api.rst fails;
- every public name, and every public method and property of a public class (or of the public
  module ``pyclpt.optim``), has a docstring of its own (autodoc silently leaves out members without
  one, so the build alone does not catch a missing docstring).

The build takes about 7 s on two cores (serial: ``-j auto`` is not faster for this site). It needs
the ``docs`` extra (``pip install ".[docs]"``, also in ``test``); without Sphinx the build tests skip.
"""
from __future__ import annotations

import configparser
import dataclasses
import inspect
import re
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

import pyclpt

REPO = Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"
BUILD_TIMEOUT_S = 300


def public_objects() -> dict[str, object]:
    return {name: getattr(pyclpt, name) for name in pyclpt.__all__}


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The HTML site, built with warnings as errors (fails the test with Sphinx's warnings)."""
    pytest.importorskip("sphinx", reason='the API reference needs Sphinx: pip install ".[docs]"')
    pytest.importorskip("myst_parser", reason='the guide pages need myst-parser: pip install ".[docs]"')
    out = tmp_path_factory.mktemp("site")
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
           "-d", str(out / ".doctrees"), str(DOCS), str(out / "html")]
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=BUILD_TIMEOUT_S)
    if done.returncode:
        pytest.fail(f"sphinx-build -W failed (exit {done.returncode}):\n{done.stderr}{done.stdout[-4000:]}",
                    pytrace=False)
    return out / "html"


def inventory(path: Path) -> dict[str, str]:
    """``objects.inv`` (format version 2: four header lines, then zlib-compressed lines
    ``name domain:role priority uri dispname``) as {name: domain:role}, for the Python domain."""
    data = path.read_bytes()
    header_end = 0
    for _ in range(4):
        header_end = data.index(b"\n", header_end) + 1
    assert data.startswith(b"# Sphinx inventory version 2"), data[:header_end]
    entries = {}
    for line in zlib.decompress(data[header_end:]).decode().splitlines():
        name, role = line.split(" ", 2)[:2]
        if role.startswith("py:"):
            entries[name] = role
    return entries


def test_the_site_builds_without_warnings(site: Path) -> None:
    for page in ("index.html", "api.html", "getting-started.html"):
        assert (site / page).is_file(), f"{page} was not built"


def test_every_public_name_is_in_the_reference(site: Path) -> None:
    documented = inventory(site / "objects.inv")
    api_html = (site / "api.html").read_text(encoding="utf-8")
    missing = []
    for name, obj in public_objects().items():
        if f"pyclpt.{name}" in documented and f'id="pyclpt.{name}"' in api_html:
            continue
        # a module (pyclpt.optim) is documented under the name it is imported from
        if inspect.ismodule(obj) and obj.__name__ in documented and f'id="module-{obj.__name__}"' in api_html:
            continue
        missing.append(name)
    assert not missing, ("public names (pyclpt.__all__) missing from the API reference; add them to "
                         f"docs/api.rst: {', '.join(missing)}")


def own_docstring(obj: object) -> str | None:
    """The object's own docstring: not the one a dataclass generates from its signature."""
    doc = obj.__dict__.get("__doc__") if inspect.isclass(obj) else getattr(obj, "__doc__", None)
    if inspect.isclass(obj) and dataclasses.is_dataclass(obj) and doc and doc.startswith(f"{obj.__name__}("):
        return None
    return doc.strip() if doc and doc.strip() else None


def public_members(cls: type) -> dict[str, object]:
    """Methods and properties a class defines itself (not inherited), whose names have no underscore."""
    members = {}
    for name, value in vars(cls).items():
        if name.startswith("_"):
            continue
        if isinstance(value, property):
            members[name] = value
        elif isinstance(value, (staticmethod, classmethod)):
            members[name] = value.__func__
        elif inspect.isfunction(value):
            members[name] = value
    return members


def test_public_names_and_their_members_have_docstrings() -> None:
    missing = []
    for name, obj in public_objects().items():
        if own_docstring(obj) is None:
            missing.append(f"pyclpt.{name}")
        if inspect.ismodule(obj):
            contents = {n: getattr(obj, n) for n in getattr(obj, "__all__", dir(obj)) if not n.startswith("_")}
            classes = [v for v in contents.values() if inspect.isclass(v) and v.__module__ == obj.__name__]
            functions = [v for v in contents.values() if inspect.isfunction(v) and v.__module__ == obj.__name__]
            missing += [f"{obj.__name__}.{v.__name__}" for v in classes + functions if own_docstring(v) is None]
            owners = [(f"{obj.__name__}.{c.__name__}", c) for c in classes]
        else:
            owners = [(f"pyclpt.{name}", obj)] if inspect.isclass(obj) else []
        for where, cls in owners:
            missing += [f"{where}.{m}" for m, v in public_members(cls).items() if own_docstring(v) is None]
    assert not missing, "public names without a docstring (the API reference would leave them out):\n" + \
        "\n".join(missing)


def test_inventory_parser_reads_a_sphinx_inventory(tmp_path: Path) -> None:
    body = "pyclpt.Renderer py:class 1 api.html#$ -\npyclpt.gradients.optim py:module 0 api.html#module-$ -\n"
    path = tmp_path / "objects.inv"
    path.write_bytes(b"# Sphinx inventory version 2\n# Project: pyclpt\n# Version: 0\n"
                     b"# The remainder of this file is compressed using zlib.\n" + zlib.compress(body.encode()))
    assert inventory(path) == {"pyclpt.Renderer": "py:class", "pyclpt.gradients.optim": "py:module"}



def test_the_docs_extra_and_the_test_extra_bring_sphinx() -> None:
    """``pip install ".[docs]"`` (README) builds the site, and CI's ``.[test]`` runs this module."""
    cfg = configparser.ConfigParser()
    cfg.read(REPO / "setup.cfg")
    extras = cfg["options.extras_require"]
    for extra in ("docs", "test"):
        names = {re.split(r"[<>=!~;\[ ]", r.strip(), maxsplit=1)[0] for r in extras[extra].splitlines()
                 if r.strip() and not r.strip().startswith("#")}
        assert {"sphinx", "myst-parser"} <= names, f"the {extra!r} extra lacks sphinx or myst-parser: {names}"
