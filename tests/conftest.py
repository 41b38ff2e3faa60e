"""Shared fixtures: one OpenCL device (PoCL) and its compiled programs for the whole session,
a private cache folder, and the shared scene folder when it exists."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

# Caches (meshes, BVHs) go to a folder of this test session, never the user's.
os.environ.setdefault("PYCLPT_CACHE_DIR", tempfile.mkdtemp(prefix="pyclpt-test-cache-"))

import pyclpt  # noqa: E402
from pyclpt.scene.library import scenes_root  # noqa: E402


@pytest.fixture(scope="session")
def device() -> pyclpt.Device:
    return pyclpt.default_device()


@pytest.fixture(scope="session")
def shared_scenes() -> Path:
    root = scenes_root()
    if root is None or not root.is_dir():
        pytest.skip("the shared scene folder (PYCLPT_SCENES, ../shared/scenes) is not available")
    return root


@pytest.fixture(scope="session")
def cornell_box() -> pyclpt.Scene:
    return pyclpt.load("cornell-box")
