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

A front-end that goes quiet is said at once to a caller that reads with a timeout: a back-end
that sets ``quiet_s`` (serial and CAN, default :data:`QUIET_S`, query key ``quiet_s``) reports a
``no_data`` fault the first time ``read(timeout)`` times out ``quiet_s`` or more after the last
block (or after opening), and a ``data_back`` fault with the next block -- unless the back-end
already said why no data come (a lost port, frames refused).
"""

from __future__ import annotations

import time
import warnings
from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass, field

from .block import Block, StreamInfo, sample_time_ns
from .errors import DeviceClosed, DeviceTimeout

QUIET_S = 1.0
"""Seconds without a block after which a front-end says ``no_data`` (module notes): ~20 blocks of
50 ms, far longer than any healthy front-end's jitter, short enough to be said before a blow
is missed."""
FAULT_POLL_S = 0.25
"""Longest wait for a block before a reader takes the device's faults (a silence, a lost port)
and says them, s: ``ramdaq record`` and a live trial read with this timeout."""


@dataclass(frozen=True)
class DeviceFault:
    """Something the device saw go wrong, for the recording's events and the live view:
    ``kind`` (e.g. ``"crc_error"``, ``"error_frame"``, ``"bus_off"``, ``"port_lost"``,
    ``"resync"``, ``"no_data"``), device time ``t_ns`` and a JSON-serialisable ``detail``
    (``at_connect``: part of a normal connect; :mod:`ramdaq.drivers.fault_words` does not show
    it). ``docs/drivers.md`` says what each kind means."""

    kind: str
    t_ns: int
    detail: dict = field(default_factory=dict)


class Device(ABC):
    """Base class of every back-end. Subclasses set ``kind`` and implement the three hooks."""

    kind: str = "device"
    quiet_s: float | None = None
    """Seconds without a block before ``no_data`` is reported; ``None``: never (module notes)."""

    def __init__(self) -> None:
        self._info: StreamInfo | None = None
        self._closed = False
        self._faults: list[DeviceFault] = []
        self._heard_at: float | None = None  # monotonic s of the last block (or the open)
        self._quiet_said = False  # the silence under way was looked at (and said, unless explained)
        self._quiet_faulted = False  # ... and no_data was reported for it
        self._t_after = 0  # device time just after the last block, ns
        self._quiet_t = 0  # device time at which the reported silence began, ns
        self._blocks_heard = False  # a block came (data_back then says "again")

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
            self._heard_at = time.monotonic()
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
            self._check_quiet()
            raise DeviceTimeout(f"{self.kind}: no block within {timeout} s")
        if block is not None and self.quiet_s is not None:
            self._heard(block)
        return block

    def _check_quiet(self) -> None:
        """Report ``no_data`` once per silence of ``quiet_s`` or more (module notes)."""
        if self.quiet_s is None or self._quiet_said or self._heard_at is None:
            return
        silent = time.monotonic() - self._heard_at
        if silent >= self.quiet_s:
            self._quiet_said = True
            if not self._silence_explained():
                self._quiet_faulted = True
                self._quiet_t = max(self._t_after, self._t_heard_ns())
                self._fault("no_data", self._quiet_t, silent_s=round(silent, 3),
                            quiet_s=self.quiet_s)

    def _heard(self, block: Block) -> None:
        """A block came: end the silence (``data_back`` if ``no_data`` was said for it), unless
        it holds only samples from before the silence (a block the back-end had not finished)."""
        now = time.monotonic()
        end = sample_time_ns(block.next_sample, block.fs_hz)
        if self._quiet_faulted:
            if end <= self._quiet_t:
                return
            self._fault("data_back", max(block.t0_ns, self._quiet_t),
                        silent_s=round(now - self._heard_at, 3),
                        missing_s=round((block.t0_ns - self._quiet_t) / 1e9, 6),
                        **({} if self._blocks_heard else {"first": True}))
        self._blocks_heard = True
        self._heard_at, self._quiet_said, self._quiet_faulted = now, False, False
        self._t_after = end

    def __iter__(self) -> Iterator[Block]:
        """Every block to the stream's end; a device with ``quiet_s`` is read with a timeout
        underneath, so that its silences are noted (``no_data``) even by a plain loop."""
        poll = None if self.quiet_s is None else min(0.25, self.quiet_s)
        while True:
            try:
                block = self.read(poll)
            except DeviceTimeout:
                continue
            if block is None:
                return
            yield block

    # -- hooks for back-ends -----------------------------------------------------------------
    def _t_heard_ns(self) -> int:
        """Device time just after the last sample received (placed in a block or not), ns."""
        return self._t_after

    def _silence_explained(self) -> bool:
        """Whether the back-end has already said why no blocks come (a lost port, frames
        refused): then a silence is not reported again as ``no_data``."""
        return False

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
