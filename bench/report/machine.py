"""What a report records about where it ran: the machine, the OpenCL platform and device with
their driver, PoCL and LLVM versions, Embree, Python packages and pyclpt's own revision."""
from __future__ import annotations

import os
import platform
import re
import subprocess
import sys
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def memory_gib() -> float | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return round(int(line.split()[1]) / 2**20, 1)
    except (OSError, ValueError, IndexError):
        pass
    return None


def load_average() -> list[float] | None:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (OSError, AttributeError):
        return None


def package_version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def git_revision() -> str | None:
    """``<short hash>`` (``+dirty`` with uncommitted changes) of the checkout pyclpt runs from, if any."""
    import pyclpt

    root = Path(pyclpt.__file__).resolve().parent.parent
    if not (root / ".git").exists():
        return None
    try:
        rev = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return f"{rev}{'+dirty' if dirty else ''}" if rev else None


def device_info(device) -> dict:
    """The OpenCL platform, device and driver; PoCL and LLVM versions parsed from the platform's."""
    d = device.device
    info = dict(device.describe())
    info.update(vendor=d.vendor.strip(), opencl_c_version=d.opencl_c_version.strip(),
                max_clock_mhz=int(d.max_clock_frequency), max_work_group_size=int(d.max_work_group_size),
                preferred_vector_width_float=int(d.preferred_vector_width_float))
    pv = info.get("platform_version", "")
    m = re.search(r"PoCL ([\w.\-]+)", pv)
    info["pocl_version"] = m.group(1) if m else None
    m = re.search(r"LLVM ([\w.\-]+)", pv)
    info["llvm_version"] = m.group(1) if m else None
    return info


def describe(device) -> dict:
    import pyopencl as cl

    import pyclpt

    embree_lib = None
    try:
        from pyclpt.accel import embree

        embree_lib = embree.library_path()
    except Exception:  # noqa: BLE001 - informational only
        pass
    return {
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "host": platform.node(),
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "memory_gib": memory_gib(),
        "os": platform.platform(),
        "python": sys.version.split()[0],
        "load_average_start": load_average(),
        "pyclpt": pyclpt.__version__,
        "git_revision": git_revision(),
        "pyopencl": cl.VERSION_TEXT,
        "numpy": package_version("numpy"),
        "pocl_binary_distribution": package_version("pocl-binary-distribution"),
        "embreex": package_version("embreex"),
        "embree_library": embree_lib,
        "matplotlib": package_version("matplotlib"),
        "opencl": device_info(device),
    }
