"""OpenCL drivers installed from PyPI, registered with the ICD loader: Intel's CPU runtime.

PoCL needs nothing: pyopencl's wheel bundles an ocl-icd loader that always reads its own
``pyopencl/.libs`` folder (PoCL's ``pocl.icd``) besides the vendors folder, ``/etc/OpenCL/vendors``
or ``$OCL_ICD_VENDORS``. Intel's CPU runtime (``pip install "pyclpt[intel]"``: the distributions
``intel-opencl-rt`` and ``intel-cmplr-lib-rt``) puts ``libintelocl.so`` into the environment's
``lib/`` folder, with an ``.icd`` file naming a path of Intel's build machine. So, before pyopencl
first enumerates platforms (:func:`register` runs when :mod:`pyclpt.device.context` is imported),
pyclpt writes ``intel-cpu.icd`` (the library's absolute path) into a folder of its cache, beside a
copy of every ``.icd`` of ``/etc/OpenCL/vendors`` (the system's drivers, a GPU's, stay visible),
and points ``OCL_ICD_VENDORS`` at that folder, for this process and its children. Both platforms
then appear together; :func:`pyclpt.list_devices` lists the registered Intel platform after the
others, so PoCL keeps its ``0:0``. ``PYCLPT_DEVICE=intel`` (any substring of the platform name)
selects it.

Intel's vectorizer (which packs work-items into SIMD lanes) is left on: the kernels whose work-items
run loops of data-dependent length (the megakernel, ``intersect``, ``shadow_test``) opt out with
``intel_vec_len_hint(1)`` (``SCALAR_KERNEL`` in cl/core/common.h), and the straight-line stages run
vectorized. ``CL_CONFIG_USE_VECTORIZER=False`` turns it off for every kernel (docs/devices.md).

A user's own ``OCL_ICD_VENDORS`` is left alone (nothing is registered then); so is a system where
``/etc/OpenCL/vendors`` already registers ``libintelocl.so``. Without the runtime nothing changes.
"""
from __future__ import annotations

import hashlib
import importlib.metadata
import logging
import sys
import tempfile
from pathlib import Path

from pyclpt.common import env
from pyclpt.common.cache import cache_root

log = logging.getLogger(__name__)

VENDORS_ENV = "OCL_ICD_VENDORS"
VECTORIZER_ENV = "CL_CONFIG_USE_VECTORIZER"
SYSTEM_VENDORS = Path("/etc/OpenCL/vendors")
INTEL_DISTRIBUTION = "intel-opencl-rt"
INTEL_LIBRARY = "libintelocl.so"
INTEL_ICD = "intel-cpu.icd"
INTEL_PLATFORM = "Intel(R) OpenCL"  # the platform name the runtime reports
MARKER = ".pyclpt"  # in a folder pyclpt wrote (the loader reads only *.icd)

# What register() found: "registered", "user" (OCL_ICD_VENDORS was set), "system" (the loader's
# folder registers Intel already), "absent" (no runtime installed), "unsupported" (not Linux) or
# "failed: reason"; None before it ran.
state: str | None = None


def intel_library() -> Path | None:
    """The ``libintelocl.so`` of the installed ``intel-opencl-rt`` distribution, or None."""
    try:
        dist = importlib.metadata.distribution(INTEL_DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:
        return None
    candidates = [dist.locate_file(f) for f in dist.files or () if f.name == INTEL_LIBRARY]
    candidates.append(Path(sys.prefix) / "lib" / INTEL_LIBRARY)  # where pip puts it in a venv
    for path in candidates:
        path = Path(path).resolve()
        if path.is_file():
            return path
    return None


def _system_icds() -> dict[str, str]:
    """The ``.icd`` files of /etc/OpenCL/vendors: {name: contents}."""
    try:
        return {p.name: p.read_text() for p in sorted(SYSTEM_VENDORS.glob("*.icd")) if p.is_file()}
    except OSError:
        return {}


def vendors_folder() -> Path | None:
    """The folder pyclpt points OCL_ICD_VENDORS at (written by :func:`register`), or None."""
    lib = intel_library()
    if lib is None:
        return None
    icds = {**_system_icds(), INTEL_ICD: f"{lib}\n"}
    key = hashlib.sha1(repr(sorted(icds.items())).encode()).hexdigest()[:12]
    return cache_root() / "opencl-vendors" / key


def _write(folder: Path, icds: dict[str, str]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in icds.items():
        path = folder / name
        if path.is_file() and path.read_text() == text:
            continue
        tmp = path.with_name(f".{name}.{id(icds)}.tmp")
        tmp.write_text(text)
        tmp.replace(path)


def registered() -> bool:
    """True when OCL_ICD_VENDORS names a folder pyclpt wrote (in this process or a parent)."""
    value = env.get(VENDORS_ENV)
    return value is not None and (Path(value) / MARKER).is_file()


def register() -> str:
    """Register Intel's CPU runtime with the ICD loader if it is installed (see module docstring);
    returns and records in :data:`state` what was done. Never raises: a failure is logged."""
    global state
    if state is not None:
        return state
    state = _register()
    log.debug("Intel CPU OpenCL runtime: %s", state)
    return state


def _register() -> str:
    if not sys.platform.startswith("linux"):
        return "unsupported"
    if env.get(VENDORS_ENV) is not None:
        return "registered" if registered() else "user"
    lib = intel_library()
    if lib is None:
        return "absent"
    system = _system_icds()
    if any(INTEL_LIBRARY in text for text in system.values()):
        return "system"
    icds = {**system, INTEL_ICD: f"{lib}\n", MARKER: "written by pyclpt/device/vendors.py\n"}
    folder = vendors_folder()
    assert folder is not None
    try:
        _write(folder, icds)
    except OSError as exc:  # an unusable cache folder: a private temporary one instead
        try:
            folder = Path(tempfile.mkdtemp(prefix="pyclpt-opencl-vendors-")) / "opencl-vendors" / folder.name
            _write(folder, icds)
        except OSError:
            log.warning("cannot register Intel's CPU OpenCL runtime (%s): writing %s failed (%s)", lib, folder, exc)
            return f"failed: {exc}"
    env.set_for_process(VENDORS_ENV, str(folder))
    return "registered"
