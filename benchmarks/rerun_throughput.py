"""Rerun logging throughput: how fast :meth:`ramdaq.daq.rerun_view.RerunView.log_block` takes a stream,
and how big the .rrd grows per second of stream.

For 16 channels at 2048 Hz and 25.6 kHz (simulated albacore trial, blocks pre-computed so only the
logging is timed) prints input samples/s through ``log_block`` (min/max decimation + one
``send_columns`` of all gages per batch + flush to the file), the multiple of real time, and the
.rrd bytes per second of stream. Then, for reference, raw Rerun rates at full rate: one entity of
16-wide rows, 16 entities via ``send_columns``, and ``rr.log`` per sample. Last, the size that
matters to a user: ``ramdaq trial`` (simulated ALBACORE in water, 40 s, a blow every 10 s, as fast
as it goes) writes its MCAP and its .rrd; their ratio (issue target: .rrd <= 3x the MCAP).

    python benchmarks/rerun_throughput.py [--seconds 20] [--live-rate 100]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import rerun as rr

from ramdaq.daq.rerun_view import LIVE_RATE_HZ, RerunView
from ramdaq.drivers.block import Block
from ramdaq.drivers.sim import SimDevice

RIG = Path(__file__).resolve().parent.parent / "recordings" / "rigs" / "albacore.toml"


def stream(fs_hz: float, seconds: float) -> tuple[object, list[Block]]:
    """Pre-computed blocks of a simulated trial, an impact every 5 s."""
    impacts = [1.0 + 5.0 * k for k in range(int(seconds // 5) + 1) if 1.0 + 5.0 * k < seconds]
    with SimDevice(RIG, duration_s=seconds, impacts=impacts, fs_hz=fs_hz, seed=0) as dev:
        info = dev.open()
        return info, list(dev)


def bench_view(fs_hz: float, seconds: float, live_rate_hz: float, tmp: Path) -> None:
    info, blocks = stream(fs_hz, seconds)
    path = tmp / f"view_{fs_hz:g}.rrd"
    t0, cpu0 = time.perf_counter(), time.process_time()
    with RerunView(info, rrd_path=path, live_rate_hz=live_rate_hz) as view:
        for b in blocks:
            view.log_block(b)
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    n = sum(b.n_samples for b in blocks) * info.n_channels
    rows_s = info.fs_hz / view.bucket
    points_s = rows_s * (2 if view.bucket > 1 else 1) * info.n_channels
    print(f"log_block  16 ch x {fs_hz:>7g} Hz ({len(blocks)} blocks of {blocks[0].n_samples}): "
          f"{n / wall / 1e6:6.1f} M samples/s in, {seconds / wall:4.0f}x real time, "
          f"{cpu / seconds * 1e3:5.1f} ms CPU (all threads) per stream s; "
          f"bucket {view.bucket} -> {rows_s:.0f} rows/s/ch; "
          f".rrd {path.stat().st_size / seconds / 1e3:6.1f} kB per stream s; "
          f"viewer ~{points_s * 70 / 1e6:.1f} MB per stream s at 70 B/point")


def bench_raw(fs_hz: float, seconds: float, tmp: Path) -> None:
    rng = np.random.default_rng(0)
    n_blk, n_ch = 1280, 16
    n_blocks = max(1, int(seconds * fs_hz / n_blk))
    data = rng.standard_normal((n_ch, n_blk))

    def run(label: str, fn: object, n_samples: int) -> None:
        path = tmp / f"raw_{label}.rrd"
        rec = rr.RecordingStream("bench", make_default=False)
        rec.set_sinks(rr.FileSink(path))
        t0 = time.perf_counter()
        fn(rec)
        rec.flush()
        wall = time.perf_counter() - t0
        rec.disconnect()
        print(f"raw full rate  {label:<34}: {n_samples / wall / 1e6:7.2f} M samples/s, "
              f"{path.stat().st_size / n_samples:5.1f} B/sample on disk")

    def times(b: int) -> rr.TimeColumn:
        idx = np.arange(b * n_blk, (b + 1) * n_blk)
        return rr.TimeColumn("time", duration=np.round(idx * 1e9 / fs_hz).astype("timedelta64[ns]"))

    def wide(rec: rr.RecordingStream) -> None:
        for b in range(n_blocks):
            rec.send_columns("gages", indexes=[times(b)], columns=rr.Scalars.columns(scalars=data.T))

    def per_entity(rec: rr.RecordingStream) -> None:
        for b in range(n_blocks):
            t = times(b)
            for c in range(n_ch):
                rec.send_columns(f"gages/g{c + 1:02d}", indexes=[t],
                                 columns=rr.Scalars.columns(scalars=data[c]))

    n_log = 20000

    def per_sample(rec: rr.RecordingStream) -> None:
        for i in range(n_log // n_ch):
            rec.set_time("time", duration=np.timedelta64(int(i * 1e9 / fs_hz), "ns"))
            for c in range(n_ch):
                rec.log(f"gages/g{c + 1:02d}", rr.Scalars(data[c, i % n_blk]))

    total = n_blocks * n_blk * n_ch
    run("send_columns, 1 entity x 16-wide", wide, total)
    run("send_columns, 16 entities", per_entity, total)
    run("rr.log per sample", per_sample, n_log)


def bench_trial(tmp: Path) -> None:
    mcap, rrd = tmp / "trial.mcap", tmp / "trial.rrd"
    subprocess.run([sys.executable, "-m", "ramdaq", "trial", "--rig", str(RIG), "--medium", "water",
                    "--duration", "40", "--impact-every", "10", "--fast", "--quiet",
                    "--out", str(mcap), "--rrd", str(rrd)], check=True, stdout=subprocess.DEVNULL)
    m, r = mcap.stat().st_size, rrd.stat().st_size
    print(f"ramdaq trial, 40 s, 4 blows: MCAP {m / 1e6:.2f} MB, .rrd {r / 1e6:.2f} MB "
          f"= {r / m:.2f}x the MCAP")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="stream seconds per rate")
    ap.add_argument("--live-rate", type=float, default=LIVE_RATE_HZ,
                    help=f"live rows/s per channel (default {LIVE_RATE_HZ:g})")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for fs in (2048.0, 25600.0):
            bench_view(fs, args.seconds, args.live_rate, Path(tmp))
        bench_raw(25600.0, min(args.seconds, 10.0), Path(tmp))
        bench_trial(Path(tmp))


if __name__ == "__main__":
    main()
