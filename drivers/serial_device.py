"""Serial back-end: framed ADC samples (:mod:`ramdaq.drivers.serial_frames`) over any pyserial URL.

::

    with open_device("serial:///dev/ttyUSB0?rig=rigs/albacore.toml") as dev:
        for block in dev:
            ...
    open_device("serial://socket://10.0.0.7:4001?rig=rigs/albacore.toml")  # Ethernet bridge

The address is anything :func:`serial.serial_for_url` opens (a device path, ``socket://``,
``rfc2217://``, ...). Query keys this back-end knows (``rig``, ``fs_hz``, ``channels``,
``block_s``, ``baudrate``, ``reconnect_s``, ``give_up_s``, ``quiet_s``) are taken out of the URL before it is
handed to pyserial; any other key (``logging=debug``) is left for pyserial.

Frames are gathered into blocks of at most ``block_s`` (and at least one frame); a block's
``first_sample`` is its first frame's own sample index, so frames that never arrived leave a
gap that is never filled. A sample once placed is never moved. Each CRC-valid frame is
classified against the stream so far (its sequence number, sample index and payload CRC):

* it starts where the last one ended: placed;
* it is a frame already placed, the same bytes again (a TCP link or a buffer that repeated a
  span; the last 4096 frames are remembered): dropped, a run of them one ``repeated_frame`` event;
* it starts later, and its sequence number skipped exactly the frames that would fill the gap:
  placed after a ``seq_gap``;
* anything else -- behind the stream but not a repeat, or ahead by what its sequence does not
  explain -- is held until the next frame says what it was. Continued by it (sequence +1, sample
  index on from it): ahead, a gap (placed); behind, the device restarted its count
  (``stream_restart``: placed after the last sample, with a gap estimated from the host clock
  between the two frames' arrivals, ``gap_unknown`` true). Not continued: a stale or foreign
  frame, dropped (``stale_frame``).

Faults are reported through :meth:`~ramdaq.drivers.base.Device.take_faults`, never raised:

* ``crc_error`` -- frames whose header or payload CRC failed (``count``, ``total``);
* ``resync`` -- sync regained after garbage or a torn frame (``bytes_discarded``, ``seq``;
  ``at_connect`` when no frame had been placed yet: the bytes before the first frame boundary
  of a connect are normal, recorded but not shown);
* ``seq_gap`` -- frames missing from the sequence (``missing_frames``, ``missing_samples``);
* ``repeated_frame`` -- frames received again, dropped (``frames``, ``first_seq``, ``last_seq``,
  ``samples``, ``placed_at``: the stream sample where the first of them had been placed);
* ``stale_frame`` -- a frame that fits neither the stream nor the frame after it, dropped
  (``seq``, ``device_first_sample``, ``samples``, ``where``: ``behind`` or ``ahead``);
* ``stream_restart`` -- the device restarted its count (``seq``, ``device_first_sample``,
  ``continues_at``, ``gap_samples``, ``gap_unknown``);
* ``port_lost`` -- the port vanished (USB unplug, bridge down, EOF on a pty or socket);
* ``port_back`` -- the port reopened and data flows again, with the gap it left
  (``gap_samples``, ``gap_frames``, ``down_s``);
* ``frame_mismatch`` -- CRC-valid frames with the wrong channel count, dropped: the first at
  once, then at most once per ``report_s`` (1 s) with the count (``channels``, ``expected``,
  ``frames`` since the last report, ``total``);
* ``no_data`` / ``data_back`` -- no block for ``quiet_s`` (default 1 s) while the port is open,
  and the block that ended that silence (:mod:`ramdaq.drivers.base`).

A lost port is reopened with the same URL every ``reconnect_s`` seconds; after ``give_up_s``
seconds without it, :meth:`read` raises :class:`~ramdaq.drivers.errors.DeviceClosed` naming the URL.
The block in progress when the port is lost is handed out at once, so the loss is recorded live.
``read`` checks its timeout once per ``read_slice_s`` (20 ms): a timeout may run over by that.
"""

from __future__ import annotations

import io
import select
import time
from collections import deque
from pathlib import Path
from urllib.parse import unquote

import numpy as np
import serial

from ..analysis.model.rig import Rig, load_rig, parse_rig
from .base import QUIET_S, TIMED_OUT, Device
from .block import Block, StreamInfo, sample_time_ns
from .errors import DeviceClosed, DeviceNotFound
from .rig_channels import rig_channels
from .serial_frames import Frame, FrameParser

__all__ = ["SerialDevice", "split_url"]

_QUERY_KEYS = {"rig": str, "fs_hz": float, "channels": int, "block_s": float, "baudrate": int,
               "reconnect_s": float, "give_up_s": float, "quiet_s": float}
_READ_CHUNK = 1 << 16
_HISTORY = 4096  # frames remembered (by sequence number) to tell a repeat from a restart
_PORT_ERRORS = (serial.SerialException, OSError)


def split_url(address: str) -> tuple[str, dict[str, str]]:
    """Split ``address`` into the URL for pyserial and this back-end's own query options.

    ``"socket://h:1?rig=a.toml&logging=debug"`` -> ``("socket://h:1?logging=debug",
    {"rig": "a.toml"})``.
    """
    base, sep, query = address.partition("?")
    if not sep:
        return address, {}
    own, kept = {}, []
    for item in query.split("&"):
        key, _, value = item.partition("=")
        if key in _QUERY_KEYS:
            own[key] = unquote(value)
        elif item:
            kept.append(item)
    return base + ("?" + "&".join(kept) if kept else ""), own


def _load_rig(rig: Rig | str | Path) -> Rig:
    if isinstance(rig, Rig):
        return rig
    if isinstance(rig, str) and ("\n" in rig or "=" in rig):
        return parse_rig(rig, source="serial:rig")
    return load_rig(rig)


class SerialDevice(Device):
    """A front-end streaming :mod:`~ramdaq.drivers.serial_frames` frames (back-end name ``"serial"``).

    Parameters
    ----------
    url : str
        pyserial URL or device path, optionally with ``?rig=...&fs_hz=...`` (see module notes).
    baudrate : int, optional
        Line rate, baud; default 2 000 000 (ignored by ``socket://``). 16 ch x 2048 Hz x 3 bytes
        is 100 kB/s with framing, ~1 Mbaud at 10 bits per byte.
    rig : Rig, path or str, optional
        The rig (object, TOML path or TOML text): channel names, gages, scales, sample rate.
        Without one the channels are ``c01``... in raw counts (scale 1).
    channels : int, optional
        Channel count; the rig's, else 16. Frames with another count are dropped.
    fs_hz : float, optional
        Sample rate, Hz; the rig's, else 2048.
    block_s : float, optional
        Longest block, s; default 0.05 (blocks hold whole frames; a longer frame is a block).
    reconnect_s : float, optional
        Seconds between attempts to reopen a lost port; default 0.5.
    give_up_s : float, optional
        Seconds a port may stay lost before the stream ends with ``DeviceClosed``; default 30.
    quiet_s : float, optional
        Seconds without a block, port open, before ``no_data`` is reported; default 1.
    read_slice_s : float
        Longest wait for bytes in one go, s: the granularity of ``read(timeout)``.
    report_s : float
        Frames of a wrong channel count are reported at most this often, s (the first at once).
    """

    kind = "serial"

    def __init__(self, url: str, *, baudrate: int | None = None, rig: Rig | str | Path | None = None,
                 channels: int | None = None, fs_hz: float | None = None,
                 block_s: float | None = None, reconnect_s: float | None = None,
                 give_up_s: float | None = None, quiet_s: float | None = None,
                 read_slice_s: float = 0.02, report_s: float = 1.0) -> None:
        super().__init__()
        self.url, query = split_url(url)
        given = {"rig": rig, "fs_hz": fs_hz, "channels": channels, "block_s": block_s,
                 "baudrate": baudrate, "reconnect_s": reconnect_s, "give_up_s": give_up_s,
                 "quiet_s": quiet_s}
        opts = {}
        for key, value in given.items():
            if key in query and value is not None:
                raise ValueError(f"serial: {key} given both in {url!r} and as an argument")
            try:
                opts[key] = _QUERY_KEYS[key](query[key]) if key in query else value
            except ValueError:
                raise ValueError(f"serial: {key}={query[key]!r} in {url!r} is not a "
                                 f"{_QUERY_KEYS[key].__name__}") from None
        self.rig = None if opts["rig"] is None else _load_rig(opts["rig"])
        rig_fs = self.rig.daq.sample_rate_hz if self.rig else 2048.0
        rig_ch = self.rig.n_channels if self.rig else 16  # gages and forces
        self.fs_hz = float(opts["fs_hz"] or rig_fs)
        self.n_channels = int(opts["channels"] or rig_ch)
        self.baudrate = int(opts["baudrate"] or 2_000_000)
        self.block_s = float(opts["block_s"] if opts["block_s"] is not None else 0.05)
        self.reconnect_s = float(opts["reconnect_s"] if opts["reconnect_s"] is not None else 0.5)
        self.give_up_s = float(opts["give_up_s"] if opts["give_up_s"] is not None else 30.0)
        self.quiet_s = float(opts["quiet_s"] if opts["quiet_s"] is not None else QUIET_S)
        self.read_slice_s = float(read_slice_s)
        self.report_s = float(report_s)
        for name in ("fs_hz", "block_s", "reconnect_s", "give_up_s", "quiet_s", "read_slice_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"serial: {name} ({getattr(self, name)}) must be positive")
        if self.rig is not None and self.n_channels != rig_ch:
            raise ValueError(f"serial: channels ({self.n_channels}) differs from the rig's {rig_ch}")
        if not 1 <= self.n_channels <= 255:
            raise ValueError(f"serial: channels ({self.n_channels}) must be within 1..255")
        self.block_n = max(1, round(self.block_s * self.fs_hz))
        self.parser = FrameParser()
        self._port: serial.SerialBase | None = None
        self._fileno: int | None = None
        self._ready: deque[Block] = deque()
        self._parts: list[np.ndarray] = []
        self._part_first = 0
        self._part_n = 0
        self._next: int | None = None  # sample index the next frame should start at
        self._last_seq: int | None = None
        self._offset = 0  # added to device sample indices after a device restart
        self._placed: list[tuple | None] = [None] * _HISTORY  # seq % _HISTORY -> (seq, device
        # first sample, payload CRC, stream first sample) of the frames placed
        self._suspect: Frame | None = None  # a frame held until the next one says what it is
        self._suspect_t = 0.0
        self._repeats: dict | None = None  # the run of repeated frames being dropped
        self._t_read = 0.0  # monotonic time of the read whose frames are being placed, s
        self._t_last: float | None = None  # ... of the last frame placed
        self._seq = 0
        self._ended = False
        self._lost_at: float | None = None
        self._next_try = 0.0
        self._back: float | None = None  # seconds the port was down, until data flows again
        self._refused = self._refused_said = 0  # frames of a wrong channel count: all, reported
        self._refused_next = 0.0  # monotonic s of the next frame_mismatch report
        self._refused_at_block = 0  # ... refused when the last block was made
        self._refused_last = (0, 0)  # sequence number and channel count of the last refused

    # -- Device hooks ------------------------------------------------------------------------
    def _open(self) -> StreamInfo:
        try:
            self._port = self._open_port()
        except _PORT_ERRORS as err:
            raise DeviceNotFound(f"serial: cannot open {self.url}: {_one_line(err)}") from err
        if self.rig is not None:
            ch = rig_channels(self.rig)  # its gages and force channels (N: the force mode)
            names, units, numbers = ch.names, ch.units, ch.gages
            self.scale = ch.scales.astype(np.float64)
            extra = {"adc_bits": self.rig.daq.adc_bits, "medium": self.rig.medium,
                     "rig_name": self.rig.name}
        else:
            names = tuple(f"c{i + 1:02d}" for i in range(self.n_channels))
            units, numbers = ("count",) * self.n_channels, (0,) * self.n_channels
            self.scale = np.ones(self.n_channels)
            extra = {}
        extra.update(url=self.url, baudrate=self.baudrate, block_samples=self.block_n,
                     wire_format="ramdaq-serial v1")
        return StreamInfo(device=f"serial://{self.url}", fs_hz=self.fs_hz, channels=names,
                          units=units, gages=numbers, rig_toml=self.rig.text if self.rig else "",
                          extra=extra)

    def _read(self, timeout: float | None) -> Block | None:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            if self._ready:
                return self._ready.popleft()
            if self._ended:
                return None
            if self._port is None:
                if not self._reconnect(deadline):
                    return TIMED_OUT
                continue
            try:
                data = self._receive()
            except _PORT_ERRORS as err:
                self._lose(err)
                continue
            self._t_read = time.monotonic()
            if data:
                self._ingest(self.parser.feed(data))
            if not self._ready and deadline is not None and time.monotonic() >= deadline:
                return TIMED_OUT

    def _close(self) -> None:
        self._drop_port()

    # -- port --------------------------------------------------------------------------------
    def _open_port(self) -> serial.SerialBase:
        port = serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=self.read_slice_s)
        try:
            self._fileno = port.fileno()
        except (AttributeError, io.UnsupportedOperation, *_PORT_ERRORS):
            self._fileno = None  # rfc2217://, loop://, ...: pyserial's own timeout does the waiting
        else:
            port.timeout = 0  # select() below waits; each read is then a single recv / os.read
        return port

    def _receive(self) -> bytes:
        """Bytes that arrived, waiting at most ``read_slice_s``; ``b""`` if none did.

        pyserial's ``read(n)`` with a timeout loops until ``n`` bytes, and its ``socket://`` and
        posix handlers raise at EOF *discarding what that call had already read* -- the last
        frames before an unplug or the end-of-stream frame. Waiting with ``select`` on the port's
        descriptor and then reading without a timeout makes each read one ``recv``/``os.read``:
        nothing read is ever thrown away.
        """
        port = self._port
        if self._fileno is None:
            return port.read(max(1, min(port.in_waiting, _READ_CHUNK)))
        ready, _, _ = select.select([self._fileno], [], [], self.read_slice_s)
        return port.read(_READ_CHUNK) if ready else b""

    def _drop_port(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except _PORT_ERRORS:
                pass  # it is gone already

    def _lose(self, err: BaseException) -> None:
        """The port failed: keep what was received, hand out the partial block, start retrying."""
        self._drop_port()
        self._ingest(self.parser.flush())
        self._end_repeats()
        self._report_refused()
        self._emit_partial()
        if self._ended:  # the device said goodbye before it went: not a fault
            return
        self._lost_at = time.monotonic()
        self._next_try = self._lost_at + self.reconnect_s
        self._fault("port_lost", self._t_next(), url=self.url, error=_one_line(err),
                    retry_every_s=self.reconnect_s, give_up_s=self.give_up_s)

    def _reconnect(self, deadline: float | None) -> bool:
        """Reopen the lost port; False if ``deadline`` came first. Raises DeviceClosed at give-up."""
        while True:
            now = time.monotonic()
            if now - self._lost_at >= self.give_up_s:
                raise DeviceClosed(f"serial: {self.url} vanished and did not come back within "
                                   f"{self.give_up_s:g} s")
            if now >= self._next_try:
                try:
                    self._port = self._open_port()
                except _PORT_ERRORS:
                    self._next_try = now + self.reconnect_s
                else:
                    self._back = now - self._lost_at
                    self._lost_at = None
                    return True
            wake = min(self._next_try, self._lost_at + self.give_up_s)
            if deadline is not None and wake > deadline:
                time.sleep(max(0.0, deadline - now))
                return False
            time.sleep(max(0.0, wake - now))

    # -- frames -> blocks --------------------------------------------------------------------
    def _t_next(self) -> int:
        return sample_time_ns(self._next if self._next is not None else 0, self.fs_hz)

    def _ingest(self, frames: list[Frame]) -> None:
        for frame in frames:
            if frame.failed_crc:
                self._fault("crc_error", self._t_next(), count=frame.failed_crc,
                            total=self.parser.crc_errors)
            if frame.skipped_bytes:
                connect = {"at_connect": True} if self._next is None else {}
                self._fault("resync", self._t_next(), bytes_discarded=frame.skipped_bytes,
                            seq=frame.seq, total=self.parser.resyncs, **connect)
            if frame.end:
                if self._suspect is not None:
                    self._judge_suspect(frame)
                self._end_repeats()
                self._report_refused()
                self._ended = True
                self._drop_port()
                break
            if frame.n_channels != self.n_channels:
                self._mismatch(frame)
                continue
            self._report_refused()  # a run of refused frames ended: its count, all of it
            self._place(frame)
        if self._ended:
            self._emit_partial()

    def _mismatch(self, frame: Frame) -> None:
        """A frame of the wrong channel count, refused: reported at once, then at most once per
        ``report_s`` with the count; until a block comes, this says why no data come."""
        self._refused += 1
        self._refused_last = (frame.seq, frame.n_channels)
        if time.monotonic() >= self._refused_next:
            self._report_refused()

    def _report_refused(self) -> None:
        """A ``frame_mismatch`` for the frames refused since the last one, if any."""
        if self._refused > self._refused_said:
            seq, channels = self._refused_last
            self._fault("frame_mismatch", self._t_next(), seq=seq, channels=channels,
                        expected=self.n_channels, frames=self._refused - self._refused_said,
                        total=self._refused)
            self._refused_said, self._refused_next = self._refused, time.monotonic() + self.report_s

    def _place(self, frame: Frame) -> None:
        """Where a CRC-valid frame goes (module notes): on from the last, dropped as a repeat,
        after a gap its sequence explains, or held until the next frame says what it is."""
        if self._next is None:
            self._accept(frame)
            return
        if self._suspect is not None:
            self._judge_suspect(frame)
        expected = self._next - self._offset
        if frame.first_sample != expected and self._is_repeat(frame):
            self._count_repeat(frame)
            return
        self._end_repeats()
        if frame.first_sample == expected or (frame.first_sample > expected and self._explained(frame)):
            self._accept(frame)
        else:
            self._suspect, self._suspect_t = frame, self._t_read

    def _explained(self, frame: Frame) -> bool:
        """Whether a frame that starts later skipped exactly the frames its sequence skipped
        (taken to be of its own length)."""
        lost = (frame.seq - self._last_seq - 1) % 2**32
        return frame.first_sample - (self._next - self._offset) == lost * frame.n_samples

    def _is_repeat(self, frame: Frame) -> bool:
        e = self._placed[frame.seq % _HISTORY]
        return e is not None and e[:3] == (frame.seq, frame.first_sample, frame.payload_crc)

    def _count_repeat(self, frame: Frame) -> None:
        r = self._repeats
        if r is not None and frame.seq == (r["last_seq"] + 1) % 2**32:
            r["frames"] += 1
            r["last_seq"] = frame.seq
            r["samples"] += frame.n_samples
            return
        self._end_repeats()
        self._repeats = {"frames": 1, "first_seq": frame.seq, "last_seq": frame.seq,
                         "samples": frame.n_samples, "placed_at": self._placed[frame.seq % _HISTORY][3]}

    def _end_repeats(self) -> None:
        if self._repeats is not None:
            self._fault("repeated_frame", self._t_next(), **self._repeats)
            self._repeats = None

    def _judge_suspect(self, after: Frame) -> None:
        """The frame after a held one says what that was: continued by it, a gap (ahead of the
        stream) or a restart (behind it); otherwise a stale or foreign frame, dropped."""
        s, self._suspect = self._suspect, None
        behind = s.first_sample < self._next - self._offset
        if after.seq == (s.seq + 1) % 2**32 and after.first_sample == s.first_sample + s.n_samples:
            if behind:
                self._restart(s)
            self._accept(s, gap_event=not behind)
        else:
            self._fault("stale_frame", self._t_next(), seq=s.seq, device_first_sample=s.first_sample,
                        samples=s.n_samples, where="behind" if behind else "ahead")

    def _restart(self, frame: Frame) -> None:
        """The device restarted its count: go on after the last sample placed, leaving the gap
        the host clock saw between the two frames' arrivals (an estimate: said so)."""
        seen = 0.0 if self._t_last is None else self._suspect_t - self._t_last
        gap = max(0, round(seen * self.fs_hz) - frame.n_samples)
        self._fault("stream_restart", self._t_next(), seq=frame.seq,
                    device_first_sample=frame.first_sample, continues_at=self._next + gap,
                    gap_samples=gap, gap_unknown=True)
        self._offset = self._next + gap - frame.first_sample

    def _accept(self, frame: Frame, gap_event: bool = True) -> None:
        first = frame.first_sample + self._offset
        if (self._next is not None and first > self._next) or self._back is not None:
            missing = first - (self._next if self._next is not None else first)
            frames = 0 if self._last_seq is None else (frame.seq - self._last_seq - 1) % 2**32
            detail = {"gap_samples": missing, "gap_frames": frames}
            if self._back is not None:
                self._fault("port_back", self._t_next(), url=self.url,
                            down_s=round(self._back, 3), **detail)
                self._back = None
            elif gap_event:
                self._fault("seq_gap", self._t_next(), after_seq=self._last_seq, seq=frame.seq,
                            missing_frames=frames, missing_samples=missing)
            if missing:
                self._emit_partial()
        if not self._parts:
            self._part_first = first
        self._parts.append(frame.counts)
        self._part_n += frame.n_samples
        self._next = first + frame.n_samples
        self._last_seq = frame.seq
        self._placed[frame.seq % _HISTORY] = (frame.seq, frame.first_sample, frame.payload_crc, first)
        self._t_last = self._t_read
        if self._part_n + frame.n_samples > self.block_n:  # another such frame would not fit
            self._emit_partial()

    def _t_heard_ns(self) -> int:
        return self._t_next()

    def _silence_explained(self) -> bool:
        """port_lost or frame_mismatch already said why no blocks come."""
        return self._lost_at is not None or self._refused > self._refused_at_block

    def _emit_partial(self) -> None:
        if not self._parts:
            return
        self._refused_at_block = self._refused
        counts = np.ascontiguousarray(np.concatenate(self._parts, axis=1), dtype=np.int32)
        self._ready.append(Block(seq=self._seq, first_sample=self._part_first,
                                 t0_ns=sample_time_ns(self._part_first, self.fs_hz),
                                 fs_hz=self.fs_hz, counts=counts, scale=self.scale))
        self._seq += 1
        self._parts, self._part_n = [], 0


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split()) or type(err).__name__
