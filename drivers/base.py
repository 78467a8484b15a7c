"""The one small interface every device implements.

A device is opened, streams :class:`~ramdaq.drivers.block.Block` s, and is closed::

    with open_device("sim", rig=rig, duration_s=10) as dev:
        info = dev.info               # channel names, units, sample rate
        for block in dev:             # until the stream ends (finite devices) or close()
            ...

The base class owns the lifecycle (open once, close twice safely, warn if never closed) and the
timeout loop; a back-end overrides ``_open``, ``_read`` and ``_close`` only, as python-can's
``BusABC`` back-ends override ``_recv_internal``. Devices start no threads: pacing and queues
belong to the session that reads them.
"""

from __future__ import annotations

import warnings
from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass, field

from .block import Block, StreamInfo
from .errors import DeviceClosed, DeviceTimeout


@dataclass(frozen=True)
class DeviceFault:
    """Something the device saw go wrong, for the recording's events and the live view:
    ``kind`` (e.g. ``"crc_error"``, ``"error_frame"``, ``"bus_off"``, ``"port_lost"``,
    ``"resync"``), device time ``t_ns`` and a JSON-serialisable ``detail``."""

    kind: str
    t_ns: int
    detail: dict = field(default_factory=dict)


class Device(ABC):
    """Base class of every back-end. Subclasses set ``kind`` and implement the three hooks."""

    kind: str = "device"

    def __init__(self) -> None:
        self._info: StreamInfo | None = None
        self._closed = False
        self._faults: list[DeviceFault] = []

    # -- faults --------------------------------------------------------------------------------
    def _fault(self, kind: str, t_ns: int, **detail: object) -> None:
        """Back-ends call this to report a fault; it is never raised, only collected."""
        self._faults.append(DeviceFault(kind, t_ns, dict(detail)))

    def take_faults(self) -> list[DeviceFault]:
        """Faults seen since the last call (oldest first); the caller records and shows them."""
        out, self._faults = self._faults, []
        return out

    # -- lifecycle ---------------------------------------------------------------------------
    def open(self) -> StreamInfo:
        """Open the device (idempotent) and return what it streams."""
        if self._closed:
            raise DeviceClosed(f"{self.kind}: cannot reopen a closed device")
        if self._info is None:
            self._info = self._open()
        return self._info

    @property
    def info(self) -> StreamInfo:
        """Stream description; opens the device if needed (and stays known after close)."""
        return self._info if self._info is not None else self.open()

    def close(self) -> None:
        """Release the device. Safe to call more than once."""
        if not self._closed:
            self._closed = True
            if self._info is not None:
                self._close()

    @property
    def closed(self) -> bool:
        return self._closed

    def __enter__(self) -> Device:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        if getattr(self, "_info", None) is not None and not getattr(self, "_closed", True):
            warnings.warn(f"{self.kind} device was not closed", ResourceWarning, stacklevel=1)

    # -- streaming ---------------------------------------------------------------------------
    def read(self, timeout: float | None = None) -> Block | None:
        """Return the next block, or ``None`` when a finite stream has ended.

        Parameters
        ----------
        timeout : float or None
            Seconds to wait for a block; ``None`` waits as long as the device needs.

        Raises
        ------
        DeviceTimeout
            No block within ``timeout``.
        DeviceClosed
            The device is closed or vanished.
        """
        if self._closed:
            raise DeviceClosed(f"{self.kind}: read from a closed device")
        self.open()
        block = self._read(timeout)
        if block is _TIMED_OUT:
            raise DeviceTimeout(f"{self.kind}: no block within {timeout} s")
        return block

    def __iter__(self) -> Iterator[Block]:
        while True:
            block = self.read()
            if block is None:
                return
            yield block

    # -- hooks for back-ends -----------------------------------------------------------------
    @abstractmethod
    def _open(self) -> StreamInfo:
        """Acquire the device and describe its stream."""

    @abstractmethod
    def _read(self, timeout: float | None) -> Block | None:
        """Next block; ``None`` at the end of a finite stream; ``TIMED_OUT`` on timeout."""

    def _close(self) -> None:  # noqa: B027 - optional hook
        """Release what ``_open`` acquired."""


class _TimedOut:
    def __repr__(self) -> str:
        return "TIMED_OUT"


_TIMED_OUT: Block = _TimedOut()  # type: ignore[assignment]
TIMED_OUT = _TIMED_OUT
"""Sentinel a back-end's ``_read`` returns when ``timeout`` elapsed with no block."""
