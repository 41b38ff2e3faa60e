"""OpenCL devices and programs: device selection and buffer allocation (``context``), programs
assembled from ``cl/`` with ``#line`` markers and ``-D`` specialisations (``program``), per-kernel
timing (``profile``).

May import: :mod:`pyclpt.common`. Knows nothing of scenes."""
from pyclpt.device.context import (  # noqa: F401
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
