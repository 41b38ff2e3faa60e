"""Shared fixtures: one OpenCL device (PoCL) and its compiled programs for the whole session,
a private cache folder, and the shared scene folder when it exists.

``each_device`` parametrises a test over the devices it should pass on, as PyOpenCL's tests do:
PoCL and, when installed (``pip install ".[intel]"``), Intel's CPU OpenCL runtime. One context and
its compiled programs per device for the session (:func:`pyclpt.get_device` keeps them). Without
the runtime the Intel cases are skipped with the reason, unless ``PYCLPT_REQUIRE_INTEL=1`` (CI sets
it) makes them fail: a failed download cannot turn them off unseen."""
from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import pytest

# Caches (meshes, BVHs) go to a folder of this test session, never the user's: made by the process that starts the
# session (pytest-xdist's workers inherit it) and removed when that process ends (not a forked child's exit).
if "PYCLPT_CACHE_DIR" not in os.environ:
    os.environ["PYCLPT_CACHE_DIR"] = tempfile.mkdtemp(prefix="pyclpt-test-cache-")

    def _remove_cache(folder: str = os.environ["PYCLPT_CACHE_DIR"], owner: int = os.getpid()) -> None:
        if os.getpid() == owner:
            shutil.rmtree(folder, ignore_errors=True)

    atexit.register(_remove_cache)
# The session's device is PoCL (the default device is the fastest installed: Intel's CPU runtime where CI
# installs it); child processes (the CLI tests) inherit it. PYCLPT_DEVICE=intel runs the suite there.
os.environ.setdefault("PYCLPT_DEVICE", "pocl")

import pyclpt  # noqa: E402
from pyclpt.common import env  # noqa: E402
from pyclpt.device.context import DeviceError  # noqa: E402
from pyclpt.scene.library import scenes_root  # noqa: E402

#: Test files started first, longest first: pytest-xdist (``--dist loadfile``, setup.cfg) runs each file whole in one
#: worker, handing files out in collection order, so a long file handed out last keeps one worker busy long after the
#: other has finished (the GPU ISA check's fixture alone compiles for minutes). Longest first, the short files fill in
#: at the end. Their order: a cold run's per-file times (docs/testing.md); the other files keep theirs after them.
FIRST_FILES = ("test_gpu_isa.py", "test_docs.py", "test_interior.py", "test_gradients.py", "test_gpu_layout.py",
               "test_rfilter.py", "test_shadows.py", "test_instance_gradients.py", "test_plugins.py",
               "test_instances.py", "test_wavefront.py", "test_scenes.py", "test_edges.py", "test_bench.py",
               "test_distributed.py")


def pytest_collection_modifyitems(config, items) -> None:
    first = {name: k for k, name in enumerate(FIRST_FILES)}
    items.sort(key=lambda item: first.get(item.path.name, len(first)))  # stable: the files' own order otherwise


@pytest.fixture(scope="session")
def device() -> pyclpt.Device:
    return pyclpt.default_device()


DEVICES = ["pocl", "intel"]


def open_intel() -> pyclpt.Device:
    """Intel's CPU OpenCL device; skips the test without it (fails under PYCLPT_REQUIRE_INTEL=1)."""
    try:
        return pyclpt.get_device("intel")
    except DeviceError as exc:
        if env.flag("PYCLPT_REQUIRE_INTEL"):
            pytest.fail(f"PYCLPT_REQUIRE_INTEL=1 but {exc}", pytrace=False)
        pytest.skip(f"Intel's CPU OpenCL runtime is not available: {exc}")


@pytest.fixture(scope="session")
def intel_device() -> pyclpt.Device:
    return open_intel()


@pytest.fixture(scope="session", params=DEVICES)
def each_device(request, device) -> pyclpt.Device:
    return device if request.param == "pocl" else open_intel()


@pytest.fixture(scope="session")
def shared_scenes() -> Path:
    root = scenes_root()
    if root is None or not root.is_dir():
        pytest.skip("the shared scene folder (PYCLPT_SCENES, ../shared/scenes) is not available")
    return root


@pytest.fixture(scope="session")
def cornell_box() -> pyclpt.Scene:
    return pyclpt.load("cornell-box")
