"""Sphinx configuration of pyclpt's documentation site: the guide pages (docs/*.md, through
myst-parser) and the API reference (docs/api.rst, autodoc + napoleon from the docstrings).

Build it with ``pip install ".[docs]" && sphinx-build docs docs/_build``; tests/test_reference.py
builds it with warnings as errors, so a broken docstring fails the test suite.
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # a checkout without `pip install` documents its own sources

import pyclpt  # noqa: E402

project = "pyclpt"
author = "the pyclpt authors"
copyright = "the pyclpt authors, MIT licence"  # noqa: A001 (Sphinx's name)
release = version = pyclpt.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "myst_parser",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "**/.ipynb_checkpoints"]

# -- autodoc / napoleon -------------------------------------------------------------------------------
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
# members with a docstring of their own; base classes only for the exceptions (docs/api.rst)
autodoc_default_options = {"members": True}
napoleon_google_docstring = True
napoleon_numpy_docstring = True
napoleon_use_rtype = False

# Napoleon reads the first line of an attribute's or a property's docstring as Google's
# "type: description", but pyclpt's are prose that often starts "X: ..." ("CL_DEVICE_GLOBAL_MEM_SIZE: all
# the buffers...", "Reprojection: a previous pixel..."), and their types come from the annotations. So
# those docstrings are kept as written: saved before napoleon (priority 500) and put back after it.
_PROSE_KINDS = {"attribute", "property", "data"}
_saved_docstrings: dict[int, list[str]] = {}


def _save_prose_docstring(app, what, name, obj, options, lines) -> None:
    if what in _PROSE_KINDS:
        _saved_docstrings[id(lines)] = list(lines)


def _restore_prose_docstring(app, what, name, obj, options, lines) -> None:
    saved = _saved_docstrings.pop(id(lines), None)
    if saved is not None:
        lines[:] = saved


def setup(app) -> None:
    app.connect("autodoc-process-docstring", _save_prose_docstring, priority=400)
    app.connect("autodoc-process-docstring", _restore_prose_docstring, priority=600)


# -- myst (the guide pages) ---------------------------------------------------------------------------
# GitHub-style anchors for headings, so the pages' `page.md#heading` links resolve as on GitHub.
myst_heading_anchors = 6

# The guide pages are written for GitHub and may link to files outside docs/ (getting-started.md links
# ../README.md), which are not documents of this site: myst warns "Unknown source document" with the
# target as an absolute path (or one starting with ../). Only those are ignored, so a broken link
# between the site's own pages still fails the build; tests/test_docs.py checks that every relative
# link, inside docs/ or not, resolves on GitHub.
nitpick_ignore_regex = [("myst", r"(/|\.\./).*")]

# -- HTML ---------------------------------------------------------------------------------------------
html_theme = "alabaster"
html_title = f"pyclpt {release}"
html_copy_source = False  # no _sources/*.md.txt next to the pages
