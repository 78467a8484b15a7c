"""Serial adapter throughput: frames and samples decoded per second on one core, and the CPU
share of reading 16 channels x 2.048 kHz over a real pty from the emulator.

1. Parser alone: a stream of 16-channel int24 frames (32 samples each, the emulator's default)
   fed to :class:`~ramdaq.drivers.serial_frames.FrameParser` in 4 KiB reads, as a port delivers them.
2. Whole path, as fast as it goes: emulator (``--pace fast``) -> pty -> pyserial ->
   :class:`~ramdaq.drivers.serial_device.SerialDevice` -> blocks.
3. Real time: emulator (``--pace realtime``) -> pty -> ``SerialDevice``; the reader's CPU time
   over the wall time it streamed, as a percentage of one core. Target (issue): under 10 %.

    python benchmarks/serial_throughput.py [--seconds 20] [--frames 20000]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ramdaq.drivers.serial_device import SerialDevice
from ramdaq.drivers.serial_frames import FrameParser, encode_frame

ROOT = Path(__file__).resolve().parent.parent
RIG = ROOT / "recordings" / "rigs" / "albacore.toml"
N_CH, SPF = 16, 32


def parser_rate(n_frames: int) -> tuple[float, float, float]:
    """Frames/s, samples/s and MB/s the parser decodes on one core (CPU time)."""
    rng = np.random.default_rng(0)
    counts = rng.integers(-(2**23), 2**23, size=(N_CH, SPF * 64))
    wire = b"".join(encode_frame(k, k * SPF, counts[:, (k % 64) * SPF:(k % 64 + 1) * SPF])
                    for k in range(n_frames))
    parser, got = FrameParser(), 0
    cpu = time.process_time()
    for i in range(0, len(wire), 4096):
        got += len(parser.feed(wire[i:i + 4096]))
    cpu = time.process_time() - cpu
    assert got == n_frames and parser.crc_errors == 0
    return got / cpu, got * SPF * N_CH / cpu, len(wire) / cpu / 1e6


def through_pty(seconds: float, pace: str) -> dict:
    """Stream ``seconds`` of the simulator through the emulator and a pty into SerialDevice."""
    emu = subprocess.Popen([sys.executable, "-m", "ramdaq.drivers.emulators.serial_emulator",
                            "--pty", "--rig",
                            str(RIG), "--duration", str(seconds), "--impacts", "1", "--pace", pace],
                           cwd=ROOT, stdout=subprocess.PIPE, text=True)
    address = emu.stdout.readline().strip()
    dev = SerialDevice(address, rig=RIG)
    samples = blocks = 0
    with dev:
        first = dev.read()  # the clock starts with the first block
        cpu, wall = time.process_time(), time.perf_counter()
        for block in dev:
            samples += block.n_samples
            blocks += 1
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    emu.stdout.read()
    _, status, usage = os.wait4(emu.pid, 0)
    emu.returncode = os.waitstatus_to_exitcode(status)
    assert first.n_channels == N_CH and dev.parser.crc_errors == 0
    return {"samples": samples, "blocks": blocks, "cpu": cpu, "wall": wall,
            "emulator_cpu": usage.ru_utime + usage.ru_stime}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="stream seconds in real time")
    ap.add_argument("--frames", type=int, default=20000, help="frames for the parser alone")
    args = ap.parse_args()
    fps, sps, mbs = parser_rate(args.frames)
    print(f"parser alone, one core:   {fps:10,.0f} frames/s  {sps / 1e6:6.1f} M samples/s  "
          f"{mbs:6.1f} MB/s  ({N_CH} ch x {SPF} samples, int24)")
    need = N_CH * 2048.0
    print(f"  16 ch x 2.048 kHz needs {2048 / SPF:.0f} frames/s = {need / 1e3:.1f} k samples/s: "
          f"{100 * need / sps:.2f} % of one core")
    fast = through_pty(max(10.0, args.seconds), "fast")
    rate = fast["samples"] * N_CH / fast["wall"]
    print(f"pty, as fast as it goes: {rate / 1e6:6.2f} M samples/s wall "
          f"({rate / need:.0f}x real time), reader CPU {100 * fast['cpu'] / fast['wall']:.0f} %"
          f" of a core, emulator CPU {fast['emulator_cpu']:.1f} s")
    rt = through_pty(args.seconds, "realtime")
    share = 100 * rt["cpu"] / rt["wall"]
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"pty, real time, 16 ch x 2.048 kHz for {rt['wall']:.1f} s: reader CPU "
          f"{rt['cpu']:.2f} s = {share:.1f} % of one core (target < 10 %), "
          f"{rt['blocks']} blocks, emulator CPU {rt['emulator_cpu']:.1f} s, max RSS {rss_mb:.0f} MB")


if __name__ == "__main__":
    main()
