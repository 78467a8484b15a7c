"""RSS growth of the Rerun view alone, per minute of stream: what the ``.rrd`` writer holds.

A :class:`~ramdaq.daq.rerun_view.RerunView` writing an ``.rrd`` is fed 16-gage blocks of noise
as fast as it takes them, with what a live trial logs per blow every ``--every`` s (markers,
full-rate traces, 16 final results with their envelopes, the mode shape) and, with ``--looks``,
a first look of every gage every 0.5 s of the first 25 s of each decay, each followed by a
flush of Rerun's batcher (a live trial's looks are 0.5 s of wall time apart, so each becomes
chunks of its own; without the flush a fast loop would merge them). Rerun's file footer keeps a
manifest entry per chunk in memory until the file is closed, so RSS grows with the chunks
written; ``--no-footer`` shows the difference. Prints the slope of RSS against stream minutes
after the first two, the .rrd size and CPU seconds. No analysis runs: this isolates the view
(``benchmarks/soak.py`` is the whole trial).

    python benchmarks/rerun_rss.py [--seconds 600] [--looks] [--no-footer] [--batch 0.2]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil

from ramdaq.daq.rerun_view import RerunView
from ramdaq.drivers.block import Block
from ramdaq.drivers.sim import SimDevice

RIG = Path(__file__).resolve().parent.parent / "recordings" / "rigs" / "albacore.toml"


def log_blow(view: RerunView, k: int, onset_s: float, fs: float, rng) -> None:
    """What the session logs for one accepted blow."""
    n_ch = view.info.n_channels
    view.log_impact(k, onset_s, {"double_hit": False}, None)
    view.log_impact(k, onset_s, {"double_hit": False}, True, "")
    view.log_full_rate(int((onset_s - 0.2) * fs), rng.normal(size=(n_ch, int(1.2 * fs))), fs, k=k)
    t = np.linspace(0.0, 25.0, 256)
    for g in range(1, 17):
        view.log_gage_result(k, g, onset_s + 25, 13.0, 0.05, 1.0, True, decay_t_s=onset_s + t,
                             envelope=np.exp(-t))
    view.log_mode_shape(k, 13.0, {g: 1.0 for g in range(1, 17)})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=600.0, help="stream seconds")
    ap.add_argument("--rate", type=float, default=2048.0, help="sample rate, Hz")
    ap.add_argument("--every", type=float, default=30.0, help="s between blows")
    ap.add_argument("--looks", action="store_true", help="first looks every 0.5 s of a decay")
    ap.add_argument("--footer", action=argparse.BooleanOptionalAction, default=True)
    ap.add_argument("--batch", type=float, default=0.2, help="RerunView live_batch_s")
    a = ap.parse_args()
    info = SimDevice(RIG, medium="water", fs_hz=a.rate).open()
    proc, rng = psutil.Process(), np.random.default_rng(0)
    n = round(0.05 * a.rate)
    counts = rng.integers(-1000, 1000, size=(info.n_channels, n), dtype=np.int32)
    scale = np.full(info.n_channels, 1e-3)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "view.rrd"
        view = RerunView(info, rrd_path=path, footer=a.footer, live_batch_s=a.batch)
        t0, k, onset, points = time.process_time(), 0, -1e9, []
        for i in range(int(a.seconds * a.rate / n)):
            view.log_block(Block(i, i * n, 0, a.rate, counts, scale))
            t = (i + 1) * n / a.rate
            if t >= (k + 0.5) * a.every:
                onset = t - 1.0
                log_blow(view, k, onset, a.rate, rng)
                k += 1
            if a.looks and onset + 0.2 < t < onset + 25 and i % 10 == 0:
                for g in range(1, 17):
                    view.log_gage_result(k, g, t, 13.0, 0.05, float("nan"), False)
                view.rec.flush(timeout_sec=30)
            if i % round(60 * a.rate / n) == 0:
                view.rec.flush(timeout_sec=30)
                points.append((t, proc.memory_info().rss / 1e6))
        cpu = time.process_time() - t0
        view.close()
        size = path.stat().st_size / 1e6
    tt, mb = np.array(points).T
    sel = tt >= 120
    slope = 60 * np.polyfit(tt[sel], mb[sel], 1)[0]
    print(f"view alone, {a.seconds:g} s at {a.rate:g} Hz, a blow every {a.every:g} s, looks "
          f"{'on' if a.looks else 'off'}, footer {'on' if a.footer else 'off'}, live batch "
          f"{a.batch:g} s: RSS {mb[sel][0]:.1f} -> {mb[-1]:.1f} MB, {slope:+.2f} MB per stream "
          f"minute; .rrd {size:.1f} MB; {cpu:.1f} s CPU")


if __name__ == "__main__":
    main()
