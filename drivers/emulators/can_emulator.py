"""A CAN front-end emulator: the simulator's samples sent as the frames a DBC describes.

::

    python -m ramdaq.drivers.emulators.can_emulator --interface slcan --rig recordings/rigs/sampson.toml \\
        --dbc fd24 --duration 10 --impacts 2,6 --seed 1 [--drop-every 500] [--bus-off-at 4]

``--interface slcan`` opens a pseudo-terminal pair, prints ``SLCAN <slave path>`` and speaks the
Lawicel serial-line protocol on the master side, as a USB-CAN adapter does: it answers ``O``,
``L``, ``C``, ``S``/``s``/``Y``, ``V``, ``N`` and ``F`` commands, and once opened sends ``t``/``T``
(classic) and ``d``/``b`` (CAN FD) frame lines. The adapter opens it with python-can::

    ramdaq trial --device "can://slcan/<slave path>?sleep_after_open=0&dbc=fd24&rig=RIG&idle_s=2"

``--pace realtime`` sends each cycle's frames when its last sample is due (on slcan in one write,
as a USB adapter packs them into packets); ``fast`` as fast as the bus or the reader takes them.
Any other interface is opened with ``can.Bus(interface=..., channel=...)`` (``socketcan`` on a
``vcan0``; ``virtual`` only reaches buses of the same process: tests run :func:`send_frames` in a
thread). ``--channel`` may be repeated: group ``i`` goes to the ``i``-th channel.

Faults are injected by counting sample frames: every K-th is dropped, corrupted (one bit flipped:
the CRC catches it), shortened (wrong DLC) or, on slcan, garbled (an unparseable line); every K-th
is followed by an error frame or by a frame of another node; a bus-off (error frames with the
SocketCAN bus-off and restarted classes, the frames between lost) at a chosen time. Error frames
cannot be said in the Lawicel protocol: on slcan they are left out, so a bus-off there is a plain
silence. A front-end restart (``--restart-at``): silent for ``--restart-s``, then its SEQ counts
from 0 again. ``--seq-offset`` starts the SEQ counter elsewhere (a twin front-end powered up at
another time: tests merge two emulators' frames). :attr:`CanEmulator.lost` and
``--report`` give the cycles lost, the ground truth a test compares the recording with.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import re
import select
import sys
import time
import tty
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import can
import numpy as np

from ...analysis.model.rig import RigError, load_rig
from ..block import Block
from ..can_frames import FrameCodec

__all__ = ["CanEmulator", "Wire", "send_frames", "serve_slcan", "slcan_line", "rig_with_adc_bits", "main"]

_UNRELATED = (can.Message(arbitration_id=0x7E8, data=bytes.fromhex("0441 0d37 0000 0000")),
              can.Message(arbitration_id=0x18FEF100, is_extended_id=True, data=bytes(range(8))))


@dataclass(frozen=True)
class Wire:
    """A frame to send: its group's bus (0 for all), due time ``t_s`` (s of stream), the frame."""

    group: int
    t_s: float
    msg: can.Message
    garble: bool = False  # slcan: send an unparseable line instead (other buses: not sent)
    cycle: int = -1       # the cycle a sample frame belongs to


def rig_with_adc_bits(text: str, bits: int) -> str:
    """Rig TOML text with ``[daq] adc_bits`` set to ``bits`` (a 16-bit front-end for classic CAN)."""
    out, n = re.subn(r"(?m)^(adc_bits\s*=\s*)\d+", rf"\g<1>{bits}", text)
    if n != 1:
        raise ValueError(f"rig text has {n} adc_bits lines, expected 1")
    return out


class CanEmulator:
    """Blocks from a device (the simulator) -> the frames of a DBC layout, with faults injected.

    Parameters
    ----------
    codec : FrameCodec
        The layout.
    blocks : iterable of Block
        The samples (all the layout's channels, in channel order). Whole cycles are sent; a last
        partial cycle is not.
    drop_every, corrupt_every, wrong_dlc_every, garble_every : int
        Lose every K-th sample frame: not sent, one bit flipped, one byte short, unparseable
        slcan line (0: never).
    unrelated_every, error_frame_every : int
        After every K-th sample frame, a frame of another node / a bus error frame.
    bus_off_at_s, bus_off_s : float
        Go bus-off at this stream time for this long (frames in between are lost).
    restart_at_s, restart_s : float
        The front-end restarts at this stream time: silent this long, then SEQ from 0 again.
    seq_offset : int
        SEQ of cycle 0 (the counter's phase), cycles.
    """

    def __init__(self, codec: FrameCodec, blocks: Iterable[Block], *, drop_every: int = 0,
                 corrupt_every: int = 0, wrong_dlc_every: int = 0, garble_every: int = 0,
                 unrelated_every: int = 0, error_frame_every: int = 0,
                 bus_off_at_s: float | None = None, bus_off_s: float = 0.1,
                 restart_at_s: float | None = None, restart_s: float = 0.2, seq_offset: int = 0) -> None:
        self.codec, self.blocks = codec, blocks
        self.every = {"drop": drop_every, "corrupt": corrupt_every, "wrong_dlc": wrong_dlc_every,
                      "garble": garble_every}
        self.unrelated_every, self.error_frame_every = unrelated_every, error_frame_every
        self.bus_off = None if bus_off_at_s is None else (bus_off_at_s, bus_off_at_s + bus_off_s)
        self.restart = None if restart_at_s is None else (restart_at_s, restart_at_s + restart_s)
        self.restarted_at: int | None = None  # first cycle after the restart (SEQ 0)
        self.seq_offset = seq_offset
        self.lost: dict[int, set[int]] = {g: set() for g in codec.groups}
        self.injected: Counter = Counter()
        self.cycles_sent: dict[int, int] = dict.fromkeys(codec.groups, 0)
        self.fs_hz = 0.0

    def frames(self) -> Iterator[Wire]:
        """The frames in bus order (cycle by cycle, groups interleaved by time), faults included."""
        k = 0
        state = "on"
        for batch in self._cycles():
            for group, cycle, start_s, t_s, msg in batch:
                if self.bus_off and state == "on" and start_s >= self.bus_off[0]:
                    state = "off"
                    self.injected["bus_off"] += 1
                    yield Wire(0, t_s, can.Message(is_error_frame=True, arbitration_id=0x40, dlc=8))
                if state == "off":
                    if start_s < self.bus_off[1]:
                        self.lost[group].add(cycle)
                        continue
                    state = "done"
                    yield Wire(0, t_s, can.Message(is_error_frame=True, arbitration_id=0x100, dlc=8))
                if self.restart and start_s >= self.restart[0]:
                    if start_s < self.restart[1]:
                        self.lost[group].add(cycle)
                        continue
                    if self.restarted_at is None:
                        self.restarted_at = cycle
                        self.injected["restart"] += 1
                    msg = self._with_seq(msg, cycle - self.restarted_at)
                k += 1
                fault = next((f for f, n in self.every.items() if n and k % n == 0), None)
                if fault:
                    self.injected[fault] += 1
                    self.lost[group].add(cycle)
                if fault == "corrupt":
                    data = bytearray(msg.data)
                    data[(k * 7) % len(data)] ^= 1 << (k % 8)
                    msg = _copy(msg, bytes(data))
                elif fault == "wrong_dlc":
                    msg = _copy(msg, bytes(msg.data[: 48 if msg.is_fd else len(msg.data) - 1]))
                if fault != "drop":
                    yield Wire(group, t_s, msg, fault == "garble", cycle)
                if self.error_frame_every and k % self.error_frame_every == 0:
                    self.injected["error_frame"] += 1
                    yield Wire(group, t_s, can.Message(is_error_frame=True, arbitration_id=0x88, dlc=8,
                                                       data=bytes([0, 0, 0x08, 0x18, 0, 0, 0, 0])))
                if self.unrelated_every and k % self.unrelated_every == 0:
                    self.injected["unrelated"] += 1
                    yield Wire(group, t_s, _UNRELATED[(k // self.unrelated_every) % 2])

    def _with_seq(self, msg: can.Message, seq: int) -> can.Message:
        """``msg`` with its SEQ set to ``seq`` (modulo the period) and its CRC made good again."""
        lay = self.codec.check(msg)[0]
        data = bytearray(msg.data)
        width = lay.seq_end - lay.seq_at
        data[lay.seq_at : lay.seq_end] = (seq % (1 << 8 * width)).to_bytes(width, "little")
        if lay.crc_name:
            crc = lay.crc_update(bytes(data[: lay.crc_at]), lay.crc_seed) ^ lay.crc_xorout
            data[lay.crc_at : lay.crc_end] = crc.to_bytes(lay.crc_end - lay.crc_at, "little")
        return _copy(msg, bytes(data))

    def _cycles(self) -> Iterator[list[tuple[int, int, float, float, can.Message]]]:
        groups = self.codec.groups
        rows = {g: [self.codec.channels.index(c) for c in lay.channels] for g, lay in groups.items()}
        pending = {g: [] for g in groups}
        for block in self.blocks:
            self.fs_hz = block.fs_hz
            out = []
            for g, lay in groups.items():
                if max(rows[g]) >= block.n_channels:  # a group the rig has no channels for
                    continue                           # (fd24_force's force group, 16 gages)
                pending[g].append(block.counts[rows[g]])
                have = np.concatenate(pending[g], axis=1)
                n = have.shape[1] // lay.samples_per_cycle
                if not n:
                    pending[g] = [have]
                    continue
                T, c0, F = lay.samples_per_cycle, self.cycles_sent[g], len(lay.frames)
                msgs = self.codec.messages(g, c0 + self.seq_offset, have[:, : n * T])
                pending[g] = [have[:, n * T :]]
                self.cycles_sent[g] += n
                fs = block.fs_hz
                out += [(g, c0 + i // F, (c0 + i // F) * T / fs, (c0 + i // F + 1) * T / fs, m)
                        for i, m in enumerate(msgs)]
            out.sort(key=lambda w: (w[3], w[0]))
            yield out

    def missing(self, n_samples: int) -> np.ndarray:
        """Which of the first ``n_samples`` samples the frames do not carry, bool (n_samples,)."""
        gone = np.zeros(n_samples, dtype=bool)
        idx = np.arange(n_samples)
        for g, lay in self.codec.groups.items():
            T = lay.samples_per_cycle
            gone |= np.isin(idx // T, sorted(self.lost[g])) | (idx >= self.cycles_sent[g] * T)
        return gone

    def report(self) -> dict:
        """Ground truth as JSON: cycles lost per group, faults injected, cycles sent."""
        return {"lost": {str(g): sorted(c) for g, c in self.lost.items()},
                "injected": dict(self.injected),
                "cycles_sent": {str(g): n for g, n in self.cycles_sent.items()},
                "samples_per_cycle": {str(g): lay.samples_per_cycle for g, lay in self.codec.groups.items()}}


def _copy(msg: can.Message, data: bytes) -> can.Message:
    return can.Message(arbitration_id=msg.arbitration_id, is_extended_id=msg.is_extended_id,
                       is_fd=msg.is_fd, bitrate_switch=msg.bitrate_switch, data=data)


def _paced(wires: Iterable[Wire], pace: str) -> Iterator[list[Wire]]:
    """The frames in batches due at the same time; ``realtime`` waits for each batch's time."""
    t0 = time.monotonic()
    for t_s, batch in itertools.groupby(wires, key=lambda w: w.t_s):
        if pace == "realtime":
            wait = t0 + t_s - time.monotonic()
            if wait > 0:
                time.sleep(wait)
        yield list(batch)


def send_frames(wires: Iterable[Wire], buses: dict[int, can.BusABC] | can.BusABC,
                pace: str = "fast") -> int:
    """Send frames on ``buses`` (one, or one per group); group 0 frames go to every bus.

    A garbled frame (an slcan line fault) is not sent: a CAN bus cannot carry it.
    """
    by_group = buses if isinstance(buses, dict) else {0: buses}
    every = list({id(b): b for b in by_group.values()}.values())
    n = 0
    for batch in _paced(wires, pace):
        for w in batch:
            if w.garble:
                continue
            for bus in every if (w.group == 0 or len(every) == 1) else [by_group[w.group]]:
                bus.send(w.msg)
            n += 1
    return n


def slcan_line(msg: can.Message, garble: bool = False) -> bytes | None:
    """One frame in the Lawicel protocol (``None`` for an error frame: the protocol has none);
    ``garble`` puts a non-hex character where python-can's parser expects a digit."""
    if msg.is_error_frame:
        return None
    ident = f"{msg.arbitration_id:08X}" if msg.is_extended_id else f"{msg.arbitration_id:03X}"
    if msg.is_fd:
        kind = "b" if msg.bitrate_switch else "d"
        kind = kind.upper() if msg.is_extended_id else kind
        dlc = f"{can.util.len2dlc(len(msg.data)):X}"
    else:
        kind, dlc = ("T" if msg.is_extended_id else "t"), str(len(msg.data))
    line = f"{kind}{ident}{dlc}{bytes(msg.data).hex().upper()}"
    if garble:
        line = line[:5] + "Z" + line[6:]
    return line.encode() + b"\r"


_REPLIES = {b"V": b"V1013\r", b"N": b"NRDQ1\r", b"F": b"F00\r"}


def serve_slcan(wires: Iterable[Wire], *, pace: str = "fast", ready: Callable[[str], None] = print,
                linger_s: float = 30.0, stall_s: float = 10.0) -> int:
    """Serve the frames as a Lawicel slcan adapter on a new pseudo-terminal; returns lines sent.

    ``ready(path)`` is called with the slave's path. Frames flow once the host sends ``O`` (or
    ``L``), stop at ``C``; after the last one the adapter stays up ``linger_s`` or until ``C``.
    """
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    ready(os.ttyname(slave))
    state = {"open": False, "closed": False, "inbuf": b""}

    def serve_commands(timeout: float) -> None:
        r, _, _ = select.select([master], [], [], timeout)
        if not r:
            return
        try:
            state["inbuf"] += os.read(master, 4096)
        except OSError:
            return
        *cmds, state["inbuf"] = state["inbuf"].split(b"\r")
        for cmd in cmds:
            reply = _REPLIES.get(cmd[:1], b"\r")
            if cmd[:1] in (b"O", b"L"):
                state["open"], state["closed"] = True, False
            elif cmd[:1] == b"C":
                state["closed"] = state["open"] or state["closed"]
                state["open"] = False
            elif cmd[:1] not in (b"", b"S", b"s", b"Y", b"V", b"N", b"F", b"Z"):
                reply = b"\a"
            os.write(master, reply)

    sent = 0
    try:
        while not state["open"]:
            serve_commands(0.1)
        out = b""
        for batch in _paced(wires, pace):  # a batch is written at once, as a USB adapter does
            lines = [line for line in (slcan_line(w.msg, w.garble) for w in batch) if line]
            out += b"".join(lines)
            sent += len(lines)
            if len(out) < 2048 and pace == "fast":
                continue
            out = _drain(master, out, serve_commands, state, stall_s)
            if state["closed"]:
                return sent
        _drain(master, out, serve_commands, state, stall_s)
        end = time.monotonic() + linger_s
        while not state["closed"] and time.monotonic() < end:
            serve_commands(0.1)
    finally:
        os.close(master)
        os.close(slave)
    return sent


def _drain(fd: int, out: bytes, serve: Callable[[float], None], state: dict, stall_s: float) -> bytes:
    stalled = time.monotonic() + stall_s
    while out and not state["closed"]:
        serve(0.0)
        _, w, _ = select.select([], [fd], [], 0.05)
        if w:
            n = os.write(fd, out)
            out = out[n:]
            stalled = time.monotonic() + stall_s
        elif time.monotonic() > stalled:
            raise TimeoutError(f"slcan emulator: nobody read the pseudo-terminal for {stall_s} s")
    return out


def main(argv: list[str] | None = None) -> int:
    from ..sim import SimDevice

    ap = argparse.ArgumentParser(prog="python -m ramdaq.drivers.emulators.can_emulator",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--interface", default="slcan", help="slcan (a pty), or any python-can interface")
    ap.add_argument("--channel", action="append", default=[], help="bus channel (repeat: one per group)")
    ap.add_argument("--rig", required=True, help="rig file, or a shipped rig's name (albacore)")
    ap.add_argument("--dbc", default=None, help="classic, fd24, fd16 or a DBC path")
    ap.add_argument("--fd", action="store_true", help="CAN FD (default layout fd24)")
    ap.add_argument("--duration", type=float, default=10.0, help="stream length, s")
    ap.add_argument("--impacts", default="", help="impact times, s, comma-separated")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--fs", type=float, default=None, help="sample rate, Hz (default: the rig's)")
    ap.add_argument("--block-s", type=float, default=0.05)
    ap.add_argument("--pace", choices=("realtime", "fast"), default="realtime")
    for name in ("drop", "corrupt", "wrong-dlc", "garble", "unrelated", "error-frame"):
        ap.add_argument(f"--{name}-every", type=int, default=0, metavar="K")
    ap.add_argument("--bus-off-at", type=float, default=None, metavar="S")
    ap.add_argument("--bus-off-s", type=float, default=0.1, metavar="S")
    ap.add_argument("--restart-at", type=float, default=None, metavar="S",
                    help="the front-end restarts (silent, then SEQ from 0) at this stream time")
    ap.add_argument("--restart-s", type=float, default=0.2, metavar="S")
    ap.add_argument("--seq-offset", type=int, default=0, metavar="CYCLES", help="SEQ of cycle 0")
    ap.add_argument("--report", default=None, help="write the ground truth (JSON) here at the end")
    ap.add_argument("--linger", type=float, default=30.0, help="slcan: stay up after the last frame, s")
    a = ap.parse_args(argv)
    codec = FrameCodec(a.dbc, fd=a.fd)
    try:
        rig = load_rig(a.rig)
    except RigError as err:
        raise SystemExit(f"can_emulator: {err}") from None
    bits = min(lay.sample_bits for lay in codec.groups.values())
    if rig.daq.adc_bits > bits:
        raise SystemExit(f"can_emulator: {a.rig} has a {rig.daq.adc_bits}-bit ADC, {codec.name} carries "
                         f"{bits}-bit samples (use --dbc fd24, or a {bits}-bit rig)")
    impacts = [float(t) for t in a.impacts.split(",") if t.strip()]
    sim = SimDevice(rig, seed=a.seed, duration_s=a.duration, impacts=impacts, fs_hz=a.fs,
                    block_s=a.block_s, pace="fast")
    emu = CanEmulator(codec, sim, drop_every=a.drop_every, corrupt_every=a.corrupt_every,
                      wrong_dlc_every=a.wrong_dlc_every, garble_every=a.garble_every,
                      unrelated_every=a.unrelated_every, error_frame_every=a.error_frame_every,
                      bus_off_at_s=a.bus_off_at, bus_off_s=a.bus_off_s, restart_at_s=a.restart_at,
                      restart_s=a.restart_s, seq_offset=a.seq_offset)
    with sim:
        if a.interface == "slcan":
            n = serve_slcan(emu.frames(), pace=a.pace, linger_s=a.linger,
                            ready=lambda p: print(f"SLCAN {p}", flush=True))
        else:
            chans = a.channel or ["0"]
            fd = any(f.fd for g in codec.groups.values() for f in g.frames)
            opened = {c: can.Bus(interface=a.interface, channel=c, fd=fd) for c in dict.fromkeys(chans)}
            print(f"{a.interface.upper()} {' '.join(chans)}", flush=True)
            try:
                n = send_frames(emu.frames(), {g: opened[chans[i % len(chans)]]
                                               for i, g in enumerate(codec.groups)}, a.pace)
            finally:
                for bus in opened.values():
                    bus.shutdown()
    if a.report:
        with open(a.report, "w", encoding="utf-8") as f:
            json.dump({**emu.report(), "frames_sent": n}, f)
    print(f"sent {n} frames; injected {dict(emu.injected)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
