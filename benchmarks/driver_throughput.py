"""Front-end adapters' decoding throughput on one core, and their CPU share at 16 ch x 2.048 kHz.

Each case decodes a simulated trial and prints frames and samples (per channel x channels) per
second of CPU time in the decoding thread, and the share of one core the adapter would take at
16 channels x 2.048 kHz (target < 10 %). CAN cases: the codec alone (fast path and its cantools
twin), the slcan line parser alone, and the whole adapter (bus, checks, cycle assembly, blocks) on
a pre-filled python-can virtual bus and on slcan over a pseudo-terminal (the adapter's own bulk
reader, :mod:`ramdaq.drivers.slcan_reader`; emulator in its own process), as fast as it goes (CPU share
computed from CPU per frame) and at the sample clock (CPU share measured).

    python benchmarks/driver_throughput.py [--seconds 5]

Other adapters add a function returning their cases to ``CASE_GROUPS``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import can
import numpy as np

from ramdaq.drivers.can_device import CanDevice
from ramdaq.drivers.can_frames import FrameCodec
from ramdaq.drivers.emulators.can_emulator import (
    CanEmulator,
    Wire,
    rig_with_adc_bits,
    send_frames,
    slcan_line,
)
from ramdaq.drivers.sim import SimDevice
from ramdaq.drivers.slcan_reader import READ_EVERY_S, parse_lines

ROOT = Path(__file__).resolve().parent.parent
RIG = ROOT / "recordings" / "rigs" / "sampson.toml"
FS_HZ, N_CH = 2048.0, 16


@dataclass
class Row:
    """One benchmark result: frames and samples decoded per CPU second, share at 16 ch x 2.048 kHz."""

    adapter: str
    case: str
    frames_per_s: float
    samples_per_s: float
    cpu_share: float  # of one core, at 16 ch x 2.048 kHz
    note: str = ""


def _rig(dbc: str, tmp: Path) -> Path:
    if dbc == "fd24":
        return RIG
    path = tmp / "rig16.toml"
    path.write_text(rig_with_adc_bits(RIG.read_text(), 16))
    return path


def _frames(dbc: str, seconds: float, tmp: Path) -> tuple[FrameCodec, list[can.Message], Path]:
    codec = FrameCodec(dbc)
    rig = _rig(dbc, tmp)
    with SimDevice(rig, seed=1, duration_s=seconds, impacts=[seconds / 2], pace="fast") as sim:
        wires = list(CanEmulator(codec, sim).frames())
    return codec, [w.msg for w in wires], rig


def _per_frame(codec: FrameCodec) -> int:
    g = next(iter(codec.groups.values()))
    return g.samples_per_cycle * len(g.channels) // len(g.frames)


def _row(adapter: str, case: str, frames: int, cpu_s: float, per_frame: int, note: str = "") -> Row:
    needed = N_CH * FS_HZ / per_frame  # frames/s at 16 ch x 2.048 kHz
    return Row(adapter, case, frames / cpu_s, frames * per_frame / cpu_s, needed * cpu_s / frames, note)


def _codec_case(dbc: str, reference: bool) -> Callable[[float], Row]:
    def run(seconds: float) -> Row:
        with tempfile.TemporaryDirectory() as tmp:
            codec, msgs, _ = _frames(dbc, seconds, Path(tmp))
        t = time.thread_time()
        if reference:
            for m in msgs:
                codec.decode_reference(m)
        else:  # the adapter's path: check every frame, unpack whole cycles in batches
            rows: dict[int, list[bytes]] = {}
            for m in msgs:
                lay, _ = codec.check(m)
                rows.setdefault(lay.group, []).append(bytes(m.data))
            for g, frames in rows.items():
                lay = codec.groups[g]
                raw = np.frombuffer(b"".join(f.ljust(lay.frame_bytes) for f in frames), np.uint8)
                cycles = raw.reshape(len(frames) // len(lay.frames), -1)
                for chunk in np.array_split(cycles, max(1, len(cycles) // 40)):  # ~a block each
                    codec.decode_cycles(g, chunk)
        cpu = time.thread_time() - t
        name = "cantools decode_message per frame" if reference else "fast path: check + batched unpack"
        return _row("CAN codec", f"{dbc}: {name}", len(msgs), cpu, _per_frame(codec))
    return run


def _slcan_parse_case(dbc: str) -> Callable[[float], Row]:
    def run(seconds: float) -> Row:
        with tempfile.TemporaryDirectory() as tmp:
            codec, msgs, _ = _frames(dbc, seconds, Path(tmp))
        lines = b"".join(slcan_line(m) for m in msgs).decode("latin-1").split("\r")[:-1]
        per_read = max(1, round(N_CH * FS_HZ / _per_frame(codec) * READ_EVERY_S))  # lines of one read
        t = time.thread_time()
        frames = sum(len(parse_lines(lines[i : i + per_read], 0.0)) for i in range(0, len(lines), per_read))
        cpu = time.thread_time() - t
        assert frames == len(msgs)
        return _row("slcan lines", f"{dbc}: Lawicel lines -> frames", frames, cpu, _per_frame(codec),
                    f"parse_lines, {per_read} lines a call (one read at 16 ch x 2.048 kHz)")
    return run


def _virtual_case(dbc: str) -> Callable[[float], Row]:
    def run(seconds: float) -> Row:
        with tempfile.TemporaryDirectory() as tmp:
            codec, msgs, rig = _frames(dbc, seconds, Path(tmp))
            channel = f"bench-{uuid.uuid4().hex[:8]}"
            dev = CanDevice(f"virtual/{channel}", dbc=dbc, rig=str(rig), idle_s=0.2)
            dev.open()
            tx = can.Bus(interface="virtual", channel=channel)
            send_frames((Wire(1, 0.0, m) for m in msgs), tx)  # pre-filled: no sender in the timing
            tx.shutdown()
            t = time.thread_time()
            samples = sum(b.n_samples for b in dev)
            cpu = time.thread_time() - t
            dev.close()
        assert samples > 0
        return _row("CAN adapter", f"{dbc}: virtual bus -> blocks", dev.counters["frames"], cpu,
                    _per_frame(codec), "python-can recv included")
    return run


def _slcan_case(dbc: str, pace: str) -> Callable[[float], Row]:
    def run(seconds: float) -> Row:
        with tempfile.TemporaryDirectory() as tmp:
            rig = _rig(dbc, Path(tmp))
            proc = subprocess.Popen(
                [sys.executable, "-m", "ramdaq.drivers.emulators.can_emulator",
                 "--interface", "slcan", "--rig", str(rig),
                 "--dbc", dbc, "--duration", str(seconds), "--impacts", str(seconds / 2), "--pace", pace,
                 "--linger", "5"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT)
            port = proc.stdout.readline().split()[1]
            dev = CanDevice(f"slcan/{port}?sleep_after_open=0&idle_s=0.3", dbc=dbc, rig=str(rig))
            dev.open()
            t, wall = time.thread_time(), time.perf_counter()
            samples = sum(b.n_samples for b in dev)
            cpu, wall = time.thread_time() - t, time.perf_counter() - wall - 0.3
            dev.close()
            proc.wait(10)
        assert samples > 0
        per_frame = _per_frame(FrameCodec(dbc))
        if pace == "fast":
            return _row("CAN adapter", f"{dbc}: slcan pty -> blocks", dev.counters["frames"], cpu, per_frame,
                        f"{samples / FS_HZ / wall:.1f}x real time (emulator in another process)")
        frames = dev.counters["frames"]
        return Row("CAN adapter", f"{dbc}: slcan pty, real time", frames / cpu, frames * per_frame / cpu,
                   cpu / wall, "measured: reader CPU / wall while streaming at the sample clock")
    return run


def can_cases() -> list[Callable[[float], Row]]:
    """The CAN rows: codec (fast and reference), slcan parser, adapter on virtual and slcan buses."""
    return [_codec_case("classic", False), _codec_case("classic", True), _codec_case("fd24", False),
            _codec_case("fd24", True), _slcan_parse_case("classic"), _slcan_parse_case("fd24"),
            _virtual_case("classic"), _virtual_case("fd24"),
            _slcan_case("classic", "fast"), _slcan_case("fd24", "fast"), _slcan_case("classic", "realtime"),
            _slcan_case("fd24", "realtime")]


CASE_GROUPS: list[Callable[[], list[Callable[[float], Row]]]] = [can_cases]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=5.0, help="stream seconds per case")
    args = ap.parse_args()
    print(f"{'adapter':<12} {'case':<42} {'frames/s':>10} {'samples/s':>11} {'CPU @16ch x 2.048 kHz':>22}")
    ok = True
    for group in CASE_GROUPS:
        for case in group():
            r = case(args.seconds)
            ok &= r.cpu_share < 0.10 or r.adapter.endswith("codec")
            print(f"{r.adapter:<12} {r.case:<42} {r.frames_per_s:>10,.0f} {r.samples_per_s:>11,.0f} "
                  f"{100 * r.cpu_share:>21.1f}%  {r.note}", flush=True)
    print(f"result: {'PASS' if ok else 'FAIL'} (every adapter < 10 % of one core at 16 ch x 2.048 kHz)")


if __name__ == "__main__":
    main()
