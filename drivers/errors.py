"""Errors raised by devices.

::

    DeviceError                  any failure of a device back-end
     +-- DeviceNotFound          no back-end of that name, or the address does not exist
     +-- DeviceTimeout           no block within the timeout (also a TimeoutError)
     +-- DeviceClosed            read from a device that is closed or has vanished
     +-- FrameError              a malformed frame or record in the incoming stream

Bad arguments stay ``ValueError``. Messages are one line and name what and where.
"""

from __future__ import annotations


class DeviceError(Exception):
    """Base of every device error."""


class DeviceNotFound(DeviceError):
    """No back-end of that name, or its address does not exist."""


class DeviceTimeout(DeviceError, TimeoutError):
    """No block arrived within the timeout."""


class DeviceClosed(DeviceError):
    """The device is closed, or vanished while streaming."""


class FrameError(DeviceError):
    """A malformed frame or record in the incoming stream."""
