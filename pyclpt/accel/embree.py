"""ctypes binding of Embree 4's BVH builder API (``rtcBuildBVH``).

Only the parts of the C API that :mod:`pyclpt.accel.bvh` needs are bound: devices,
``rtcNewBVH`` / ``rtcBuildBVH`` / ``rtcReleaseBVH``, ``rtcThreadLocalAlloc``
and the error query. The library is the ``libembree4`` that the ``embreex``
wheel ships (``embreex.libs/`` on Linux, ``embreex/.dylibs`` on macOS, DLLs next
to the package on Windows); ``$PYCLPT_EMBREE_LIB`` names a library file to use
instead.

Struct layouts follow Embree 4's ``include/embree4/rtcore_builder.h`` and
``include/embree4/rtcore_common.h`` (unchanged since Embree 3.x's "byteSize"
revision of the builder API)::

    struct RTC_ALIGN(32) RTCBuildPrimitive {
      float lower_x, lower_y, lower_z; unsigned int geomID;
      float upper_x, upper_y, upper_z; unsigned int primID; };
    struct RTC_ALIGN(16) RTCBounds {
      float lower_x, lower_y, lower_z, align0;
      float upper_x, upper_y, upper_z, align1; };
    struct RTCBuildArguments {
      size_t byteSize;
      enum RTCBuildQuality buildQuality; enum RTCBuildFlags buildFlags;
      unsigned int maxBranchingFactor, maxDepth, sahBlockSize;
      unsigned int minLeafSize, maxLeafSize;
      float traversalCost, intersectionCost;
      RTCBVH bvh; struct RTCBuildPrimitive* primitives;
      size_t primitiveCount; size_t primitiveArrayCapacity;
      RTCCreateNodeFunction createNode; RTCSetNodeChildrenFunction setNodeChildren;
      RTCSetNodeBoundsFunction setNodeBounds; RTCCreateLeafFunction createLeaf;
      RTCSplitPrimitiveFunction splitPrimitive;
      RTCProgressMonitorFunction buildProgress; void* userPtr; };
"""
from __future__ import annotations

import ctypes
import glob
import os
import sys
import threading
from ctypes import (
    POINTER,
    Structure,
    c_bool,
    c_char_p,
    c_double,
    c_float,
    c_int,
    c_size_t,
    c_uint,
    c_void_p,
)
from pathlib import Path

from pyclpt.common import env

__all__ = [
    "EmbreeError",
    "RTCBounds",
    "RTCBuildArguments",
    "RTCBuildPrimitive",
    "RTC_BUILD_QUALITY_LOW",
    "RTC_BUILD_QUALITY_MEDIUM",
    "RTC_BUILD_QUALITY_HIGH",
    "RTC_BUILD_FLAG_NONE",
    "RTC_BUILD_MAX_PRIMITIVES_PER_LEAF",
    "CreateNodeFunc",
    "SetNodeChildrenFunc",
    "SetNodeBoundsFunc",
    "CreateLeafFunc",
    "SplitPrimitiveFunc",
    "ProgressMonitorFunc",
    "library_path",
    "lib",
    "device",
    "check_error",
    "default_build_arguments",
]


class EmbreeError(RuntimeError):
    """Embree could not be loaded, or one of its calls reported an error."""


# enum RTCBuildQuality (rtcore_common.h)
RTC_BUILD_QUALITY_LOW = 0
RTC_BUILD_QUALITY_MEDIUM = 1
RTC_BUILD_QUALITY_HIGH = 2
RTC_BUILD_QUALITY_REFIT = 3

# enum RTCBuildFlags (rtcore_builder.h)
RTC_BUILD_FLAG_NONE = 0
RTC_BUILD_FLAG_DYNAMIC = 1

# enum RTCBuildConstants
RTC_BUILD_MAX_PRIMITIVES_PER_LEAF = 32

# enum RTCError (rtcore_device.h)
_ERROR_NAMES = {
    0: "RTC_ERROR_NONE",
    1: "RTC_ERROR_UNKNOWN",
    2: "RTC_ERROR_INVALID_ARGUMENT",
    3: "RTC_ERROR_INVALID_OPERATION",
    4: "RTC_ERROR_OUT_OF_MEMORY",
    5: "RTC_ERROR_UNSUPPORTED_CPU",
    6: "RTC_ERROR_CANCELLED",
    7: "RTC_ERROR_LEVEL_ZERO_RAYTRACING_SUPPORT_MISSING",
}


class RTCBuildPrimitive(Structure):
    _fields_ = [
        ("lower_x", c_float),
        ("lower_y", c_float),
        ("lower_z", c_float),
        ("geomID", c_uint),
        ("upper_x", c_float),
        ("upper_y", c_float),
        ("upper_z", c_float),
        ("primID", c_uint),
    ]


class RTCBounds(Structure):
    _fields_ = [
        ("lower_x", c_float),
        ("lower_y", c_float),
        ("lower_z", c_float),
        ("align0", c_float),
        ("upper_x", c_float),
        ("upper_y", c_float),
        ("upper_z", c_float),
        ("align1", c_float),
    ]


# Callback types. Pointer arguments are declared as c_void_p (they arrive in
# Python as plain ints, the cheapest conversion) except where noted.
#   void* createNode(RTCThreadLocalAllocator alloc, unsigned int childCount, void* userPtr)
CreateNodeFunc = ctypes.CFUNCTYPE(c_void_p, c_void_p, c_uint, c_void_p)
#   void setNodeChildren(void* nodePtr, void** children, unsigned int childCount, void* userPtr)
SetNodeChildrenFunc = ctypes.CFUNCTYPE(None, c_void_p, POINTER(c_void_p), c_uint, c_void_p)
#   void setNodeBounds(void* nodePtr, const struct RTCBounds** bounds, unsigned int childCount, void* userPtr)
SetNodeBoundsFunc = ctypes.CFUNCTYPE(None, c_void_p, POINTER(c_void_p), c_uint, c_void_p)
#   void* createLeaf(RTCThreadLocalAllocator alloc, const struct RTCBuildPrimitive* prims,
#                    size_t primitiveCount, void* userPtr)
CreateLeafFunc = ctypes.CFUNCTYPE(c_void_p, c_void_p, c_void_p, c_size_t, c_void_p)
#   void splitPrimitive(const struct RTCBuildPrimitive* prim, unsigned int dim, float pos,
#                       struct RTCBounds* lbounds, struct RTCBounds* rbounds, void* userPtr)
SplitPrimitiveFunc = ctypes.CFUNCTYPE(None, c_void_p, c_uint, c_float, c_void_p, c_void_p, c_void_p)
#   bool buildProgress(void* userPtr, double n)
ProgressMonitorFunc = ctypes.CFUNCTYPE(c_bool, c_void_p, c_double)


class RTCBuildArguments(Structure):
    _fields_ = [
        ("byteSize", c_size_t),
        ("buildQuality", c_int),
        ("buildFlags", c_int),
        ("maxBranchingFactor", c_uint),
        ("maxDepth", c_uint),
        ("sahBlockSize", c_uint),
        ("minLeafSize", c_uint),
        ("maxLeafSize", c_uint),
        ("traversalCost", c_float),
        ("intersectionCost", c_float),
        ("bvh", c_void_p),
        ("primitives", c_void_p),
        ("primitiveCount", c_size_t),
        ("primitiveArrayCapacity", c_size_t),
        ("createNode", CreateNodeFunc),
        ("setNodeChildren", SetNodeChildrenFunc),
        ("setNodeBounds", SetNodeBoundsFunc),
        ("createLeaf", CreateLeafFunc),
        ("splitPrimitive", SplitPrimitiveFunc),
        ("buildProgress", ProgressMonitorFunc),
        ("userPtr", c_void_p),
    ]


# Layout checks against the C header (LP64 / LLP64 both have 8-byte pointers
# and size_t on the 64-bit platforms Embree 4 supports).
assert ctypes.sizeof(RTCBuildPrimitive) == 32
assert ctypes.sizeof(RTCBounds) == 32
if ctypes.sizeof(c_void_p) == 8:
    assert RTCBuildArguments.bvh.offset == 48
    assert RTCBuildArguments.createNode.offset == 80
    assert ctypes.sizeof(RTCBuildArguments) == 136


def default_build_arguments() -> RTCBuildArguments:
    """Python version of the header's inline ``rtcDefaultBuildArguments()``."""
    args = RTCBuildArguments()
    args.byteSize = ctypes.sizeof(RTCBuildArguments)
    args.buildQuality = RTC_BUILD_QUALITY_MEDIUM
    args.buildFlags = RTC_BUILD_FLAG_NONE
    args.maxBranchingFactor = 2
    args.maxDepth = 32
    args.sahBlockSize = 1
    args.minLeafSize = 1
    args.maxLeafSize = RTC_BUILD_MAX_PRIMITIVES_PER_LEAF
    args.traversalCost = 1.0
    args.intersectionCost = 1.0
    # bvh, primitives, counts, callbacks and userPtr are zero/NULL already.
    return args


# --------------------------------------------------------------------------
# Locating and loading the library


def _candidate_paths() -> list[Path]:
    found: list[Path] = []
    try:
        import importlib.util

        spec = importlib.util.find_spec("embreex")
    except (ImportError, ValueError):
        spec = None
    roots: list[Path] = []
    if spec is not None and spec.submodule_search_locations:
        for loc in spec.submodule_search_locations:
            pkg = Path(loc)
            # auditwheel (Linux): site-packages/embreex.libs; delocate (macOS):
            # embreex/.dylibs; delvewheel (Windows): site-packages/embreex.libs
            # or DLLs in the package folder itself.
            roots += [pkg.parent / "embreex.libs", pkg / ".dylibs", pkg / "lib", pkg, pkg.parent]
    if sys.platform == "win32":
        patterns = ["embree4*.dll", "libembree4*.dll"]
    elif sys.platform == "darwin":
        patterns = ["libembree4*.dylib"]
    else:
        patterns = ["libembree4*.so*"]
    for root in roots:
        if not root.is_dir():
            continue
        for pat in patterns:
            found += sorted(Path(p) for p in glob.glob(str(root / pat)))
    return found


def library_path() -> str:
    """Path (or bare name, for the system loader) of the Embree 4 library to load."""
    lib_env = env.get("PYCLPT_EMBREE_LIB")
    if lib_env:
        if not Path(lib_env).exists():
            raise EmbreeError(f"PYCLPT_EMBREE_LIB={lib_env!r} does not exist: set it to the path of "
                              f"libembree4.so / libembree4.dylib / embree4.dll, or unset it")
        return lib_env
    cands = _candidate_paths()
    if cands:
        return str(cands[0])
    import ctypes.util

    name = ctypes.util.find_library("embree4")
    if name:
        return name
    raise EmbreeError(
        "could not find the Embree 4 library (libembree4). Install the 'embreex' "
        "wheel (pip install embreex), which ships it, or set PYCLPT_EMBREE_LIB to "
        "the path of libembree4.so / libembree4.dylib / embree4.dll."
    )


_lib = None
_lib_lock = threading.Lock()
_device = None


def _bind(lib: ctypes.CDLL) -> None:
    def fn(name, restype, *argtypes):
        f = getattr(lib, name)
        f.restype = restype
        f.argtypes = list(argtypes)

    fn("rtcNewDevice", c_void_p, c_char_p)
    fn("rtcReleaseDevice", None, c_void_p)
    fn("rtcGetDeviceError", c_int, c_void_p)
    fn("rtcNewBVH", c_void_p, c_void_p)
    fn("rtcBuildBVH", c_void_p, POINTER(RTCBuildArguments))
    fn("rtcReleaseBVH", None, c_void_p)
    fn("rtcThreadLocalAlloc", c_void_p, c_void_p, c_size_t, c_size_t)
    if hasattr(lib, "rtcGetDeviceLastErrorMessage"):  # Embree >= 4.3
        fn("rtcGetDeviceLastErrorMessage", c_char_p, c_void_p)


def lib() -> ctypes.CDLL:
    """The loaded, bound Embree library (loaded once per process)."""
    global _lib
    if _lib is None:
        with _lib_lock:
            if _lib is None:
                path = library_path()
                folder = os.path.dirname(path)
                if sys.platform == "win32" and folder and hasattr(os, "add_dll_directory"):
                    # Let Windows find the wheel's tbb12.dll next to embree4.dll.
                    os.add_dll_directory(folder)
                try:
                    handle = ctypes.CDLL(path)
                except OSError as exc:
                    named = " (PYCLPT_EMBREE_LIB)" if env.get("PYCLPT_EMBREE_LIB") else ""
                    raise EmbreeError(f"could not load Embree library {path!r}{named}: {exc}") from exc
                try:
                    _bind(handle)
                except AttributeError as exc:
                    raise EmbreeError(
                        f"{path!r} lacks the Embree 4 builder API ({exc}); is it Embree 4?"
                    ) from exc
                _lib = handle
    return _lib


def check_error(dev: int, what: str) -> None:
    """Raise :class:`EmbreeError` if ``dev`` has a pending error (clearing it)."""
    L = lib()
    code = L.rtcGetDeviceError(dev)
    if code != 0:
        msg = ""
        if hasattr(L, "rtcGetDeviceLastErrorMessage"):
            raw = L.rtcGetDeviceLastErrorMessage(dev)
            if raw:
                msg = ": " + raw.decode("utf-8", "replace")
        raise EmbreeError(f"{what} failed with {_ERROR_NAMES.get(code, code)}{msg}")


def device() -> int:
    """A process-wide Embree device handle, created on first use.

    Its config string is ``$PYCLPT_EMBREE_CONFIG`` or ``"threads=1"``: the
    builder's callbacks are Python functions serialised by the GIL, so more
    builder threads only add contention (see :mod:`pyclpt.accel.bvh`).
    """
    global _device
    if _device is None:
        L = lib()
        with _lib_lock:
            if _device is None:
                config = env.get("PYCLPT_EMBREE_CONFIG")
                dev = L.rtcNewDevice((config or "threads=1").encode())
                if not dev:
                    code = L.rtcGetDeviceError(None)
                    named = f" (PYCLPT_EMBREE_CONFIG={config!r}: fix or unset it)" if config else ""
                    raise EmbreeError(
                        f"rtcNewDevice failed with {_ERROR_NAMES.get(code, code)}{named}"
                    )
                _device = dev
    return _device


def release_device() -> None:
    """Release the process-wide device (a later :func:`device` makes a new one)."""
    global _device
    with _lib_lock:
        if _device is not None:
            lib().rtcReleaseDevice(_device)
            _device = None
