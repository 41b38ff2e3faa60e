"""Device selection, the no-driver error, allocation limits."""
from __future__ import annotations

import os

import numpy as np
import pyopencl as cl
import pytest

import pyclpt
from pyclpt.device.context import (
    INSTALL_HINT,
    BufferTooLarge,
    Device,
    DeviceError,
    alloc,
    check_alloc,
    default_device,
    get_device,
    list_devices,
    open_device,
    upload,
)


def _pocl_entries():
    return [(p, i, d) for p, i, d in list_devices() if "portable computing language" in d.platform.name.lower()]


def test_default_device_is_pocl(device):
    if os.environ.get("PYCLPT_DEVICE"):
        pytest.skip("PYCLPT_DEVICE overrides the default device")
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
