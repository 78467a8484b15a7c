"""Soak: a live trial on the simulated device, paced in real time, with the process's resident
memory (RSS) printed every few seconds and its growth fitted in MB per minute.

The trial is the session ``ramdaq trial`` runs (:class:`ramdaq.daq.session.Session`: recorder,
trigger, analyzer, optionally the Rerun view into an ``.rrd``), into a temporary folder, on the
ALBACORE-like rig in water with a blow every ``--impact-every`` s. The growth is the slope of a
least-squares line through the RSS samples after ``--warmup`` s (the first records, caches and
Rerun's batcher fill up then), with its standard error, twice: through every sample, and through
the lowest sample of each ``--window`` s (the floor the process returns to between analyses: a
sample taken while a 16-gage analysis holds its copies sits tens of MB above it, which in a
short run moves the first slope by more than the goal). The verdict is on the floor's slope;
both are printed, and the verdict against issue 22's goal: <= 5 MB/min, over 10 minutes at
2048 Hz with the view and 5 minutes at 25.6 kHz. The machine's load average (1 min) and how far
the paced stream fell behind the sample clock are printed with it: on a shared machine the
analyzer falls behind and sheds work (the summary's analyzer line counts it), which changes
what the process holds; say so with the figures. Each line's "lag" is wall minus stream seconds
since the first block arrived (the simulator's clock starts at open, so it begins at an offset);
how far it rises is how far the acquisition fell behind.

    python benchmarks/soak.py                         # 10 min at 2048 Hz, with the view
    python benchmarks/soak.py --rate 25600            # 5 min at 25.6 kHz, with the view
    python benchmarks/soak.py --minutes 2 --no-view   # a short check
    python benchmarks/soak.py --rate 25600 --keep /tmp/s   # keep soak.mcap and soak.rrd

Diagnostics (not what the trial does): ``--mmap-threshold`` and ``--trim-every`` change how
glibc's heap returns freed memory; "RSS" minus glibc's "held" is Rerun's own allocator
(mimalloc), Python's small objects and the code.
"""

from __future__ import annotations

import argparse
import ctypes
import ctypes.util
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the CLI sets it (daq/commands/cli.py)

import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import psutil  # noqa: E402

from ramdaq.daq.rerun_view import RerunView  # noqa: E402
from ramdaq.daq.session import Session  # noqa: E402
from ramdaq.drivers.sim import SimDevice  # noqa: E402

RIG = Path(__file__).resolve().parent.parent / "recordings" / "rigs" / "albacore.toml"
GOAL_MB_PER_MIN = 5.0
"""Issue 22's bound on RSS growth."""


@dataclass(frozen=True)
class Growth:
    """RSS growth fitted over the samples after the warm-up: slope and its standard error,
    MB/min, and the RSS at the first and last sample fitted, MB."""

    mb_per_min: float
    se_mb_per_min: float
    first_mb: float
    last_mb: float
    n: int


def floor_of(t_s: np.ndarray, rss_mb: np.ndarray, window_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The lowest RSS sample of each ``window_s`` window, with its time."""
    k = np.floor(t_s / window_s)
    idx = [int(np.flatnonzero(k == w)[np.argmin(rss_mb[k == w])]) for w in np.unique(k)]
    return t_s[idx], rss_mb[idx]


def fit_growth(t_s: np.ndarray, rss_mb: np.ndarray) -> Growth:
    """Least-squares line through (t_s, rss_mb); the slope's standard error from the residual
    scatter (RSS moves in steps, so this is a rough figure, not a statistical test)."""
    if t_s.size < 3:
        raise ValueError(f"soak: {t_s.size} RSS samples after the warm-up; run longer")
    a, b = np.polyfit(t_s, rss_mb, 1)
    resid = rss_mb - (a * t_s + b)
    se = np.sqrt(resid @ resid / (t_s.size - 2) / np.sum((t_s - t_s.mean()) ** 2))
    return Growth(60 * a, 60 * se, float(rss_mb[0]), float(rss_mb[-1]), int(t_s.size))


class _MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd",
                                               "usmblks", "fsmblks", "uordblks", "fordblks",
                                               "keepcost")]


def _mallinfo2():
    """glibc's ``mallinfo2`` (over all its arenas), or None where there is none (not glibc)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        fn = libc.mallinfo2
    except (OSError, AttributeError):
        return None
    fn.restype = _MallInfo2
    return fn


MALLINFO2 = _mallinfo2()


def glibc_heap_mb() -> tuple[float, float]:
    """glibc malloc's bytes in use and bytes it holds from the OS (arenas + mmapped blocks), MB;
    NaN without glibc. numpy's arrays live there; Rerun's Rust side does not (it has its own
    allocator, mimalloc), nor do Python's small objects (pymalloc arenas): RSS minus the held
    figure is theirs plus the code."""
    if MALLINFO2 is None:
        return float("nan"), float("nan")
    m = MALLINFO2()
    return (m.uordblks + m.hblkhd) / 1e6, (m.arena + m.hblkhd) / 1e6


class RssSampler:
    """Samples this process's RSS every ``every_s`` s on its own thread and prints it, with
    the stream seconds ``stream_s()`` says the session has taken; only samples taken while the
    stream still ran are kept (after it, the session only waits for its last finals)."""

    def __init__(self, every_s: float, stream_s, duration_s: float, lag_s, on_end) -> None:
        self.every_s, self.stream_s, self.duration_s = every_s, stream_s, duration_s
        self.trim_every_s: float | None = None  # glibc malloc_trim(0) this often, s, if set
        self.on_end = on_end  # called once, with this sampler, when the stream has ended
        self.lag_s = lag_s  # s the stream is behind the sample clock (wall; offset), or NaN
        self.samples: list[tuple[float, float]] = []  # (wall s since start, RSS MB)
        self.loads: list[float] = []  # 1-min load average at each sample
        self.lags: list[float] = []  # stream lag at each sample, s
        self._stop = threading.Event()
        self._proc = psutil.Process()
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="soak-rss", daemon=True)

    def __enter__(self) -> RssSampler:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        last_trim = time.monotonic()
        while not self._stop.wait(self.every_s):
            if self.trim_every_s and time.monotonic() - last_trim >= self.trim_every_s:
                last_trim = time.monotonic()
                ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim(0)
            t, rss = time.monotonic() - self._t0, self._proc.memory_info().rss / 1e6
            used, held = glibc_heap_mb()
            stream, lag, load = self.stream_s(), self.lag_s(), os.getloadavg()[0]
            if stream < self.duration_s:
                self.samples.append((t, rss))
                self.loads.append(load)
                self.lags.append(lag)
            print(f"  t = {t:6.0f} s   stream {stream:6.1f} s (lag {lag:5.1f} s)   RSS {rss:7.1f} MB"
                  f"   glibc heap {used:6.1f} used / {held:6.1f} held MB   load {load:5.2f}"
                  + ("" if stream < self.duration_s else "   (stream ended: not fitted)"),
                  flush=True)
            if stream >= self.duration_s and self.on_end is not None:
                self.on_end(self)  # the verdict now; the session still waits for its finals
                self.on_end = None


def run_trial(args: argparse.Namespace, folder: Path, on_end) -> tuple[object, RssSampler]:
    """The paced trial with the RSS sampler running; its outcome and the sampler."""
    duration = 60 * args.minutes
    impacts = [args.impact_every / 2 + args.impact_every * k
               for k in range(int(duration // args.impact_every))]
    dev = SimDevice(RIG, medium="water", seed=args.seed, duration_s=duration, impacts=impacts,
                    fs_hz=args.rate, pace="realtime")
    info = dev.open()
    view = (RerunView(info, rrd_path=folder / "soak.rrd", footer=args.footer) if args.view
            else None)
    session = Session(dev, record_path=folder / "soak.mcap", view=view, readout=False,
                      log=print if args.verbose else None)

    def lag_s() -> float:
        start = session.wall_at_start
        return (float("nan") if start is None
                else time.monotonic() - start - session.samples / info.fs_hz)

    with RssSampler(args.every, lambda: session.samples / info.fs_hz, duration, lag_s,
                    on_end) as rss:
        rss.trim_every_s = args.trim_every
        try:
            outcome = session.run()
        finally:
            if view is not None:
                view.close()
    return outcome, rss


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rate", type=float, default=2048.0, help="sample rate, Hz")
    ap.add_argument("--minutes", type=float, default=None,
                    help="trial length (default 10 at 2048 Hz, 5 at higher rates)")
    ap.add_argument("--view", action=argparse.BooleanOptionalAction, default=True,
                    help="log to a Rerun .rrd as the trial does")
    ap.add_argument("--footer", action=argparse.BooleanOptionalAction, default=True,
                    help="finish the .rrd with Rerun's footer, as the trial does (its chunk "
                         "manifest is held in memory until the end)")
    ap.add_argument("--impact-every", type=float, default=30.0, help="s between blows")
    ap.add_argument("--every", type=float, default=5.0, help="s between RSS samples")
    ap.add_argument("--warmup", type=float, default=60.0, help="s left out of the fit")
    ap.add_argument("--window", type=float, default=15.0,
                    help="s per window of the RSS floor (the lowest sample in each)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--trim-every", type=float, default=None, metavar="S",
                    help="glibc: malloc_trim(0) every S s on the sampler's thread (a diagnostic: "
                         "returns the heap's free pages; the trial does not do it)")
    ap.add_argument("--keep", type=Path, default=None, metavar="DIR",
                    help="write the .mcap and .rrd into DIR (kept) instead of a temporary folder")
    ap.add_argument("--verbose", action="store_true", help="print the session's hit messages")
    ap.add_argument("--mmap-threshold", type=int, default=None, metavar="BYTES",
                    help="glibc: give every allocation of BYTES or more its own mapping "
                         "(a diagnostic of heap fragmentation; the trial does not set it)")
    args = ap.parse_args()
    if args.minutes is None:
        args.minutes = 10.0 if args.rate <= 2048 else 5.0
    warmup = args.warmup
    view = f"on ({'with' if args.footer else 'without'} .rrd footer)" if args.view else "off"
    print(f"soak: {args.minutes:g} min at {args.rate:g} Hz, 16 gages, a blow every "
          f"{args.impact_every:g} s, view {view}; fit after {warmup:g} s; {os.cpu_count()} "
          f"cores, load average {os.getloadavg()[0]:.2f} (1 min) at the start")
    if args.mmap_threshold is not None:
        set_mmap_threshold(args.mmap_threshold)
        print(f"glibc: every allocation of {args.mmap_threshold} B or more in its own mapping")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) if args.keep is None else args.keep
        folder.mkdir(parents=True, exist_ok=True)
        outcome, rss = run_trial(args, folder, lambda r: print_growth(r, args))
        size = {p.suffix: p.stat().st_size / 1e6 for p in folder.glob("soak.*")}
    s = outcome.summary
    print(f"hits {s['hits']}, accepted {s['accepted']}; analyzer: {s['analyzer']}")
    print("files: " + ", ".join(f"{k} {v:.1f} MB" for k, v in sorted(size.items()))
          + (f"; the .rrd is {size['.rrd'] / size['.mcap']:.2f}x the MCAP (issue 19: <= 3x)"
             if ".rrd" in size else ""))


def print_growth(rss: RssSampler, args: argparse.Namespace) -> None:
    """The fits, the machine's load and the verdict, printed as soon as the stream has ended
    (at 25.6 kHz on a loaded machine the session may then wait minutes for its last finals)."""
    t, mb = (np.array(v) for v in zip(*rss.samples, strict=True))
    after = t >= args.warmup
    g = fit_growth(t[after], mb[after])
    floor = fit_growth(*floor_of(t[after], mb[after], args.window))
    print(f"RSS {g.first_mb:.1f} -> {g.last_mb:.1f} MB over {g.n} samples after the warm-up; "
          f"peak {mb.max():.1f} MB")
    print(f"growth, every sample: {g.mb_per_min:+.2f} +- {g.se_mb_per_min:.2f} MB/min")
    print(f"growth of the floor ({floor.n} windows of {args.window:g} s): "
          f"{floor.mb_per_min:+.2f} +- {floor.se_mb_per_min:.2f} MB/min")
    behind = np.nanmax(rss.lags) - np.nanmin(rss.lags)  # the first blocks set the reference
    print(f"machine: load average (1 min) over the stream: median {np.median(rss.loads):.2f}, "
          f"max {max(rss.loads):.2f}, on {os.cpu_count()} cores; the stream fell behind the "
          f"sample clock by up to {behind:.1f} s ({behind / (60 * args.minutes):.1%} of its "
          "length)")
    print(verdict(floor), flush=True)


def set_mmap_threshold(n_bytes: int) -> None:
    """glibc: every allocation of ``n_bytes`` or more gets its own mapping, returned to the OS
    when freed (``mallopt(M_MMAP_THRESHOLD)``; it also stops glibc raising the threshold to
    the largest block freed so far, which lets arrays of up to 32 MB settle in the heap)."""
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    if libc.mallopt(-3, int(n_bytes)) != 1:  # M_MMAP_THRESHOLD
        raise SystemExit(f"soak: mallopt(M_MMAP_THRESHOLD, {n_bytes}) failed")


def verdict(floor: Growth) -> str:
    """The one-line verdict on the floor's growth against :data:`GOAL_MB_PER_MIN`."""
    ok = floor.mb_per_min <= GOAL_MB_PER_MIN
    return (f"verdict: {'PASS' if ok else 'FAIL'}: the RSS floor grows {floor.mb_per_min:+.2f} "
            f"+- {floor.se_mb_per_min:.2f} MB/min; goal <= {GOAL_MB_PER_MIN:g} MB/min")


if __name__ == "__main__":
    main()
