"""OpenCL devices and programs: device selection and buffer allocation (``context``), programs
assembled from ``cl/`` with ``#line`` markers and ``-D`` specialisations (``program``), per-kernel
timing (``profile``).

May import: :mod:`pyclpt.common`. Knows nothing of scenes."""
from pyclpt.device.context import (BufferTooLarge, Device, DeviceError, alloc, check_alloc,  # noqa: F401
                                   default_device, get_device, list_devices, open_device, upload)
