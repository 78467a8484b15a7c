"""Replay and ``ramdaq analyze`` of a recording: CPU seconds and speed against real time.

Run:  python benchmarks/replay_speed.py [--file recordings/albacore-water.mcap] [--runs 2]

Each command runs as its own process (single-threaded BLAS, as the CLI sets it); its CPU time
(user + system, ``resource.getrusage(RUSAGE_CHILDREN)``) is what is printed, the least of
``--runs`` (the machine is shared: wall time and even CPU time grow with its load, the least
is nearest to the program's own cost). Printed, each with issue 19's target:

- ``ramdaq replay FILE`` (trigger, first looks and final analyses, as fast as possible): CPU
  seconds and the recording's duration over them, "x real time" (target >= 100x on one core);
- ``ramdaq analyze FILE`` with the default plots, with ``--no-plots`` and with ``--plots all``
  (target <= 3 s CPU with plots for a 3-blow recording);
- where ``analyze``'s time goes, in this process: the imports (a fresh interpreter importing
  what ``ramdaq analyze`` imports), the analysis of every hit (:func:`run_analysis`, warm) and
  each plot kind of one hit (built and written as PNG).
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]


def child_cpu(cmd: list[str]) -> float:
    """CPU seconds (user + system) of the finished child process ``cmd``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   env=os.environ | {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def least(cmd: list[str], runs: int) -> float:
    return min(child_cpu(cmd) for _ in range(runs))


def in_process(path: Path) -> None:
    """Where ``ramdaq analyze``'s CPU goes: imports, analysis, each plot kind of one hit."""
    imports = least([sys.executable, "-c", "import ramdaq.daq.commands.cli, "
                     "ramdaq.daq.commands.analyze, ramdaq.analysis.impact"], 1)
    from ramdaq.daq.api import decay_samples
    from ramdaq.daq.commands.analyze import run_analysis
    from ramdaq.daq.reports import impact_plots

    run_analysis(path)  # warm: caches, lazily imported modules
    t0 = time.process_time()
    rig, hits = run_analysis(path)
    analysis = time.process_time() - t0
    n_hits = sum(h.accepted for h in hits)
    print(f"  of which: imports {imports:.2f} s (a fresh interpreter); analysis of {n_hits} "
          f"hit(s) {analysis:.2f} s ({analysis / max(n_hits, 1):.2f} s a hit; target 0.2)")
    h = next(h for h in hits if h.accepted)
    x, fs = decay_samples(h, rig), h.event.record.fs_hz
    impact_plots.impact_figures(h.analysis, x, fs, rig, ("spectrum",))  # warm fonts
    with tempfile.TemporaryDirectory() as tmp:
        parts = []
        for kind in impact_plots.PLOT_KINDS:
            t0 = time.process_time()
            impact_plots.plot_impact(h.analysis, x, fs, rig, Path(tmp), 0, (kind,))
            parts.append(f"{kind} {time.process_time() - t0:.2f} s")
        t0 = time.process_time()
        reuse: dict = {}  # as ramdaq analyze draws them: one decay figure redrawn hit after hit
        for h in (h for h in hits if h.accepted):
            impact_plots.plot_impact(h.analysis, decay_samples(h, rig), fs, rig, Path(tmp),
                                     h.index, ("decay",), reuse=reuse)
        every = time.process_time() - t0
    print(f"  plots of one hit, built and written: {', '.join(parts)}")
    print(f"  the decay plots of all {n_hits} hits as ramdaq analyze draws them: {every:.2f} s "
          f"({every / max(n_hits, 1):.2f} s a hit)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--file", default=str(ROOT / "recordings" / "albacore-water.mcap"))
    ap.add_argument("--runs", type=int, default=2, help="runs per command; the least is shown")
    args = ap.parse_args()
    path = Path(args.file)
    from ramdaq.daq.recording import read_recording

    rec = read_recording(path)
    dur = rec.duration_s
    ramdaq = [sys.executable, "-m", "ramdaq.daq.commands.cli"]
    print(f"{path.name}: {dur:.1f} s at {rec.fs_hz:g} Hz, {len(rec.impacts)} blow(s); "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (figures are noisy)")
    replay = least([*ramdaq, "replay", str(path)], args.runs)
    print(f"  ramdaq replay: {replay:.2f} s CPU, {dur / replay:.1f}x real time (target >= 100x)")
    with tempfile.TemporaryDirectory() as out:
        for label, extra in (("default plots (decay)", []), ("--no-plots", ["--no-plots"]),
                             ("--plots all", ["--plots", "all"])):
            cpu = least([*ramdaq, "analyze", str(path), "--out", out, *extra], args.runs)
            print(f"  ramdaq analyze, {label}: {cpu:.2f} s CPU (target <= 3 with plots)")
    in_process(path)


if __name__ == "__main__":
    main()
