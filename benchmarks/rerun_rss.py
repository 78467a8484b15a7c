"""RSS growth of the Rerun view alone, per minute of stream: what the ``.rrd`` writer holds.

A :class:`~ramdaq.daq.rerun_view.RerunView` writing an ``.rrd`` is fed 16-gage blocks of noise,
as fast as it takes them or, with ``--pace 1``, in real time as a live trial feeds it, with what
a live trial logs per blow every ``--every`` s (markers, 1.2 s of full-rate traces unless
``--no-full-rate``, 16 final results with their envelopes, the mode shape) and, with ``--looks``,
a first look of every gage every 0.5 s of the first 25 s of each decay, each followed by a
flush of Rerun's batcher (a live trial's looks are 0.5 s of wall time apart, so each becomes
chunks of its own; without the flush a fast loop would merge them). Rerun's file footer keeps a
manifest entry per chunk in memory until the file is closed (``--no-footer`` shows what that
costs), and Rerun's allocator keeps freed pages until the thread that owns them allocates
again, which a fast loop does at once and a paced one does not: only ``--pace 1`` shows what a
live trial holds. Prints the slope of RSS against stream minutes after ``--warmup`` s, the .rrd
size, its number of chunks (``rerun rrd stats``) and CPU seconds; ``--verbose`` every sample
(RSS, glibc's heap, pyarrow's pool). No analysis runs: this isolates the view
(``benchmarks/soak.py`` is the whole trial).

    python benchmarks/rerun_rss.py [--seconds 600] [--looks] [--no-footer] [--batch 0.2]
    python benchmarks/rerun_rss.py --seconds 300 --rate 25600 --looks --pace 1 --warmup 60
"""

from __future__ import annotations

import argparse
import re
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil
import pyarrow as pa
from soak import glibc_heap_mb, set_mmap_threshold  # benchmarks/soak.py, this script's folder

from ramdaq.daq.rerun_view import RerunView, rerun_binary
from ramdaq.drivers.block import Block
from ramdaq.drivers.sim import SimDevice

RIG = Path(__file__).resolve().parent.parent / "recordings" / "rigs" / "albacore.toml"


def log_blow(view: RerunView, k: int, onset_s: float, fs: float, rng, full_rate: bool = True) -> None:
    """What the session logs for one accepted blow (``full_rate``: with its 1.2 s of full-rate
    traces)."""
    n_ch = view.info.n_channels
    view.log_impact(k, onset_s, {"double_hit": False}, None)
    view.log_impact(k, onset_s, {"double_hit": False}, True, "")
    if full_rate:
        view.log_full_rate(int((onset_s - 0.2) * fs), rng.normal(size=(n_ch, int(1.2 * fs))), fs, k=k)
    t = np.linspace(0.0, 25.0, 256)
    for g in range(1, 17):
        view.log_gage_result(k, g, onset_s + 25, 13.0, 0.05, 1.0, True, decay_t_s=onset_s + t,
                             envelope=np.exp(-t))
    view.log_mode_shape(k, 13.0, {g: 1.0 for g in range(1, 17)})


def count_chunks(path: Path) -> int:
    """Chunks in an ``.rrd`` (``rerun rrd stats``), or -1 if it does not say."""
    out = subprocess.run([str(rerun_binary()), "rrd", "stats", str(path)], capture_output=True,
                         text=True).stdout
    m = re.search(r"num_chunks = (.*)", out)  # digits in groups of 3, apart by a (thin) space
    digits = re.sub(r"\D", "", m.group(1)) if m else ""
    return int(digits) if digits else -1


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=600.0, help="stream seconds")
    ap.add_argument("--rate", type=float, default=2048.0, help="sample rate, Hz")
    ap.add_argument("--every", type=float, default=30.0, help="s between blows")
    ap.add_argument("--looks", action="store_true", help="first looks every 0.5 s of a decay")
    ap.add_argument("--full-rate", action=argparse.BooleanOptionalAction, default=True,
                    help="log 1.2 s of full-rate traces around each blow")
    ap.add_argument("--footer", action=argparse.BooleanOptionalAction, default=True)
    ap.add_argument("--batch", type=float, default=0.2, help="RerunView live_batch_s")
    ap.add_argument("--pace", type=float, default=0.0, metavar="X",
                    help="feed at X times real time (1 = as a live trial; 0 = as fast as it goes)")
    ap.add_argument("--flush", action="store_true",
                    help="with --pace: flush Rerun every 10 stream s, as the fast loop does")
    ap.add_argument("--mmap-threshold", type=int, default=None, metavar="BYTES",
                    help="glibc: every allocation of BYTES or more in its own mapping")
    ap.add_argument("--verbose", action="store_true", help="print every RSS sample")
    ap.add_argument("--out", type=Path, default=None, help="write (and keep) the .rrd here")
    ap.add_argument("--warmup", type=float, default=120.0, help="stream s left out of the fit")
    a = ap.parse_args()
    if a.mmap_threshold is not None:
        set_mmap_threshold(a.mmap_threshold)
    info = SimDevice(RIG, medium="water", fs_hz=a.rate).open()
    proc, rng = psutil.Process(), np.random.default_rng(0)
    n = round(0.05 * a.rate)
    counts = rng.integers(-1000, 1000, size=(info.n_channels, n), dtype=np.int32)
    scale = np.full(info.n_channels, 1e-3)
    with tempfile.TemporaryDirectory() as tmp:
        path = a.out or Path(tmp) / "view.rrd"
        view = RerunView(info, rrd_path=path, footer=a.footer, live_batch_s=a.batch)
        t0, k, onset, points = time.process_time(), 0, -1e9, []
        wall0 = time.monotonic()
        for i in range(int(a.seconds * a.rate / n)):
            view.log_block(Block(i, i * n, 0, a.rate, counts, scale))
            t = (i + 1) * n / a.rate
            if a.pace > 0 and (ahead := t / a.pace - (time.monotonic() - wall0)) > 0:
                time.sleep(ahead)
            if t >= (k + 0.5) * a.every:
                onset = t - 1.0
                log_blow(view, k, onset, a.rate, rng, a.full_rate)
                k += 1
            if a.looks and onset + 0.2 < t < onset + 25 and i % 10 == 0:
                for g in range(1, 17):
                    view.log_gage_result(k, g, t, 13.0, 0.05, float("nan"), False)
                view.rec.flush(timeout_sec=30)
            if i % round(10 * a.rate / n) == 0:
                if a.pace <= 0 or a.flush:
                    view.rec.flush(timeout_sec=30)
                points.append((t, proc.memory_info().rss / 1e6))
                if a.verbose:
                    used, held = glibc_heap_mb()
                    print(f"  stream {t:6.0f} s  RSS {points[-1][1]:6.1f} MB  glibc heap "
                          f"{used:6.1f} used / {held:6.1f} held MB  pyarrow pool "
                          f"{pa.total_allocated_bytes() / 1e6:6.1f} MB", flush=True)
        cpu = time.process_time() - t0
        view.close()
        size = path.stat().st_size / 1e6
        chunks = count_chunks(path)
    tt, mb = np.array(points).T
    sel = tt >= a.warmup
    slope = 60 * np.polyfit(tt[sel], mb[sel], 1)[0]
    print(f"view alone, {a.seconds:g} s at {a.rate:g} Hz, a blow every {a.every:g} s, looks "
          f"{'on' if a.looks else 'off'}, footer {'on' if a.footer else 'off'}, live batch "
          f"{a.batch:g} s: RSS {mb[sel][0]:.1f} -> {mb[-1]:.1f} MB, {slope:+.2f} MB per stream "
          f"minute; .rrd {size:.1f} MB in {chunks} chunks ({chunks / a.seconds * 60:.0f} per minute); "
          f"{cpu:.1f} s CPU")


if __name__ == "__main__":
    main()
