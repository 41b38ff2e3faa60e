"""Device selection, the no-driver error, allocation limits."""
from __future__ import annotations

import os
import re

import numpy as np
import pyopencl as cl
import pytest

import pyclpt
from pyclpt.device.context import (
    CPU_RESERVE,
    INSTALL_HINT,
    BufferTooLarge,
    Device,
    DeviceError,
    DeviceMemoryError,
    alloc,
    check_alloc,
    check_memory,
    default_device,
    get_device,
    list_devices,
    open_device,
    upload,
)
from pyclpt.rendering.memory import render_memory


def _pocl_entries():
    return [(p, i, d) for p, i, d in list_devices() if "portable computing language" in d.platform.name.lower()]


def test_default_device_is_pocl(device):
    """The session's default device is PoCL: tests/conftest.py sets PYCLPT_DEVICE=pocl (the default without
    it is the fastest installed: tests/test_devices.py)."""
    if os.environ.get("PYCLPT_DEVICE", "").strip().lower() != "pocl":
        pytest.skip("PYCLPT_DEVICE selects another device for this session")
    assert device.is_pocl
    assert "Portable Computing Language" in device.name
    assert default_device() is default_device() is device
    assert get_device(None) is device
    assert get_device(device) is device


def test_list_devices_includes_pocl():
    found = list_devices()
    assert found
    assert all(isinstance(d, cl.Device) for _, _, d in found)
    assert _pocl_entries()


def test_open_pocl():
    dev = open_device("pocl")
    assert dev.is_pocl
    assert isinstance(dev.context, cl.Context)
    assert dev.queue.properties & cl.command_queue_properties.PROFILING_ENABLE
    # selectors are case- and space-insensitive
    assert open_device("  PoCL ").is_pocl


def test_open_cpu():
    dev = open_device("cpu")
    assert dev.device.type & cl.device_type.CPU


def test_open_by_index():
    p, i, d = list_devices()[0]
    dev = open_device(f"{p}:{i}")
    assert dev.device.int_ptr == d.int_ptr


def test_open_by_name_substring(device):
    # device name, in another case
    dev = open_device(device.device.name.strip().upper())
    assert dev.device.name == device.device.name
    # platform name substring
    dev = open_device(device.platform.name.strip()[:8].lower())
    assert dev.platform.name == device.platform.name


def test_get_device_caches_by_selector():
    assert get_device("pocl") is get_device("pocl")


@pytest.mark.parametrize("spec", ["no-such-device-xyz", "9:9"])
def test_bad_selector_lists_found_devices(spec):
    with pytest.raises(DeviceError) as info:
        open_device(spec)
    msg = str(info.value)
    assert repr(spec) in msg
    assert "found:" in msg
    _, _, d = list_devices()[0]
    assert d.name.strip() in msg
    assert "0:0" in msg


def test_gpu_selector_without_gpu():
    if any(d.type & cl.device_type.GPU for _, _, d in list_devices()):
        pytest.skip("a GPU is present")
    with pytest.raises(DeviceError, match="no OpenCL GPU device; found: "):
        open_device("gpu")


def test_env_selects_device(monkeypatch):
    monkeypatch.setenv("PYCLPT_DEVICE", "no-such-device-xyz")
    with pytest.raises(DeviceError, match="no-such-device-xyz"):
        open_device(None)
    p, i, d = list_devices()[0]
    monkeypatch.setenv("PYCLPT_DEVICE", f"{p}:{i}")
    assert open_device(None).device.int_ptr == d.int_ptr
    monkeypatch.setenv("PYCLPT_DEVICE", "pocl")
    assert open_device(None).is_pocl


def test_no_platform_raises_with_install_hint(monkeypatch):
    def no_platforms():
        raise cl.LogicError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")

    monkeypatch.setattr(cl, "get_platforms", no_platforms)
    with pytest.raises(DeviceError) as info:
        open_device("pocl")
    msg = str(info.value)
    assert "no OpenCL platform" in msg
    assert "PLATFORM_NOT_FOUND_KHR" in msg
    assert INSTALL_HINT in msg
    assert "pocl-binary-distribution" in msg


def test_empty_platform_list_raises_with_install_hint(monkeypatch):
    monkeypatch.setattr(cl, "get_platforms", lambda: [])
    with pytest.raises(DeviceError, match="no OpenCL device found") as info:
        list_devices()
    assert INSTALL_HINT in str(info.value)
    with pytest.raises(DeviceError):
        open_device(None)


def test_platform_without_devices_is_skipped(monkeypatch):
    real = cl.get_platforms()

    class Broken:
        name = "Broken Platform"

        def get_devices(self):
            raise cl.RuntimeError("clGetDeviceIDs failed: DEVICE_NOT_FOUND")

    monkeypatch.setattr(cl, "get_platforms", lambda: [Broken(), *real])
    found = list_devices()
    assert found and all(p >= 1 for p, _, _ in found)
    assert open_device("pocl").is_pocl


class _SmallDevice(Device):
    """The session device with a 1 KiB allocation limit."""

    max_alloc = 1024


def _small(device: Device) -> Device:
    return _SmallDevice(device=device.device, context=device.context, queue=device.queue)


def test_upload_rejects_oversized_buffer_before_allocating(device, monkeypatch):
    small = _small(device)
    assert small.max_alloc == 1024
    ok = upload(small, np.zeros(256, np.float32), "fits")  # exactly the limit
    assert isinstance(ok, cl.Buffer) and ok.size == 1024

    def no_buffers(*args, **kwargs):
        raise AssertionError("cl.Buffer must not be called for an oversized buffer")

    monkeypatch.setattr(cl, "Buffer", no_buffers)
    with pytest.raises(BufferTooLarge) as info:
        upload(small, np.zeros(257, np.float32), "test positions")
    assert isinstance(info.value, MemoryError)
    msg = str(info.value)
    assert "test positions" in msg
    assert "CL_DEVICE_MAX_MEM_ALLOC_SIZE" in msg
    with pytest.raises(BufferTooLarge, match="path state"):
        alloc(small, 4096, "path state")


def test_check_alloc_on_real_limit(device):
    check_alloc(device, device.max_alloc, "at the limit")  # no error
    with pytest.raises(BufferTooLarge, match="huge film"):
        check_alloc(device, device.max_alloc + 1, "huge film")


def test_upload_and_alloc_small(device):
    arr = np.arange(10, dtype=np.float32)
    buf = upload(device, arr, "ten floats")
    back = np.empty_like(arr)
    cl.enqueue_copy(device.queue, back, buf)
    np.testing.assert_array_equal(back, arr)
    assert upload(device, np.zeros(0, np.int32), "empty").size >= 4
    assert alloc(device, 0, "nothing").size >= 4


def test_describe_keys(device):
    info = device.describe()
    assert set(info) == {"platform", "platform_version", "device", "device_version", "driver_version",
                         "compute_units", "global_mem_mb", "max_alloc_mb"}
    assert all(isinstance(v, str) and v for v in info.values())
    assert int(info["compute_units"]) >= 1
    assert int(info["max_alloc_mb"]) == device.max_alloc // 2**20
    assert info["device"] == device.device.name.strip()


def test_public_exports():
    assert pyclpt.DeviceError is DeviceError
    assert pyclpt.open_device is open_device


# -- the memory of a render, all buffers together -----------------------------------------------------

class _SmallMemoryDevice(Device):
    """The session device with 1 MiB of global memory (each buffer still allowed on its own)."""

    global_mem = 2**20


def _small_memory(device: Device) -> Device:
    return _SmallMemoryDevice(device=device.device, context=device.context, queue=device.queue,
                              programs=device.programs)


def test_check_memory_counts_all_buffers_together(device):
    small = _small_memory(device)
    check_memory(small, {"a": 2**19, "b": 2**19})  # exactly the global memory
    with pytest.raises(DeviceMemoryError) as info:
        check_memory(small, {"frame": 3 * 2**19, "sum": 2**20}, hint="to fit, lower it")
    assert isinstance(info.value, MemoryError)
    msg = str(info.value)
    assert msg.startswith("this render needs 2 MiB (frame 2 MiB, sum 1 MiB), more than the 1 MiB available: ")
    assert "CL_DEVICE_GLOBAL_MEM_SIZE" in msg and small.name in msg and msg.endswith("; to fit, lower it")


def test_check_memory_of_the_process(device, monkeypatch):
    """A CPU device's buffers are this process's memory: RLIMIT_AS (ulimit -v) and free RAM apply."""
    import pyclpt.device.context as context

    monkeypatch.setattr(context, "host_memory_limits", lambda: [(CPU_RESERVE + 2**20, "test limit")])
    host = {"image read back": 2**19}
    if device.is_cpu:
        with pytest.raises(DeviceMemoryError, match=r"needs 2 MiB .* more than the 1 MiB available: the test "
                                                    r"limit, less 256 MiB kept free"):
            check_memory(device, {"frame": 3 * 2**19}, host=host)
    check_memory(device, {"frame": 2**19}, host=host)


def test_render_too_large_for_memory_fails_before_allocating(device, cornell_box, monkeypatch):
    small = _small_memory(device)

    def no_buffers(*args, **kwargs):
        raise AssertionError("nothing may be allocated for a render that does not fit")

    monkeypatch.setattr(cl, "Buffer", no_buffers)
    with pytest.raises(DeviceMemoryError) as info:
        pyclpt.Renderer(cornell_box, device=small, width=256, height=256)
    msg = str(info.value)
    # a batch of 4 frames (the wave size holds 4 frames of 256x256: pyclpt/rendering/memory.py, batch_frames)
    assert "needs 6 MiB" in msg and "frame buffer 256x256, 4 frames 3 MiB" in msg
    assert "dropped-sample marks 0 MiB" not in msg  # parts under half a MiB are not listed
    assert "accumulation sum (double) 2 MiB" in msg and "more than the 1 MiB available" in msg
    assert "lower the resolution (width, height) or sum in single precision (precision='single'" in msg
    assert "or use a smaller wave_size" in msg
    with pytest.raises(DeviceMemoryError, match="path state and queues .* use a smaller wave_size"):
        pyclpt.Renderer(cornell_box, device=small, width=128, height=128, integrator="wavefront",
                        precision="single")


def test_render_memory_parts(cornell_box):
    single = render_memory(cornell_box, 100, 50, precision="single", integrator="megakernel")
    double = render_memory(cornell_box, 100, 50, precision="double", integrator="wavefront", wave_size=1000,
                           max_depth=4)
    assert single["frame buffer 100x50, 52 frames"] == 52 * single["accumulated image"] == 52 * 12 * 5000
    assert double["frame buffer 100x50"] == 12 * 5000  # a wave of 1000 paths: one frame of 5000 pixels
    assert single["accumulation sum (single)"] == 12 * 5000 and double["accumulation sum (double)"] == 24 * 5000
    assert not any(k.startswith("path state") for k in single)
    assert double["path state and queues (1000 paths)"] > 1000 * 6 * 4
    assert 0 < single["scene buffers (estimate)"] < 2**20


def test_huge_render_under_ulimit_exits_1_with_a_message(tmp_path):
    """Buffers that each pass the per-buffer limit but together exceed the address space the process
    may use: a clear error and exit code 1 before anything is allocated (it used to crash in the
    driver, exit 139, or fail after minutes of rendering when the image was read back)."""
    import resource
    import subprocess
    import sys

    if not default_device().is_cpu:
        pytest.skip("the default device is not a CPU device: its buffers are not this process's memory")
    limit = 3 * 2**30

    def limit_address_space():
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    out = tmp_path / "huge.exr"
    proc = subprocess.run([sys.executable, "-m", "pyclpt.cli", "render", "cornell-box", "--width", "8000",
                           "--height", "8000", "--precision", "single", "--quiet", "-o", str(out)],
                          preexec_fn=limit_address_space, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, (proc.returncode, proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr
    assert re.search(r"this render needs [\d,]+ MiB .* more than the [\d,]+ MiB available", proc.stderr), proc.stderr
    assert "lower the resolution" in proc.stderr
    assert not out.exists()
