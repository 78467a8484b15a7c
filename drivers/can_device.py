"""CAN and CAN FD front-ends through python-can (back-end name ``"can"``).

::

    with open_device("can://socketcan/can0?rig=rigs/sampson.toml&dbc=fd24&fd=1") as dev:
        for block in dev: ...

The address is ``INTERFACE/CHANNEL`` of any python-can interface (``socketcan/can0``,
``pcan/PCAN_USBBUS1``, ``kvaser/0``, ``vector/0``, ``slcan//dev/ttyACM0``, ``virtual/0``) and a
query: ``rig``, ``dbc``, ``channels``, ``fs_hz``, ``block_s``, ``bitrate``, ``data_bitrate``, ``fd``,
``duration_s``, ``idle_s``, ``quiet_s``, ``group_timeout_s``, ``clock_tolerance_s``, ``bus`` (one more
``INTERFACE/CHANNEL``, repeatable); any other key goes to ``can.Bus`` (e.g. ``sleep_after_open=0``
for slcan). slcan is opened as python-can opens it but read by
:class:`ramdaq.drivers.slcan_reader.SlcanReader`: every byte waiting at most every ``read_every_s``
(default 4 ms), the lines parsed in bulk without a ``can.Message`` each (python-can's one byte
per call cannot keep up with 16 ch x 2.048 kHz); with ``can_filters`` it is python-can's own bus.

The frames are described by a DBC (:mod:`ramdaq.drivers.can_frames`). Each channel group's frames are
put together cycle by cycle by their SEQ counter; a block holds every channel, so a sample is
delivered only when every group delivered it. Several buses may feed one trial: a frame's
identifier names its group, whatever bus it came on. Nothing is filled in:

* a lost, corrupted (``bad_crc``) or wrong-length (``wrong_dlc``) frame loses its cycle, a SEQ
  jump loses the cycles skipped: the next block's ``first_sample`` jumps by exactly the samples
  lost, and one ``seq_gap`` per jump says them at the first missing sample's time (``groups``:
  the groups that lacked them; the same instants lost in two groups are one gap, once);
* a group silent for ``group_timeout_s`` while another delivers (and behind it by that much of
  samples: a host that stalled between two groups' frames has not heard a silence) is declared
  missing (``group_timeout``, at the stream time it fell silent, with its channels; frames of
  it still held late beside its stream -- a sender's stall before a burst -- are placed first,
  so the time is that of its last frame received). A block carries
  every channel and the recording has no per-channel hole, so nothing is recorded until it
  speaks again: the other groups' samples of that span are lost -- never the silent group's
  invented -- and the ``seq_gap`` when it is back counts them. A stream that ends while a group
  is missing (or one that never spoke, or fell behind the others by more than
  ``group_timeout_s`` of samples) has stopped where that group stopped: a ``seq_gap`` with
  ``to_end`` counts what the others sent after, and :meth:`read` raises
  :class:`~ramdaq.drivers.errors.DeviceClosed` naming the group, its channels and the time
  (``ramdaq record`` exits 1), so that such a recording never ends as a good one;
* error frames (SocketCAN error classes: bus-off 0x40, restarted 0x100), ``bus.state`` and frames
  resuming give ``error_frame``, ``bus_off`` and ``bus_recovered``;
* SEQ and the host clock. SEQ wraps (classic: 256 cycles = 0.375 s at 2.048 kHz; fd24: 65 536
  cycles = 640 s), so a silence longer than that cannot be counted by SEQ alone, bus-off report or
  not. Every frame's arrival time on the host (``msg.timestamp``; slcan: the last time the port
  was seen empty before its line, :attr:`~ramdaq.drivers.slcan_reader.SlcanReader.arrived_after`,
  so a backlog the reader took late is not a silence) is held against the group's sample clock
  (:class:`~ramdaq.drivers.can_frames.CycleAssembler` gives the rule): a frame later or earlier
  than SEQ says by more than ``clock_tolerance_s`` (default 0.1 s) is held until the frames after
  it show at what pace they come. Frames whose SEQ goes on from the group's but which came late
  by more than the tolerance (a stalled sender or host) are placed where SEQ says, with a
  ``delayed_frames`` event -- also when the lateness is whole SEQ periods: a stall cannot be told
  from a silence of exactly whole wraps, and reading it as wraps moved every later sample (the
  event gives ``whole_wraps_late``). After a SEQ jump, whole wraps that explain the lateness
  within the tolerance are counted (``seq_wrap``: the gap is exact); when nothing does (a
  front-end restarted, the tolerance is not under half the SEQ period) the samples are
  re-anchored from the host clock and a ``gap_unknown`` event gives the estimated gap, what SEQ
  said and the uncertainty -- the length is never guessed silently. Frames arriving
  faster than real time (a reader catching up after a stall, a replay) are judged by SEQ. A SEQ jump of
  more than 3 cycles is believed when the group's frames go on from it for more than 3 cycles
  (a lone one is a ``seq_outlier``);
* a second sender with the group's identifiers and valid CRCs (a twin front-end) shows as a
  second SEQ history interleaved with the group's: it is a bus fault (``foreign_sender``, then
  ``foreign_sender_gone`` when it has been quiet for 0.25 s), its frames are dropped and counted
  (``foreign_frame``), and a cycle in which the two senders' frames disagree is lost
  (``conflicting_frame``); no sample of it is ever placed;
* frames of other nodes (``unrelated_frame``), unparseable lines from a serial adapter
  (``bad_frame``, with the line), late and duplicate frames are counted; these faults are
  reported at most once per ``report_s`` with their counts, except those that lose samples
  (``bad_frame``, ``wrong_dlc``, ``bad_crc``: each at once, at the cycle its SEQ names, else at its
  group's stream time).
  ``bus_lost`` (the interface failed) ends that bus; when none is left, the samples already
  assembled are handed out and then :meth:`read` raises
  :class:`~ramdaq.drivers.errors.DeviceClosed` naming the buses;
* ``no_data`` / ``data_back``: no block for ``quiet_s`` (default 1 s; :mod:`ramdaq.drivers.base`),
  also before the first frame; ``idle_s`` (default: never) instead *ends* the stream after that
  long without a frame (only once frames have come);
* faults of a normal connect -- before the first block, a torn first line (``bad_frame``), an
  incomplete first cycle (``seq_gap``), the adapter's start-up backlog (``delayed_frames``,
  python-can's slcan sleeps 2 s after opening) -- carry ``at_connect``: recorded, not shown.
"""

from __future__ import annotations

import hashlib
import math
import time
from collections import Counter
from pathlib import Path
from urllib.parse import parse_qsl

import can
import numpy as np

from ..analysis.model.rig import Rig, load_rig, parse_rig
from .base import QUIET_S, TIMED_OUT, Device, DeviceFault
from .block import Block, StreamInfo, sample_time_ns
from .can_frames import UNRELATED, CycleAssembler, FrameCodec
from .errors import DeviceClosed, DeviceNotFound
from .fault_words import number_runs
from .rig_channels import rig_channels
from .slcan_reader import SlcanFrame, SlcanReader

__all__ = ["CanDevice", "parse_address"]

_BUS_OFF, _RESTARTED, _CRTL, _CRTL_ACTIVE = 0x40, 0x100, 0x04, 0x40  # linux/can/error.h
_OPTIONS = {"rig", "dbc", "channels", "fs_hz", "block_s", "bitrate", "data_bitrate", "fd", "bus",
            "duration_s", "idle_s", "quiet_s", "group_timeout_s", "clock_tolerance_s", "scale"}
_CONNECT_KINDS = ("bad_frame", "seq_gap", "delayed_frames", "late_frame")
_PROMPT = ("bad_frame", "wrong_dlc", "bad_crc")  # each loses samples: reported at once, never summed


def _coerce(text: str) -> object:
    low = text.lower()
    if low in ("true", "yes", "on", "false", "no", "off"):
        return low in ("true", "yes", "on")
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def parse_address(address: str) -> tuple[str, str, dict[str, object], list[str]]:
    """``"slcan//dev/pts/3?rig=r.toml&bus=virtual/1"`` -> interface, channel, options, extra buses."""
    head, _, query = address.partition("?")
    interface, _, channel = head.partition("/")
    if not interface:
        raise ValueError(f"can://{address}: expected INTERFACE/CHANNEL, e.g. socketcan/can0")
    options: dict[str, object] = {}
    buses = []
    for key, value in parse_qsl(query, keep_blank_values=True):
        if key == "bus":
            buses.append(value)
        else:
            options[key] = value if key in ("rig", "dbc", "scale") else _coerce(value)
    return interface, channel, options, buses


def _open_bus(interface: str, channel: str, options: dict) -> can.BusABC | SlcanReader:
    """``can.Bus``, except slcan: :class:`SlcanReader` (python-can's bus for ``can_filters``)."""
    if interface == "slcan" and "can_filters" not in options:
        return SlcanReader(channel, **options)
    return can.Bus(interface=interface, channel=channel, **options)


class CanDevice(Device):
    """Sample frames from one or more CAN buses (back-end name ``"can"``).

    Parameters
    ----------
    address : str
        ``INTERFACE/CHANNEL`` with optional query options (module docstring).
    dbc : str or Path, optional
        Frame layout: ``classic``, ``fd24``, ``fd16`` or a DBC path (default ``classic``, or
        ``fd24`` with ``fd``).
    channels : int, optional
        Stream the DBC's channels 1..``channels`` (default: the rig's channel count, else all).
    fs_hz : float, optional
        Sample rate, Hz (default: the rig's, else 2048).
    block_s : float, optional
        Block length, s (default 0.05).
    rig : Rig, str or Path, optional
        The rig (a path or TOML text): channel names, gage numbers, scales; kept in the stream.
    scale : float or sequence, optional
        SI units per count when no rig is given (default 1.0, units ``count``).
    bitrate, data_bitrate : int, optional
        Passed to ``can.Bus``; ``fd`` opens CAN FD buses.
    extra_buses : sequence of str
        More ``INTERFACE/CHANNEL`` buses whose frames join the same trial.
    duration_s : float, optional
        End the stream after this many seconds of samples (default: never).
    idle_s : float, optional
        End the stream when no frame came for this long after the first (default: never).
    group_timeout_s : float
        A group silent this long while another delivers is declared missing (default 0.5 s).
    clock_tolerance_s : float
        How far a frame's host arrival time may stray from its place on the sample clock before
        the clock is consulted about SEQ, s (default 0.1; module notes).
    report_s : float
        Counted faults are reported at most this often, s.
    bus_options : dict, optional
        More keyword arguments for ``can.Bus``.
    """

    kind = "can"

    def __init__(self, address: str = "virtual/0", *, dbc: str | Path | None = None,
                 channels: int | None = None, fs_hz: float | None = None,
                 block_s: float | None = None, rig: Rig | str | Path | None = None,
                 scale: float | list[float] | None = None, bitrate: int | None = None,
                 data_bitrate: int | None = None, fd: bool | None = None,
                 extra_buses: list[str] | tuple[str, ...] = (), duration_s: float | None = None,
                 idle_s: float | None = None, group_timeout_s: float | None = None,
                 clock_tolerance_s: float | None = None, report_s: float = 1.0,
                 bus_options: dict | None = None) -> None:
        super().__init__()
        interface, channel, q, more = parse_address(address)
        self._bus_settings(q, bitrate, data_bitrate, fd, bus_options)
        self.specs = [(interface, channel)] + [self._split(s) for s in [*more, *extra_buses]]
        self.codec = FrameCodec(dbc if dbc is not None else q.get("dbc"), fd=self.fd)
        rig = rig if rig is not None else q.get("rig")
        if isinstance(rig, str) and "\n" in rig:
            rig = parse_rig(rig, source=f"can://{address}:rig")
        self.rig = rig if rig is None or isinstance(rig, Rig) else load_rig(rig)
        n_rig = self.rig.n_channels if self.rig else None  # gages and forces
        n = int(channels if channels is not None else q.get("channels", n_rig or len(self.codec.channels)))
        self.fs_hz = float(fs_hz or q.get("fs_hz") or (self.rig.daq.sample_rate_hz if self.rig else 2048.0))
        tol = clock_tolerance_s if clock_tolerance_s is not None else q.get("clock_tolerance_s", 0.1)
        self.clock_tolerance_s = float(tol)
        if not self.clock_tolerance_s > 0:
            raise ValueError(f"can://{address}: clock_tolerance_s ({tol}) must be positive")
        self.groups = self._assemblers(address, n, n_rig)
        self.block_n = max(1, round(float(block_s or q.get("block_s", 0.05)) * self.fs_hz))
        dur = duration_s if duration_s is not None else q.get("duration_s")
        self.total_n = None if dur is None else round(float(dur) * self.fs_hz)
        idle = idle_s if idle_s is not None else q.get("idle_s")
        self.idle_s = None if idle is None else float(idle)
        self.quiet_s = float(q.get("quiet_s", QUIET_S))  # the query's only (module notes)
        if not self.quiet_s > 0:
            raise ValueError(f"can://{address}: quiet_s ({self.quiet_s}) must be positive")
        self.group_timeout_s = float(group_timeout_s or q.get("group_timeout_s", 0.5))
        self.report_s = report_s
        self.scale = self._scales(scale if scale is not None else q.get("scale", 1.0), n)
        self.units = "m/s^2" if self.rig or scale is not None or "scale" in q else "count"
        self.order = np.argsort([c for gr in self.groups.values() for c in gr.lay.channels])
        self.address = address
        self._counts: Counter = Counter()
        self._frames = self._good = 0
        self._dirty = False
        self._buses: list = []
        self._lost: list[str] = []  # "bus (error)" of each bus lost
        self._origin: int | None = None
        self._pos = 0
        self._seq = 0
        self._final = self._ended = False
        self._pending: dict[str, dict] = {}
        self._reported: dict[str, float] = {}
        self._first_wall: float | None = None
        self._last_wall = 0.0
        self._next_poll = 0.0
        self._states: dict[str, str] = {}  # bus name -> "active", "passive" or "bus_off"
        self._names: list[str] = []
        self._off_since: dict[str, float] = {}
        self._last_seen: dict[int, float] = {}    # group -> monotonic time of that frame, s
        self._silent: dict[int, int] = {}  # group declared missing -> sample it went silent at
        self._gap_at: tuple[int, list[int]] | None = None  # a gap the blocks are skipping: from, groups
        self._said_to = 0  # the gap said ahead ends here (absolute sample)
        self._stateful: list[bool] = []
        self._rr = 0

    def _bus_settings(self, q: dict, bitrate: int | None, data_bitrate: int | None,
                      fd: bool | None, bus_options: dict | None) -> None:
        """``self.bus_options`` and ``self.fd`` from the arguments, else the address's query."""
        unknown = {k: q.pop(k) for k in list(q) if k not in _OPTIONS}
        self.bus_options = {**unknown, **(bus_options or {})}
        for k, v in dict(bitrate=bitrate, data_bitrate=data_bitrate).items():
            v = v if v is not None else q.get(k)
            if v is not None:
                self.bus_options[k] = int(v)
        self.fd = bool(fd if fd is not None else q.get("fd", False))
        if self.fd:
            self.bus_options["fd"] = True

    def _assemblers(self, address: str, n: int, n_rig: int | None) -> dict[int, CycleAssembler]:
        """One cycle assembler per frame group of channels 1..n; refuses a layout that splits a
        group, a rig with fewer channels, or a rig ADC finer than the frames carry."""
        groups = {g: CycleAssembler(lay, cycles_per_s=self.fs_hz / lay.samples_per_cycle,
                                    tolerance_s=self.clock_tolerance_s)
                  for g, lay in self.codec.groups.items() if max(lay.channels) <= n}
        if sorted(c for gr in groups.values() for c in gr.lay.channels) != list(range(1, n + 1)):
            names = {g: f"{lay.channels[0]}-{lay.channels[-1]}" for g, lay in self.codec.groups.items()}
            raise ValueError(f"can://{address}: channels 1-{n} are not whole groups of {self.codec.name} "
                             f"(groups {names})")
        if n_rig is not None and n_rig < n:
            raise ValueError(f"can://{address}: {n} channels, but the rig has {n_rig}")
        bits = min(gr.lay.sample_bits for gr in groups.values())
        if self.rig and self.rig.daq.adc_bits > bits:
            raise ValueError(f"can://{address}: rig ADC has {self.rig.daq.adc_bits} bits, "
                             f"{self.codec.name} carries {bits}-bit samples")
        return groups

    def _scales(self, scale: float | str | list[float], n: int) -> np.ndarray:
        """Counts -> SI per channel, shape (n,): the rig's (m/s^2, a force channel's N), else
        ``scale`` (one or n values)."""
        if self.rig:
            return rig_channels(self.rig).scales[:n]
        return np.broadcast_to(np.asarray(
            [float(x) for x in scale.split(",")] if isinstance(scale, str) else scale, float), (n,)).copy()

    @staticmethod
    def _split(spec: str) -> tuple[str, str]:
        interface, _, channel = spec.partition("/")
        return interface, channel

    # -- Device hooks ------------------------------------------------------------------------
    def _open(self) -> StreamInfo:
        for interface, channel in self.specs:
            try:
                bus = _open_bus(interface, channel, self.bus_options)
            except Exception as err:
                self._close()  # the buses already opened
                if isinstance(err.__cause__, ValueError):  # python-can wraps a bad argument
                    raise ValueError(f"can://{interface}/{channel}: {err.__cause__}") from err
                if isinstance(err, (can.CanInterfaceNotImplementedError, can.CanInitializationError,
                                    ImportError, OSError)):
                    raise DeviceNotFound(f"can://{interface}/{channel}: cannot open ({err})") from err
                raise
            self._buses.append(bus)
            self._names.append(f"{interface}/{channel}")
            self._stateful.append(getattr(type(bus), "state", can.BusABC.state) is not can.BusABC.state)
        n = len(self.scale)
        if self.rig:  # its gages and force channels (N: the trigger's force mode)
            ch = rig_channels(self.rig)
            names, units, numbers = ch.names[:n], ch.units[:n], ch.gages[:n]
        else:
            numbers = tuple(range(1, n + 1))
            names, units = tuple(f"g{k:02d}" for k in numbers), (self.units,) * n
        return StreamInfo(
            device="can://" + "+".join(self._names), fs_hz=self.fs_hz,
            channels=names, units=units, gages=numbers,
            rig_toml=self.rig.text if self.rig else "",
            extra={"dbc": self.codec.name,
                   "dbc_sha256": hashlib.sha256(self.codec.path.read_bytes()).hexdigest(),
                   "groups": {str(g): list(gr.lay.channels) for g, gr in self.groups.items()},
                   "samples_per_cycle": {str(g): gr.T for g, gr in self.groups.items()},
                   "buses": list(self._names), "block_samples": self.block_n,
                   "adc_bits": self.rig.daq.adc_bits if self.rig else
                   min(gr.lay.sample_bits for gr in self.groups.values()),
                   **({"medium": self.rig.medium, "rig_name": self.rig.name} if self.rig else {})},
        )

    def _close(self) -> None:
        for bus in self._buses:
            try:
                bus.shutdown()
            except Exception:  # noqa: BLE001 - a failing interface must not stop the others closing
                pass
        self._buses, self._names, self._stateful = [], [], []

    def _read(self, timeout: float | None) -> Block | None:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            if self._dirty or self._final:  # a cycle became final since the last look
                block = self._next_block()
                if block is not None:
                    return block
                self._dirty = False
            if self._ended:
                for kind in list(self._pending):
                    self._report(kind, math.inf)
                if self._lost and not self._buses:
                    raise DeviceClosed(f"can: {'; '.join(self._lost)}: the device vanished")
                missing = self._missing_to_end()
                if missing:
                    self._silent.clear()
                    raise DeviceClosed(missing)
                return None
            wait = 0.05
            if deadline is not None:
                wait = min(wait, deadline - time.monotonic())
                if wait <= 0:
                    return TIMED_OUT
            got = self._recv(wait)
            now = time.monotonic()
            if got is not None:
                frames, i, after = got
                for msg in frames:
                    if type(msg) is str:  # an unparseable slcan line
                        self._count("bad_frame", now, reason=msg[:80])
                    else:
                        self._on_message(msg, i, now, msg.timestamp if after is None else after)
            if now >= self._next_poll or got is None:
                self._poll(now)

    # -- receiving ---------------------------------------------------------------------------
    def _recv(self, timeout: float) -> tuple[list[can.Message | SlcanFrame | str], int, float | None] | None:
        """Frames of the next bus that has some (round robin), its index, and for slcan the host
        time all of them arrived after (else ``None``: each frame's own timestamp says); slcan:
        all lines waiting, with a reason string in place of each unparseable one."""
        n = len(self._buses)
        for k in range(n):
            i = (self._rr + k) % n
            bus = self._buses[i]
            try:
                if type(bus) is SlcanReader:
                    got = bus.recv_batch(timeout if n == 1 else 0.0)
                else:
                    msg = bus.recv(timeout if n == 1 else 0.0)
                    got = None if msg is None else [msg]
            except (ValueError, IndexError, UnicodeDecodeError) as err:  # an unparseable serial line
                self._count("bad_frame", time.monotonic(), reason=f"unparseable: {err}"[:80])
                return None
            except (can.CanError, OSError) as err:
                self._lose_bus(i, err)
                return None
            if got:
                self._rr = (i + 1) % n
                return got, i, bus.arrived_after if type(bus) is SlcanReader else None
        if n > 1:
            time.sleep(min(timeout, 0.001))
        return None

    def _lose_bus(self, i: int, err: Exception) -> None:
        why = " ".join(str(err).split())[:120] or type(err).__name__
        self._lost.append(f"{self._names[i]} lost ({why})")
        self._fault("bus_lost", self._t_ns(), bus=self._names.pop(i), error=why)
        self._stateful.pop(i)
        bus = self._buses.pop(i)
        try:
            bus.shutdown()
        except Exception:  # noqa: BLE001 - already failed
            pass
        if not self._buses:
            self._finish()

    def _on_message(self, msg: can.Message | SlcanFrame, bus_i: int, now: float, t: float) -> None:
        """One frame off bus ``bus_i``; ``t`` is its arrival time on the host, s."""
        self._frames += 1
        if msg.is_error_frame:
            self._on_error_frame(msg, bus_i, now)
            return
        hit = self.codec.check(msg)
        if type(hit) is str or hit[0].group not in self.groups:
            self._rejected(msg, hit if type(hit) is str else UNRELATED, now)
            return
        if self._states and self._states.get(self._names[bus_i]) == "bus_off":
            self._bus_state(bus_i, "active", now, why="frames resumed")
        lay, seq = hit
        grp = self.groups[lay.group]
        if grp.base is None:
            started = [g.seen() for g in self.groups.values() if g.base is not None]
            grp.start(seq, max(started) // grp.T if started else None, t)
            if self._origin is None:
                self._origin = self._pos = grp.done()
                self._first_wall = now
        self._last_seen[lay.group], self._last_wall = now, now
        if self._silent:
            self._silent.pop(lay.group, None)
        base = grp.base
        problem = grp.put(seq, lay.slot, msg.data, t)
        if problem:
            self._count(problem, now, group=lay.group, id=hex(msg.arbitration_id))
        else:
            self._good += 1
        if grp.problems or grp.notes:
            self._report_decisions(grp, now)
        self._dirty = self._dirty or grp.base != base
        if grp.lost:
            self._report_lost(grp, now)

    def _rejected(self, msg: can.Message | SlcanFrame, kind: str, now: float) -> None:
        """Count a frame refused by the codec; one of a group's (a wrong length, a failed CRC) is
        stamped at the cycle its SEQ names, when it still holds one within the group's reorder
        window (frames queued faster than real time are held, so the group's stream lags the
        frames read), else where that group's stream stands -- never where the group furthest
        ahead does."""
        lay = self.codec.layout_of(msg)
        grp = self.groups.get(lay.group) if lay is not None and kind != UNRELATED else None
        at = None
        if grp is not None and grp.base is not None:
            cycle = grp.hi + 1
            if len(msg.data) >= lay.seq_end:  # a wrong length may keep its SEQ; a bad CRC may not
                named = grp.cycle_of(int.from_bytes(msg.data[lay.seq_at:lay.seq_end], "little"))
                if abs(named - cycle) <= grp.window:
                    cycle = named
            at = self._t_ns(cycle * grp.T)
        self._count(kind, now, at, id=hex(msg.arbitration_id), dlc=len(msg.data),
                    **({"group": grp.lay.group} if grp is not None else {}))

    def _on_error_frame(self, msg: can.Message | SlcanFrame, bus_i: int, now: float) -> None:
        cls, data = msg.arbitration_id, bytes(msg.data)
        if cls & _BUS_OFF:
            self._bus_state(bus_i, "bus_off", now, why=f"error frame class {cls:#x}")
        elif cls & _RESTARTED or (cls & _CRTL and len(data) > 1 and data[1] & _CRTL_ACTIVE):
            self._bus_state(bus_i, "active", now, why=f"error frame class {cls:#x}")
        else:
            self._count("error_frame", now, error_class=hex(cls), data=data.hex())

    def _bus_state(self, bus_i: int, state: str, now: float, why: str) -> None:
        bus = self._names[bus_i]
        before = self._states.get(bus, "active")
        self._states[bus] = state
        if state == "bus_off" and before != "bus_off":
            self._fault("bus_off", self._t_ns(), bus=bus, reason=why)
            self._off_since[bus] = now
        elif state == "active" and before == "bus_off":
            self._fault("bus_recovered", self._t_ns(), bus=bus, reason=why,
                        off_s=round(now - self._off_since.pop(bus, now), 3))
        elif state == "passive" and before == "active":
            self._count("error_passive", now, bus=bus)

    def _poll(self, now: float) -> None:
        """Periodic work: bus states, silent groups, idle end, due fault reports."""
        self._next_poll = now + 0.05
        for i, bus in enumerate(self._buses):
            if not self._stateful[i]:
                continue  # the interface does not report its state
            try:
                state = bus.state
            except Exception:  # noqa: BLE001 - a state that cannot be read is not a fault
                continue
            name = {can.BusState.ERROR: "bus_off", can.BusState.PASSIVE: "passive"}.get(state, "active")
            if name != self._states.get(self._names[i], "active"):
                self._bus_state(i, name, now, why=f"bus.state {state.name}")
        started = [g for g in self.groups.values() if g.base is not None]
        if started and len(self.groups) > 1 and now - self._last_wall < self.group_timeout_s:
            lead = max(g.done() for g in started)
            for g, grp in self.groups.items():
                quiet = now - self._last_seen.get(g, self._first_wall)
                if quiet > self.group_timeout_s and (grp.base is None or grp.done() < lead):
                    if g not in self._silent:
                        # frames held late beside the group (a stall of the sender before a
                        # burst) are its last: placed first, it is silent from where they end
                        grp.settle_held()
                        self._dirty = True
                        if self._behind(grp, lead) <= self._timeout_samples():
                            continue  # the host stalled between two groups' frames: not silence
                        self._timed_out(g, grp, quiet, lead)
                    grp.skip_to(lead // grp.T)
                    self._report_lost(grp, now)
                    self._dirty = True
        if self.idle_s is not None and self._origin is not None and now - self._last_wall > self.idle_s:
            self._finish()
        for kind in list(self._pending):
            if now - self._reported.get(kind, -math.inf) >= self.report_s:
                self._report(kind, now)

    def _timeout_samples(self) -> int:
        """``group_timeout_s`` in samples of the stream."""
        return round(self.group_timeout_s * self.fs_hz)

    def _behind(self, grp: CycleAssembler, lead: int) -> int:
        """Samples group ``grp``'s stream stands behind ``lead`` (the furthest group's)."""
        return lead - (self._origin if grp.base is None else grp.done())

    def _timed_out(self, g: int, grp: CycleAssembler, quiet: float, lead: int) -> None:
        """``group_timeout``: group ``g`` is declared missing from where its stream stands."""
        at = grp.seen() if grp.base is not None else (self._origin or 0)
        self._silent[g] = at
        self._fault("group_timeout", self._t_ns(at), group=g, channels=self._channels_of([g]),
                    silent_s=round(quiet, 3), others_ahead_samples=max(0, lead - at))

    def _missing_to_end(self) -> str | None:
        """The line that ends a stream in which a group was silent to the end while another
        delivered (declared missing, or behind the others by more than ``group_timeout_s`` of
        samples when the frames came faster than real time), or never spoke; ``None`` if none.

        Why the stream ends with an error there: a block carries every channel, so the samples
        the other groups delivered after the silence are not recorded (a sample of the silent
        group's channels would have to be invented). They are not dropped silently --
        ``group_timeout`` and a ``seq_gap`` with ``to_end`` give the group, its channels and the
        time --, but a recording that stops where a group stopped must not end as a good one.
        """
        if self._origin is None:
            return None
        lead = max(g.done() for g in self.groups.values() if g.base is not None)
        gone = dict(self._silent)
        for g, grp in self.groups.items():
            behind = self._behind(grp, lead)
            if g not in gone and behind > self._timeout_samples():
                self._timed_out(g, grp, behind / self.fs_hz, lead)
                gone[g] = self._silent[g]
        if not gone:
            return None
        said = [f"frame group {g} (channels {self._channels_of([g])}) silent from "
                f"{self._t_ns(at) / 1e9:.3f} s to the end" for g, at in sorted(gone.items())]
        first = min(gone.values())
        return (f"can: {'; '.join(said)} while the others delivered: their {max(0, lead - first)} "
                "samples from then on are not recorded (a block carries every channel)")

    def _finish(self) -> None:
        for grp in self.groups.values():
            if grp.base is not None:
                grp.finish()
                self._report_decisions(grp, math.inf)
                self._report_lost(grp, math.inf)
        self._final = True

    # -- faults ------------------------------------------------------------------------------
    def _t_ns(self, sample: int | None = None) -> int:
        """Device time of ``sample`` (absolute), default the newest sample seen."""
        s = max((g.seen() for g in self.groups.values()), default=0) if sample is None else sample
        return sample_time_ns(max(0, s - (self._origin or 0)), self.fs_hz)

    def _fault(self, kind: str, t_ns: int, **detail: object) -> None:
        """Base's, with ``at_connect`` on the faults of a normal connect (module notes)."""
        if self._seq == 0 and kind in _CONNECT_KINDS:
            detail["at_connect"] = True
        self._faults.append(DeviceFault(kind, t_ns, dict(detail)))

    def _t_heard_ns(self) -> int:
        return self._t_ns() if self._origin is not None else 0

    @property
    def counters(self) -> Counter:
        """Frames received, good sample frames, and each fault counted so far."""
        return Counter(frames=self._frames, good_frames=self._good, **self._counts)

    def _count(self, kind: str, now: float, t_ns: int | None = None, n: int = 1, **detail: object) -> None:
        self._counts[kind] += n
        p = self._pending.setdefault(kind, {"count": 0, "t_ns": self._t_ns() if t_ns is None else t_ns})
        p["count"] += n
        for key in ("missing_samples", "missing_cycles", "incomplete_cycles"):
            if key in detail:
                p[key] = p.get(key, 0) + detail.pop(key)
        if "groups" in detail:
            p["groups"] = sorted(set(p.get("groups", [])) | set(detail.pop("groups")))
        p.update(detail)
        if kind in _PROMPT or now - self._reported.get(kind, -math.inf) >= self.report_s:
            self._report(kind, now)

    def _report(self, kind: str, now: float) -> None:
        p = self._pending.pop(kind, None)
        if p:
            t_ns = p.pop("t_ns")
            self._fault(kind, t_ns, total=self._counts[kind], **p)
            self._reported[kind] = now

    def _report_decisions(self, grp: CycleAssembler, now: float) -> None:
        """What the group's assembler decided about frames it held: their problems counted, its
        notes (foreign sender, SEQ wraps counted by time, gaps of unknown length) as events."""
        for kind, n in grp.problems.items():
            self._count(kind, now, n=n, group=grp.lay.group)
        grp.problems.clear()
        for note in grp.notes:
            self._fault(note.kind, self._t_ns(note.cycle * grp.T), group=grp.lay.group, **note.detail)
            if note.kind == "gap_unknown":  # one front-end: its other groups re-anchor alike
                for other in self.groups.values():
                    if other is not grp and other.T == grp.T:
                        other.hint = note.shift
        grp.notes.clear()

    @staticmethod
    def _report_lost(grp: CycleAssembler, now: float) -> None:
        """Forget the group's lost cycles: what the stream misses is said where the blocks skip it
        (:meth:`_gap_closed`), once for every group that lacks those samples."""
        grp.lost = []

    # -- blocks ------------------------------------------------------------------------------
    def _next_block(self) -> Block | None:
        if self._origin is None or self._ended:
            self._ended = self._ended or self._final
            return None
        groups = list(self.groups.values())
        if any(g.base is None for g in groups):
            self._ended = self._final
            return None
        ready = min(g.done() for g in groups)
        limit = None if self.total_n is None else self._origin + self.total_n
        if limit is not None:
            ready = min(ready, limit)
        last = self._final or ready == limit
        if ready - self._pos < self.block_n and not last:
            return None
        if last:  # report what is pending while blocks remain to carry it
            for kind in list(self._pending):
                self._report(kind, math.inf)
        for g in groups:
            g.decode(self.codec)
        p = self._pos
        while p < ready:
            spans = [g.present_from(p) for g in groups]
            start = max((s[0] if s else ready) for s in spans)
            if start > p:
                if self._gap_at is None and p >= self._said_to:
                    self._gap_at = (p, [g.lay.group for g, s in zip(groups, spans, strict=True)
                                        if not s or s[0] > p])
                p = min(start, ready)
                continue
            if self._gap_at is not None:
                self._gap_fault(*self._gap_at, p)
                self._gap_at = None
            end = min(min(s[1] for s in spans), ready, p + self.block_n)
            if end - p < self.block_n and not (last or end < ready):
                break  # wait for the rest of the block
            counts = np.concatenate([g.take(p, end) for g in groups])
            if len(groups) > 1:
                counts = counts[self.order]
            first = p - self._origin
            self._pos = end
            self._seq += 1
            if end < ready:  # cut where a run ends: say the gap after it with this block
                self._gap_ahead(groups, end)
            return Block(seq=self._seq - 1, first_sample=first, t0_ns=sample_time_ns(first, self.fs_hz),
                         fs_hz=self.fs_hz, counts=np.ascontiguousarray(counts, dtype=np.int32),
                         scale=self.scale)
        self._pos = p
        if last and p >= ready:
            self._ended = True
            self._gap_to_end(groups, p)
        return None

    def _gap_ahead(self, groups: list[CycleAssembler], at: int) -> None:
        """Say the gap that starts at sample ``at`` (absolute) now if its end is known (every
        group has samples again), so that it is said with the fault that caused it."""
        q, lacking = at, None
        while True:
            spans = [g.present_from(q) for g in groups]
            if any(s is None for s in spans):
                return  # not known yet: said where the blocks skip it
            start = max(s[0] for s in spans)
            if lacking is None:
                lacking = [g.lay.group for g, s in zip(groups, spans, strict=True) if s[0] > q]
            if start == q:
                break
            q = start
        if q > at:
            self._gap_fault(at, lacking, q)
            self._said_to = q

    def _gap_fault(self, at: int, groups: list[int], to: int) -> None:
        """``seq_gap``: samples ``at..to`` (absolute) are missing from the stream, for want of
        ``groups``' frames: one fault per gap the blocks skip, as the recording's gap list has."""
        self._counts["seq_gap"] += 1
        self._fault("seq_gap", self._t_ns(at), missing_samples=to - at, groups=groups,
                    channels=self._channels_of(groups))

    def _gap_to_end(self, groups: list[CycleAssembler], p: int) -> None:
        """At the end: samples some groups delivered after the last block, lost for want of the
        others' (a group silent to the end), as a ``seq_gap`` with ``to_end``."""
        at, lacking = self._gap_at if self._gap_at is not None else (p, None)
        lead = max((g.done() for g in groups), default=p)
        if lead > at:
            lacking = lacking or [g.lay.group for g in groups if g.done() < lead]
            self._counts["seq_gap"] += 1
            Device._fault(self, "seq_gap", self._t_ns(at), missing_samples=lead - at,
                          groups=lacking, channels=self._channels_of(lacking), to_end=True)
        self._gap_at = None

    def _channels_of(self, groups: list[int]) -> str:
        """``"9-16"``: the channels of ``groups`` (1-based, as the DBC numbers them) as runs."""
        return number_runs(sorted(c for g in groups for c in self.groups[g].lay.channels))
