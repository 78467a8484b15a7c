"""slcan (Lawicel serial-line CAN) read in bulk: the CAN adapter's reader for ``can://slcan/...``.

python-can's ``slcanBus`` reads one byte per call and builds a ``can.Message`` per line; at
16 ch x 2.048 kHz on classic CAN (10 923 frames/s) that took a third to a half of the adapter's
CPU, even with the port read in chunks (``benchmarks/driver_throughput.py``). :class:`SlcanReader`
opens the port the way python-can does (same channel and ``@baud`` syntax, same pyserial
arguments, same ``C``/``S``/``Y``/``s``/``O``/``L`` command sequence, same errors), then takes every
byte waiting at most every :data:`READ_EVERY_S` seconds, splits it on ``\\r`` and parses the lines
straight into :class:`SlcanFrame` (the few ``can.Message`` attributes the adapter reads).
python-can's own bus stays in use for every other interface.

When the lines came: a read's time says when they were taken, not when they arrived -- a reader
that was not scheduled for a while reads a backlog that looks late. :attr:`SlcanReader.arrived_after`
is the last host time the port was seen empty (a read that drained it, a wait that found nothing,
or one read period before a wait on an empty port was woken by bytes): every line of the last
batch arrived after it and by its ``timestamp``. A backlog read late has an early bound (it looks
on time); lines after a silence the reader waited through have a bound within a read period of
their arrival.

What a line becomes (:func:`parse_lines`):

* ``t``/``T``/``x`` (``x``: CANdapter's extended), ``r``/``R`` (remote), ``d``/``D``/``b``/``B`` (CAN FD,
  ``b``/``B`` with bit-rate switch): a frame; identifier 3 or 8 hex digits (at most 0x7FF or
  0x1FFFFFFF), DLC a digit 0-8 (classic) or a hex digit 0-F (FD, python-can's ``CAN_FD_DLC``),
  exactly 2 hex digits per data byte, then at most 8 more hex digits (an adapter's timestamp,
  ignored; the frame's :attr:`~SlcanFrame.timestamp` is the host time of the read, s: wall-clock
  time as python-can's, but counted on the monotonic clock from the moment the port was opened,
  so a step of the wall clock (NTP) never looks like a silence on the bus to the CAN adapter,
  which holds these times against the sample clock);
* ``F`` with two hex digits (the status flags): nothing when 0, else an error frame with the
  SocketCAN classes the flags mean (controller problems 0x04, lost arbitration 0x02, bus error
  0x80);
* an empty line (``\\r``, "OK"), a BELL (``\\a``, "error": it ends a line, as in python-can) and
  the replies ``z``, ``Z`` and ``V``/``v``/``N`` with 4 letters or digits: nothing;
* anything else, a torn or a garbled line: its reason, a one-line string (never an exception).
  The stricter rules than python-can's (which also takes short data, whitespace, ``0x``, a DLC
  of 9 on a classic line and any trailing text) only turn lines it would have taken garbled into
  unparseable ones.
"""

from __future__ import annotations

import os
import select
import time

import serial
from can import BitTiming, BitTimingFd, CanInitializationError
from can.exceptions import error_check
from can.interfaces.slcan import slcanBus
from can.util import CAN_FD_DLC, check_or_adjust_timing_clock

__all__ = ["READ_EVERY_S", "SlcanFrame", "SlcanReader", "parse_lines"]

READ_EVERY_S = 0.004  # read the port at most this often, s (adds at most this latency)
_MAX_LINE = 256       # longest line kept waiting for its "\r" (a frame line has at most 146)
_CHUNK = 1 << 16      # most bytes taken in one read
_HEX = "0123456789abcdefABCDEF"
_CLASSIC = {str(n): n for n in range(9)}
_FD = {**{f"{d:X}": n for d, n in enumerate(CAN_FD_DLC)}, **{f"{d:x}": n for d, n in enumerate(CAN_FD_DLC)}}
# first character -> (index of the DLC digit, extended, remote, CAN FD, bit-rate switch, DLC table)
_KINDS = {"t": (4, False, False, False, False, _CLASSIC), "T": (9, True, False, False, False, _CLASSIC),
          "x": (9, True, False, False, False, _CLASSIC), "r": (4, False, True, False, False, _CLASSIC),
          "R": (9, True, True, False, False, _CLASSIC), "d": (4, False, False, True, False, _FD),
          "D": (9, True, False, True, False, _FD), "b": (4, False, False, True, True, _FD),
          "B": (9, True, False, True, True, _FD)}
# Lawicel status flag bit -> (SocketCAN error class, controller flags in data[1]) (linux/can/error.h)
_STATUS = ((0x01, 0x04, 0x01), (0x02, 0x04, 0x02), (0x04, 0x04, 0x0C), (0x08, 0x04, 0x01),
           (0x20, 0x04, 0x30), (0x40, 0x02, 0x00), (0x80, 0x80, 0x00))


class SlcanFrame:
    """A frame off the serial line, with the ``can.Message`` attributes the CAN adapter reads.

    ``data`` is ``bytes``, ``dlc`` its length in bytes (a remote frame: the length asked for),
    ``timestamp`` the host time the line was read, s (module notes).
    """

    __slots__ = ("arbitration_id", "is_extended_id", "is_remote_frame", "is_error_frame", "is_fd",
                 "bitrate_switch", "dlc", "data", "timestamp")

    def __init__(self, arbitration_id: int, is_extended_id: bool, is_remote_frame: bool,
                 is_error_frame: bool, is_fd: bool, bitrate_switch: bool, dlc: int, data: bytes,
                 timestamp: float) -> None:
        self.arbitration_id, self.is_extended_id = arbitration_id, is_extended_id
        self.is_remote_frame, self.is_error_frame = is_remote_frame, is_error_frame
        self.is_fd, self.bitrate_switch = is_fd, bitrate_switch
        self.dlc, self.data, self.timestamp = dlc, data, timestamp

    def __repr__(self) -> str:
        flags = "".join(c for c, on in zip("XREFB", (self.is_extended_id, self.is_remote_frame,
                        self.is_error_frame, self.is_fd, self.bitrate_switch), strict=True) if on)
        return f"SlcanFrame({self.arbitration_id:#x} {flags or '-'} dlc={self.dlc} {self.data.hex()})"


def _unparseable(line: str) -> str:
    return f"unparseable slcan line {line[:40]!r}"


def _status(line: str, timestamp: float) -> SlcanFrame | str | None:
    """A line that is not a frame: an error frame, ``None`` (a reply), or the reason it is bad."""
    if not line or line in ("z", "Z") or (line[0] in "VvN" and len(line) == 5 and line.isascii()
                                          and line[1:].isalnum()):
        return None  # OK, transmit acknowledged, version, serial number
    head = line[:1]
    if head == "F" and len(line) == 3 and not line[1:].strip(_HEX):
        flags = int(line[1:], 16)
        cls = ctrl = 0
        for bit, c, d in _STATUS:
            if flags & bit:
                cls, ctrl = cls | c, ctrl | d
        return SlcanFrame(cls, False, False, True, False, False, 8, bytes([0, ctrl, 0, 0, 0, 0, 0, 0]),
                          timestamp) if cls else None
    return _unparseable(line)


def parse_lines(lines: list[str], timestamp: float) -> list[SlcanFrame | str]:
    """Lawicel lines (without their ``\\r``) -> frames, and a reason string per unparseable line.

    Replies and a zero status are left out; ``timestamp`` (s) goes to every frame. Rules in the
    module docstring.
    """
    out: list[SlcanFrame | str] = []
    append, kinds, fromhex, hexdigits, frame = out.append, _KINDS, bytes.fromhex, _HEX, SlcanFrame
    for line in lines:
        kind = kinds.get(line[:1])
        if kind is None:
            item = _status(line, timestamp)
            if item is not None:
                append(item)
            continue
        at, ext, remote, fd, brs, dlcs = kind
        n = dlcs.get(line[at : at + 1])
        ident = line[1:at]
        if n is None or len(ident) != at - 1 or ident.strip(hexdigits):
            append(_unparseable(line))
            continue
        end = at + 1 if remote else at + 1 + 2 * n
        tail = line[end:]
        if tail and (len(tail) > 8 or tail.strip(hexdigits)):
            append(_unparseable(line))
            continue
        if remote:
            data = b""
        else:
            try:
                data = fromhex(line[at + 1 : end])
            except ValueError:
                data = b""
            if len(data) != n:
                append(_unparseable(line))
                continue
        can_id = int(ident, 16)
        if can_id > (0x1FFFFFFF if ext else 0x7FF):
            append(_unparseable(line))
            continue
        append(frame(can_id, ext, remote, False, fd, brs, n, data, timestamp))
    return out


class SlcanReader:
    """A Lawicel slcan adapter on a pyserial port, opened as python-can's ``slcanBus`` opens it.

    Parameters
    ----------
    channel : str
        pyserial port or URL (``/dev/ttyACM0``, ``socket://host:port``), optionally ``@baud``.
    tty_baudrate : int
        Serial baud rate (bit/s) unless ``channel`` says ``@baud``.
    bitrate : int, optional
        CAN bit rate, bit/s (one of python-can's slcan rates: ``S0``..``S9``).
    timing : can.BitTiming or can.BitTimingFd, optional
        Bit timing instead of ``bitrate`` (``s`` register for classic, ``S``/``Y`` for FD).
    btr : str, optional
        BTR0/BTR1 as 4 hex digits (``s`` command); python-can deprecates it.
    sleep_after_open : float
        Seconds to wait after opening the port (python-can's default 2).
    rtscts : bool
        Hardware handshake.
    listen_only : bool
        Open the channel with ``L`` instead of ``O``.
    timeout : float
        pyserial read timeout, s (used only on ports without a file descriptor).
    read_every_s : float
        Read the port at most this often, s.
    **ignored
        Other ``can.Bus`` options (``fd``, ``data_bitrate``, ...): python-can's slcan ignores them too.

    Raises
    ------
    ValueError
        No channel.
    can.CanInitializationError
        The port cannot be opened or the adapter not set up (a bad bit rate: ``__cause__`` is the
        ``ValueError``), as python-can raises it.
    """

    def __init__(self, channel: str, *, tty_baudrate: int = 115200, bitrate: int | None = None,
                 timing: BitTiming | BitTimingFd | None = None, btr: str | None = None,
                 sleep_after_open: float = slcanBus._SLEEP_AFTER_SERIAL_OPEN, rtscts: bool = False,
                 listen_only: bool = False, timeout: float = 0.001, read_every_s: float = READ_EVERY_S,
                 **ignored: object) -> None:
        if not channel:
            raise ValueError("Must specify a serial port.")
        if "@" in channel:
            channel, baud = channel.split("@")
            tty_baudrate = int(baud)
        self.channel_info = f"slcan {channel}"
        self.read_every_s = read_every_s
        self._rest = ""            # the start of a line whose "\r" has not come yet
        self._read_at = 0.0        # monotonic time of the last read, s
        self._epoch = time.time() - time.monotonic()  # frame timestamps: wall clock at open, then monotonic
        self._empty_at = time.monotonic()  # the port was last seen empty then
        self.arrived_after = self._epoch + self._empty_at  # ... as a timestamp (module notes)
        self._open_cmd = "L" if listen_only else "O"
        with error_check(exception_type=CanInitializationError):
            self.port = serial.serial_for_url(channel, baudrate=tty_baudrate, rtscts=rtscts, timeout=timeout)
        fd = getattr(self.port, "fd", None)
        self._fd = fd if isinstance(fd, int) else None
        try:
            time.sleep(sleep_after_open)
            with error_check(exception_type=CanInitializationError):  # python-can's order exactly
                if isinstance(timing, BitTiming):
                    timing = check_or_adjust_timing_clock(timing, valid_clocks=[8_000_000])
                    self._setup(f"s{timing.btr0:02X}{timing.btr1:02X}")
                elif isinstance(timing, BitTimingFd):
                    self._set_bitrate(timing.nom_bitrate, timing.data_bitrate)
                else:
                    if bitrate is not None and btr is not None:
                        raise ValueError("Bitrate and btr mutually exclusive.")
                    if bitrate is not None:
                        self._set_bitrate(bitrate, None)
                    if btr is not None:
                        self._setup("s" + btr)
                self._write(self._open_cmd)
        except BaseException:
            self.port.close()
            raise

    # -- commands (python-can's slcanBus.set_bitrate, set_bitrate_reg, open, close) -----------
    def _set_bitrate(self, bitrate: int, data_bitrate: int | None) -> None:
        if bitrate not in slcanBus._BITRATES:
            raise ValueError(f"Invalid bitrate, choose one of {', '.join(map(str, slcanBus._BITRATES))}.")
        data_bitrate = data_bitrate or 0
        if data_bitrate not in slcanBus._DATA_BITRATES:
            raise ValueError(f"Invalid data bitrate, choose one of "
                             f"{', '.join(map(str, slcanBus._DATA_BITRATES))}.")
        self._setup(slcanBus._BITRATES[bitrate], slcanBus._DATA_BITRATES[data_bitrate])

    def _setup(self, *commands: str) -> None:
        """Close the channel, send ``commands``, open it (python-can's sequence)."""
        self._write("C")
        for cmd in commands:
            self._write(cmd)
        self._write(self._open_cmd)

    def _write(self, command: str) -> None:
        with error_check("Could not write to serial device"):
            self.port.write(command.encode() + b"\r")
            self.port.flush()

    # -- reading --------------------------------------------------------------------------------
    def recv_batch(self, timeout: float | None) -> list[SlcanFrame | str]:
        """Every complete line waiting, parsed; waits up to ``timeout`` s (``None``: no limit).

        Reads at most every :attr:`read_every_s`: lines that came sooner wait for the next read.
        Returns frames and reason strings (unparseable lines) in line order; ``[]`` on timeout.
        Raises ``OSError`` (``serial.SerialException``) when the port is gone.
        """
        now = time.monotonic()
        deadline = None if timeout is None else now + timeout
        while True:
            # sleep out the rest of the period first, then look: one wake-up per read
            ready_at = self._read_at + self.read_every_s
            if now < ready_at:
                if deadline is not None and deadline < ready_at:
                    if deadline > now:
                        time.sleep(deadline - now)
                    return []
                time.sleep(ready_at - now)
            if not self._wait(None if deadline is None else max(0.0, deadline - time.monotonic())):
                self._empty_at = time.monotonic()  # nothing came: empty until now
                return []
            self.arrived_after = self._epoch + self._empty_at
            self._read_at = now = time.monotonic()
            chunk = self._read_waiting()
            if len(chunk) < _CHUNK:  # drained: what comes next arrives after this read
                self._empty_at = now
            items = self.feed(chunk, self._epoch + now)
            if items:
                return items

    def feed(self, chunk: bytes, timestamp: float) -> list[SlcanFrame | str]:
        """Bytes off the port (any split) -> :func:`parse_lines` of the lines they complete."""
        text = self._rest + chunk.decode("latin-1").replace("\a", "\r")
        *lines, self._rest = text.split("\r")
        if len(self._rest) > _MAX_LINE:  # no "\r" for too long: not slcan, or a stuck line
            lines.append(self._rest)
            self._rest = ""
        return parse_lines(lines, timestamp) if lines else []

    def _wait(self, timeout: float | None) -> bool:
        """Whether bytes are waiting, after up to ``timeout`` s (``None``: forever). A wait that
        begins on an empty port and is woken by bytes saw them come: :attr:`arrived_after` moves
        up to one read period before the wake (at least to the wait's start)."""
        if self._fd is not None:
            if select.select([self._fd], [], [], 0)[0]:
                return True
            self._empty_at = time.monotonic()
            if timeout == 0 or not select.select([self._fd], [], [], timeout)[0]:
                return False
            self._empty_at = max(self._empty_at, time.monotonic() - self.read_every_s)
            return True
        end = None if timeout is None else time.monotonic() + timeout
        while not self.port.in_waiting:  # a port without a file descriptor: poll every 1 ms
            self._empty_at = time.monotonic()
            if end is not None and time.monotonic() >= end:
                return False
            time.sleep(0.001)
        return True

    def _read_waiting(self) -> bytes:
        if self._fd is None:
            return self.port.read(self.port.in_waiting)
        try:
            chunk = os.read(self._fd, _CHUNK)
        except BlockingIOError:
            return b""
        if not chunk:
            raise serial.SerialException("end of file on the port: the adapter was unplugged or "
                                         "its other end closed")
        return chunk

    def fileno(self) -> int:
        """The port's file descriptor (``NotImplementedError`` when it has none)."""
        if self._fd is None:
            raise NotImplementedError("fileno is not implemented for this port")
        return self._fd

    def shutdown(self) -> None:
        """Close the channel (``C``) and the port; a second call does nothing."""
        port, self.port = self.port, None
        if port is None:
            return
        try:
            with error_check("Could not write to serial device"):
                port.write(b"C\r")
                port.flush()
        finally:
            port.close()
