"""OpenCL device selection.

PoCL (the CPU driver shipped by ``pocl-binary-distribution``) is the default
device everywhere. ``device=`` arguments and the ``PYCLPT_DEVICE`` setting pick
another one: ``"pocl"``, ``"gpu"``, ``"cpu"``, a platform/device index pair
``"1:0"``, or any substring of a platform or device name (``"NVIDIA"``).

The only global state in pyclpt is the lazily created default device.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import pyopencl as cl


class DeviceError(RuntimeError):
    """No usable OpenCL platform or device."""


INSTALL_HINT = (
    "pyclpt needs an OpenCL driver. The CPU driver PoCL installs with "
    "`pip install pocl-binary-distribution` (a dependency of pyclpt); on a GPU "
    "install the vendor's OpenCL driver. `pyclpt devices` lists what is found."
)


@dataclass
class Device:
    """An OpenCL device with its context and one in-order profiling queue."""

    device: cl.Device
    context: cl.Context
    queue: cl.CommandQueue
    # Compiled programs of this device, keyed by (assembled source, options).
    programs: dict[Any, cl.Program] = field(default_factory=dict, repr=False)

    @property
    def platform(self) -> cl.Platform:
        return self.device.platform

    @property
    def name(self) -> str:
        return f"{self.device.platform.name.strip()} / {self.device.name.strip()}"

    @property
    def is_pocl(self) -> bool:
        return "portable computing language" in self.device.platform.name.lower()

    @property
    def max_alloc(self) -> int:
        return int(self.device.max_mem_alloc_size)

    @property
    def has_fp64(self) -> bool:
        return "cl_khr_fp64" in self.device.extensions

    def describe(self) -> dict[str, str]:
        d = self.device
        return {
            "platform": d.platform.name.strip(),
            "platform_version": d.platform.version.strip(),
            "device": d.name.strip(),
            "device_version": d.version.strip(),
            "driver_version": d.driver_version.strip(),
            "compute_units": str(d.max_compute_units),
            "global_mem_mb": str(d.global_mem_size // 2**20),
            "max_alloc_mb": str(d.max_mem_alloc_size // 2**20),
        }


def list_devices() -> list[tuple[int, int, cl.Device]]:
    """All (platform index, device index, device) triples; raises DeviceError if none."""
    try:
        platforms = cl.get_platforms()
    except cl.Error as exc:  # pyopencl raises when the ICD loader finds nothing
        raise DeviceError(f"no OpenCL platform found ({exc}). {INSTALL_HINT}") from None
    found = []
    for pi, platform in enumerate(platforms):
        try:
            devices = platform.get_devices()
        except cl.Error:
            continue
        found.extend((pi, di, d) for di, d in enumerate(devices))
    if not found:
        raise DeviceError(f"no OpenCL device found. {INSTALL_HINT}")
    return found


def _is_pocl(d: cl.Device) -> bool:
    return "portable computing language" in d.platform.name.lower()


def _select(spec: str) -> cl.Device:
    devices = list_devices()
    s = spec.strip().lower()
    if s in ("", "default", "pocl"):
        pocl = [d for _, _, d in devices if _is_pocl(d)]
        if pocl:
            return pocl[0]
        if s == "pocl":
            raise DeviceError(f"PoCL is not installed. {INSTALL_HINT}")
        return devices[0][2]
    if s in ("gpu", "cpu", "accelerator"):
        kind = {"gpu": cl.device_type.GPU, "cpu": cl.device_type.CPU,
                "accelerator": cl.device_type.ACCELERATOR}[s]
        match = [d for _, _, d in devices if d.type & kind]
        if not match:
            raise DeviceError(f"no OpenCL {s.upper()} device; found: {_names(devices)}")
        return match[0]
    if ":" in s and all(p.strip().isdigit() for p in s.split(":", 1)):
        pi, di = (int(p) for p in s.split(":", 1))
        for p, i, d in devices:
            if (p, i) == (pi, di):
                return d
        raise DeviceError(f"no OpenCL device {spec!r}; found: {_names(devices)}")
    match = [d for _, _, d in devices
             if s in d.name.lower() or s in d.platform.name.lower()]
    if not match:
        raise DeviceError(f"no OpenCL device matches {spec!r}; found: {_names(devices)}")
    return match[0]


def _names(devices: list[tuple[int, int, cl.Device]]) -> str:
    return "; ".join(f"{p}:{i} {d.platform.name.strip()} / {d.name.strip()}" for p, i, d in devices)


def open_device(spec: str | None = None) -> Device:
    """A new Device for ``spec`` (see module docstring); ``None`` reads ``PYCLPT_DEVICE``."""
    if spec is None:
        spec = os.environ.get("PYCLPT_DEVICE", "")
    dev = _select(spec)
    ctx = cl.Context([dev])
    queue = cl.CommandQueue(ctx, dev, properties=cl.command_queue_properties.PROFILING_ENABLE)
    return Device(device=dev, context=ctx, queue=queue)


_default: Device | None = None
_opened: dict[str, Device] = {}


def default_device() -> Device:
    """The lazily created default device (``PYCLPT_DEVICE`` or PoCL)."""
    global _default
    if _default is None:
        _default = open_device(None)
    return _default


def get_device(device: Device | str | None = None) -> Device:
    """Resolve a ``device=`` argument: a Device, a selector string, or None (default)."""
    if isinstance(device, Device):
        return device
    if device is None:
        return default_device()
    if device not in _opened:
        _opened[device] = open_device(device)
    return _opened[device]


class BufferTooLarge(MemoryError):
    """A buffer larger than the device's CL_DEVICE_MAX_MEM_ALLOC_SIZE."""


def check_alloc(device: Device, nbytes: int, what: str) -> None:
    if nbytes > device.max_alloc:
        raise BufferTooLarge(
            f"{what} needs {nbytes / 2**20:.1f} MiB, more than the {device.max_alloc / 2**20:.0f} MiB "
            f"that {device.name} allows in one buffer (CL_DEVICE_MAX_MEM_ALLOC_SIZE)")


def upload(device: Device, array, what: str) -> cl.Buffer:
    """A read-only device copy of a numpy array (checked against the allocation limit)."""
    import numpy as np

    arr = np.ascontiguousarray(array)
    if arr.nbytes == 0:
        arr = np.zeros(1, dtype=arr.dtype)
    check_alloc(device, arr.nbytes, what)
    mf = cl.mem_flags
    return cl.Buffer(device.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=arr)


def alloc(device: Device, nbytes: int, what: str) -> cl.Buffer:
    """An uninitialised read-write device buffer (checked against the allocation limit)."""
    check_alloc(device, nbytes, what)
    return cl.Buffer(device.context, cl.mem_flags.READ_WRITE, size=max(int(nbytes), 4))
