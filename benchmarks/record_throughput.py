"""Sustained recording throughput: the simulated device, run as fast as possible, into MCAP.

Prints samples per second recorded (16 channels at 25.6 kHz by default), the multiple of real
time, the CPU share used (process CPU time / wall time, on a 2-core machine up to 200 %) and the
bytes per sample on disk. Target (issue 2): at least 20x real time on one core.

    python benchmarks/record_throughput.py [--seconds 60] [--fs 25600]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from ramdaq.daq.record import record
from ramdaq.drivers.sim import SimDevice

RIG = Path(__file__).resolve().parent.parent / "recordings" / "rigs" / "albacore.toml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="stream seconds to record")
    ap.add_argument("--fs", type=float, default=25600.0, help="sample rate, Hz")
    args = ap.parse_args()
    impacts = [1.0 + 5.0 * k for k in range(int(args.seconds // 5))]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.mcap"
        dev = SimDevice(RIG, duration_s=args.seconds, impacts=impacts, fs_hz=args.fs,
                        pace="fast", block_s=0.05)
        cpu0, t0 = time.process_time(), time.perf_counter()
        s = record(dev, path, readout=False)
        wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
        size = path.stat().st_size
    n_ch = 16
    total = s.samples * n_ch
    print(f"recorded {s.duration_s:.1f} s of {n_ch} ch x {args.fs:g} Hz "
          f"({total / 1e6:.1f} M samples, {len(impacts)} impacts) in {wall:.2f} s wall")
    print(f"  throughput      : {total / wall / 1e6:8.2f} M samples/s  "
          f"({s.duration_s / wall:.1f}x real time; target >= 20x)")
    print(f"  CPU share       : {100 * cpu / wall:8.1f} %  (process CPU / wall, {os.cpu_count()} cores;"
          f" the simulator, recorder thread and zstd together)")
    print(f"  CPU per sample  : {cpu / total * 1e9:8.1f} ns  "
          f"(one core alone: {s.duration_s / cpu:.1f}x real time)")
    print(f"  on disk         : {size / total:8.3f} bytes/sample ({size / 1e6:.1f} MB)")
    print(f"  gaps {s.gaps}, overflows {s.overflows}")
    ok = s.duration_s / cpu >= 20
    print(f"  result          : {'PASS' if ok else 'FAIL'} (>= 20x real time on one core's CPU)")


if __name__ == "__main__":
    main()
