"""Trigger throughput: samples per second through ``Trigger.process`` and the real-time multiple.

The simulated device's blocks (16 gages, ALBACORE rig) are generated first, so only the trigger is
timed: once on a quiet stream (armed all the time: STA/LTA on every gage) and once with a blow
every 5 s (mostly active: envelope, AR innovation detector, onset refinement, records). Run at
2048 Hz and 25.6 kHz by default.

    python benchmarks/trigger_throughput.py [--seconds 60] [--block-s 0.05] [--fs 2048 25600]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from ramdaq.daq.trigger import Trigger
from ramdaq.drivers.sim import SimDevice

RIG = Path(__file__).resolve().parent.parent / "recordings" / "rigs" / "albacore.toml"


def measure(fs_hz: float, seconds: float, block_s: float, every_s: float | None) -> tuple:
    """(samples/s, real-time multiple, events) of the trigger on ``seconds`` of stream."""
    impacts = [] if every_s is None else [3.0 + every_s * k for k in range(int(seconds // every_s))]
    dev = SimDevice(RIG, seed=1, duration_s=seconds, impacts=impacts, fs_hz=fs_hz, block_s=block_s)
    with dev:
        blocks = list(dev)
        trig = Trigger(dev.info)
    t0 = time.perf_counter()
    events = []
    for block in blocks:
        events += trig.process(block)
    events += trig.flush()
    wall = time.perf_counter() - t0
    n = sum(b.n_samples for b in blocks) * blocks[0].n_channels
    return n / wall, seconds / wall, len(events)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="stream seconds per run")
    ap.add_argument("--block-s", type=float, default=0.05, help="block length, s")
    ap.add_argument("--fs", type=float, nargs="+", default=[2048.0, 25600.0], help="rates, Hz")
    args = ap.parse_args()
    print(f"trigger on 16 ch, {args.seconds:g} s per run, {args.block_s * 1e3:g} ms blocks")
    for fs in args.fs:
        for label, every in (("quiet", None), ("blow every 5 s", 5.0)):
            rate, multiple, n_events = measure(fs, args.seconds, args.block_s, every)
            print(f"  {fs:8.0f} Hz  {label:15s}: {rate / 1e6:7.2f} M samples/s  "
                  f"{multiple:7.1f}x real time  ({n_events} events)")


if __name__ == "__main__":
    main()
