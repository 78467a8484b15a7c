"""Replay and ``ramdaq analyze`` of a recording: CPU seconds and speed against real time.

Run:  python benchmarks/replay_speed.py [--file recordings/albacore-water.mcap] [--runs 2]
      [--long FILE.mcap | --no-long | --long-only]

Each command runs as its own process (single-threaded BLAS, as the CLI sets it); its CPU time
(user + system, ``resource.getrusage(RUSAGE_CHILDREN)``) is what is printed, the least of
``--runs`` (the machine is shared: wall time and even CPU time grow with its load, the least
is nearest to the program's own cost). Printed, each with issue 19's target:

- ``ramdaq replay FILE`` (trigger, first looks and final analyses, as fast as possible): CPU
  seconds and the recording's duration over them, "x real time" (target >= 100x on one core);
- ``ramdaq analyze FILE`` with the default plots, with ``--no-plots`` and with ``--plots all``
  (target <= 3 s CPU with plots for a 3-blow recording);
- where ``analyze``'s time goes, in this process: the imports (a fresh interpreter importing
  what ``ramdaq analyze`` imports), the analysis of every hit (:func:`run_analysis`, warm),
  each plot kind of one hit (built and written as PNG), and a redrawn decay plot's steps (its
  curves built; drawn and written; the PNG encoding alone);
- a 10-minute, 20-blow water recording (``--long``; made once with ``ramdaq record --fast`` and
  kept under the temp folder): ``ramdaq replay``'s CPU and its speed against real time with the
  start-up (a fresh interpreter importing what ``ramdaq replay`` imports) and without it (the
  steady state: ``(CPU - start-up)``), and where the CPU goes, measured here one part at a time:
  reading and decoding the blocks, the trigger over them, the finals (each analyzer job's own
  thread CPU, ``time.thread_time``; split into the estimator, ``analyze_decay``, and the rest of
  the final), the rest of the session (queue, bookkeeping),
  the summary printed at the end, and the live readout the command keeps (its plain lines;
  the session measured runs without it). A throughput ">= 100x real time" is honest only as a steady
  state plus a stated start-up cost: both are printed, and the start-up's share of
  ``scipy.signal`` (timed with it stubbed out) with the modules that still import it.

The steady state is the command's CPU less the start-up: it includes the interpreter's exit
(freeing what the session held, ~0.1-0.2 s), which no part below counts.

One core: a CPU figure is every thread of the process summed (``RUSAGE_CHILDREN``), so a
replay that spread its work over threads would show more CPU, not less; ``ramdaq replay`` runs
each final on the stream's own thread (``Session.finals_inline``), and its wall time is
printed beside its CPU (CPU / wall <= 1: at most one core busy).
"""

from __future__ import annotations

import argparse
import contextlib
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


def child_times(cmd: list[str], env: dict[str, str] | None = None) -> tuple[float, float]:
    """CPU seconds (user + system, every thread of the process summed) and wall seconds of
    the finished child process ``cmd`` (its environment this one's, or ``env``)."""
    before, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   env=(os.environ if env is None else env)
                   | {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})
    wall, after = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), wall


def child_cpu(cmd: list[str]) -> float:
    """CPU seconds (user + system) of the finished child process ``cmd``."""
    return child_times(cmd)[0]


def least(cmd: list[str], runs: int) -> float:
    return min(child_cpu(cmd) for _ in range(runs))


def least_with_wall(cmd: list[str], runs: int) -> tuple[float, float]:
    """The least CPU seconds over ``runs`` and the wall seconds of that run."""
    return min(child_times(cmd) for _ in range(runs))


def in_process(path: Path) -> None:
    """Where ``ramdaq analyze``'s CPU goes: imports, analysis, each plot kind of one hit."""
    imports = least([sys.executable, "-c", "import ramdaq.daq.commands.cli, "
                     "ramdaq.daq.commands.analyze, ramdaq.analysis.impact"], 1)
    base = least([sys.executable, "-c", "import numpy, scipy.special, scipy.linalg"], 1)
    signal = least([sys.executable, "-c", "import scipy.signal"], 1)
    mpl = least([sys.executable, "-c", "import ramdaq.daq.reports.impact_plots"], 1) - \
        least([sys.executable, "-c", "import ramdaq.analysis.impact"], 1)
    from ramdaq.daq.api import decay_samples
    from ramdaq.daq.commands.analyze import run_analysis
    from ramdaq.daq.reports import impact_plots

    run_analysis(path)  # warm: caches, lazily imported modules
    t0 = time.process_time()
    rig, hits = run_analysis(path)
    analysis = time.process_time() - t0
    n_hits = sum(h.accepted for h in hits)
    print(f"  of which: imports {imports:.2f} s (a fresh interpreter; scipy.signal alone "
          f"{signal:.2f} s, of which {signal - base:.2f} s past numpy, scipy.special and "
          f"scipy.linalg: it imports scipy.stats); matplotlib for the plots {mpl:.2f} s more; "
          f"analysis of {n_hits} hit(s) {analysis:.2f} s ({analysis / max(n_hits, 1):.2f} s a "
          f"hit; target 0.2)")
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
        steps = decay_steps(hits, rig, fs, Path(tmp) / "steps.png")
    print(f"  plots of one hit, built and written: {', '.join(parts)}")
    print(f"  the decay plots of all {n_hits} hits as ramdaq analyze draws them: {every:.2f} s "
          f"({every / max(n_hits, 1):.2f} s a hit); {steps}")


def decay_steps(hits: list, rig, fs: float, png: Path) -> str:
    """A redrawn decay plot's steps (the mean over the accepted hits after the first, drawn on
    the first's figure as ``ramdaq analyze`` draws them): its curves built, drawn and written,
    and of that the PNG encoding alone."""
    import numpy as np

    from ramdaq.daq.api import decay_samples
    from ramdaq.daq.reports import impact_plots
    from ramdaq.daq.reports import png as png_file

    accepted = [h for h in hits if h.accepted]
    reuse: dict = {}
    build = write = encode = 0.0
    for i, h in enumerate(accepted):
        t0 = time.process_time()
        fig = impact_plots.decay_figure(h.analysis, decay_samples(h, rig), fs, reuse)
        t1 = time.process_time()
        impact_plots.write_decay_png(fig, png, reuse)
        t2 = time.process_time()
        png_file.encode_png(np.asarray(fig.canvas.buffer_rgba())[..., :3], impact_plots.DPI)
        if i:  # the first builds the figure and its shared layer
            build, write, encode = build + t1 - t0, write + t2 - t1, encode + time.process_time() - t2
    n = max(len(accepted) - 1, 1)
    return (f"a redrawn hit: curves built {build / n:.3f} s, drawn and written {write / n:.3f} s "
            f"(of which the PNG encoding {encode / n:.3f} s)")


LONG_CMD = ["record", "--rig", str(ROOT / "recordings" / "rigs" / "albacore.toml"), "--medium",
            "water", "--duration", "600", "--impact-every", "30", "--fast", "--quiet"]
"""The 10-minute recording: a blow every 30 s (20 blows), water, the simulator flat out."""


def long_recording(path: Path | None) -> Path:
    """``path``, or the 10-minute recording made once (:data:`LONG_CMD`) under the temp folder
    (``-viewchunks``: the live view's topics in chunks of their own, as the recorder writes them
    now; the file made before mixed them into the blocks' chunks, which a replay then reads all
    of). Written to a temporary name and renamed, so a benchmark run beside never reads half."""
    if path is not None:
        return path
    out = Path(tempfile.gettempdir()) / "ramdaq-bench" / "albacore-water-600s-20blows-viewchunks.mcap"
    if not out.is_file():
        out.parent.mkdir(parents=True, exist_ok=True)
        part = out.with_name(f"{out.stem}.{os.getpid()}.part.mcap")
        print(f"making {out} (once): ramdaq {' '.join(LONG_CMD)}", flush=True)
        subprocess.run([sys.executable, "-m", "ramdaq.daq.commands.cli", *LONG_CMD, "--out",
                        str(part), "--overwrite"], check=True, stdout=subprocess.DEVNULL)
        part.replace(out)
    return out


REPLAY_IMPORTS = ("import ramdaq.daq.commands.cli, ramdaq.daq.session, "
                  "ramdaq.drivers.mcap_replay, ramdaq.daq.commands.analyze")
"""What ``ramdaq replay`` imports before it reads a block (its start-up, with the interpreter's)."""


def speed_line(dur: float, cpu: float, startup: float, wall: float | None = None) -> str:
    """``ramdaq replay``'s speed against real time with and without its start-up (and, given
    ``wall``, the wall time of that run: CPU over wall <= 1 says it ran on one core)."""
    steady = max(cpu - startup, 1e-9)
    on_wall = ("" if wall is None else f"; wall {wall:.2f} s, CPU / wall {cpu / wall:.2f} (the "
               f"CPU is every thread's, summed: <= 1 is one core at most)")
    return (f"  ramdaq replay: {cpu:.2f} s CPU = {dur / cpu:.1f}x real time with the start-up "
            f"({startup:.2f} s: interpreter and imports); steady state {steady:.2f} s CPU = "
            f"{dur / steady:.0f}x real time (target >= 100x){on_wall}")


STUB_SIGNAL = ("import sys, types, scipy; sys.modules['scipy.signal'] = scipy.signal = "
               "types.ModuleType('scipy.signal'); ")
"""Put in front of :data:`REPLAY_IMPORTS`: ``scipy.signal`` an empty module (its users only
call it, never at import), so that the start-up is timed as it would be without it."""


def signal_users() -> list[str]:
    """The ramdaq modules loaded in this process (after a replay) that import ``scipy.signal``,
    each with the functions it calls there."""
    import re

    users = []
    for name, mod in sorted(sys.modules.items()):
        file = getattr(mod, "__file__", None) if name.startswith("ramdaq") else None
        src = Path(file).read_text() if file else ""
        found = re.search(r"^(\s*)(from scipy import signal|import scipy\.signal)", src, re.M)
        if found:
            calls = sorted(set(re.findall(r"\b(?:scipy\.)?signal\.([a-z_]+(?:\.[a-z_]+)?)\(", src)))
            where = "in a function, when called" if found.group(1) else "with the module"
            users.append(f"{name.removeprefix('ramdaq.')} ({where}: {', '.join(calls)})")
    return users


def startup_line(runs: int, startup: float) -> str:
    """What ``scipy.signal`` costs the start-up, and which modules still import it; and, where
    this environment keeps Python from writing bytecode, what compiling ramdaq's sources costs
    it (:func:`compile_share`)."""
    users = '; '.join(signal_users()) or 'none (analysis/filters.py stands in)'
    probe = REPLAY_IMPORTS + "; import sys; print('scipy.signal' in sys.modules)"
    loaded = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                            check=True).stdout.strip() == "True"
    if not loaded:  # the stub would time the same imports: their difference is noise
        return (f"  start-up {startup:.2f} s CPU; scipy.signal is not imported at start-up"
                f"{compile_share(runs, startup)}; modules of the replay that import it when "
                f"called: {users}")
    without = least([sys.executable, "-c", STUB_SIGNAL + REPLAY_IMPORTS], runs)
    return (f"  start-up {startup:.2f} s CPU, of which scipy.signal (and what only it imports) "
            f"{startup - without:.2f} s (the same imports with scipy.signal an empty module: "
            f"{without:.2f} s){compile_share(runs, startup)}; imported on the replay path by: "
            f"{users}")


def compile_share(runs: int, startup: float) -> str:
    """With ``PYTHONDONTWRITEBYTECODE`` set (as where these benchmarks were first run), every
    ``ramdaq`` command compiles ramdaq's sources afresh (an installed package has its ``.pyc``;
    numpy's and scipy's are there): the start-up again with the bytecode cache (written once
    under a temporary ``PYTHONPYCACHEPREFIX``), as a clause for :func:`startup_line`."""
    if not os.environ.get("PYTHONDONTWRITEBYTECODE"):
        return ""
    with tempfile.TemporaryDirectory() as cache:
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        env["PYTHONPYCACHEPREFIX"] = cache
        cmd = [sys.executable, "-c", REPLAY_IMPORTS]
        child_times(cmd, env)  # writes the cache
        cached = min(child_times(cmd, env)[0] for _ in range(runs))
    return (f"; PYTHONDONTWRITEBYTECODE is set here: with the bytecode cache (as installed) the "
            f"start-up is {cached:.2f} s, compiling ramdaq's sources {startup - cached:.2f} s of it")


@contextlib.contextmanager
def estimator_timed():
    """The thread CPU seconds of each :func:`~ramdaq.analysis.impact.analyze_decay` call a
    final makes meanwhile (the estimator), in a list; the rest of a final is its judging, its
    record's copy to SI and its JSON."""
    from ramdaq.daq import analyzer

    spent: list[float] = []
    inner = analyzer.analyze_decay

    def timed(*args, **kwargs):
        t0 = time.thread_time()
        try:
            return inner(*args, **kwargs)
        finally:
            spent.append(time.thread_time() - t0)

    analyzer.analyze_decay = timed
    try:
        yield spent
    finally:
        analyzer.analyze_decay = inner


def readout_cpu(info, blocks: list) -> float:
    """CPU seconds of the live readout ``ramdaq replay`` keeps over ``blocks`` (its per-block
    statistics and its plain lines, on its own console as the session makes it, the standard
    output the null device as a pipe or a file)."""
    from ramdaq.daq.readout import LiveReadout

    with open(os.devnull, "w") as null, contextlib.redirect_stdout(null):
        readout = LiveReadout(info, adc_bits=info.extra.get("adc_bits"))
        t0 = time.process_time()
        with readout:
            for b in blocks:
                readout.update(b)
        return time.process_time() - t0


def replay_parts(path: Path, cpu: float, startup: float, wall: float | None = None,
                 runs: int = 1) -> None:
    """``ramdaq replay`` of ``path`` (``cpu`` s, ``startup`` of them the start-up) against real
    time, and where its CPU goes, one part at a time in this process (warm: the imports are the
    start-up's): reading, trigger, finals, the rest, the summary."""
    import io

    from ramdaq.daq.commands.cli import REPLAY_JOIN_S, _print_outcome, build_parser
    from ramdaq.daq.session import Session
    from ramdaq.daq.trigger import Trigger
    from ramdaq.drivers.mcap_replay import McapReplayDevice

    t0 = time.process_time()
    dev = McapReplayDevice(path, pace="fast", join_s=REPLAY_JOIN_S)  # as ramdaq replay reads it
    info = dev.open()
    blocks = list(dev)
    dev.close()
    read = time.process_time() - t0
    unzipped, skipped = dev.chunks_read
    dur = sum(b.n_samples for b in blocks) / info.fs_hz
    t0 = time.process_time()
    trig = Trigger(info)
    events = [e for b in blocks for e in trig.process(b)] + trig.flush()
    trigger = time.process_time() - t0
    readout = readout_cpu(info, blocks)
    blocks_n = range(len(blocks))
    del blocks, events, trig
    session = Session(McapReplayDevice(path, pace="fast", join_s=REPLAY_JOIN_S), readout=False)
    t0 = time.process_time()
    with estimator_timed() as estimator:
        outcome = session.run()
    whole = time.process_time() - t0
    finals = [j.cpu_s for j in session.job_times if j.kind == "final"]
    print(f"{path}: {dur:.1f} s at {info.fs_hz:g} Hz in {len(blocks_n)} blocks as read (joined up to "
          f"{REPLAY_JOIN_S:g} s), "
          f"{len(outcome.hits)} blow(s); load average {os.getloadavg()[0]:.1f}")
    print(speed_line(dur, cpu, startup, wall))
    print(startup_line(runs, startup))
    t0 = time.process_time()
    with contextlib.redirect_stdout(io.StringIO()):
        _print_outcome(outcome, build_parser().parse_args(["replay", str(path)]), info.rig_toml)
    report = time.process_time() - t0
    rest = whole - read - trigger - sum(finals)
    n = max(len(finals), 1)
    print(f"  where it goes (this process, warm; the session {whole:.2f} s CPU): reading and "
          f"decoding {read:.2f} s ({unzipped} chunks decompressed, {skipped} of the live view's "
          f"stepped over unread), trigger {trigger:.2f} s, finals {sum(finals):.2f} s "
          f"({len(finals)} of them, {sum(finals) / n:.2f} s a hit, {min(finals, default=0):.2f}-"
          f"{max(finals, default=0):.2f}), the rest of the session (queue, bookkeeping) "
          f"{rest:.2f} s, the summary printed {report:.3f} s")
    print(f"  the live readout ramdaq replay keeps (a plain line every 2 s of stream time; not in "
          f"the session above, which runs without it): {readout:.2f} s")
    print(f"  the finals split: the estimator (analyze_decay) {sum(estimator):.2f} s, the rest of "
          f"the final (judging the event, its record to SI, the JSON) "
          f"{sum(finals) - sum(estimator):.3f} s")
    print(f"  without the finals (reading, trigger, the rest): {whole - sum(finals):.2f} s CPU = "
          f"{dur / max(whole - sum(finals), 1e-9):.0f}x real time; the finals alone "
          f"{dur / max(sum(finals), 1e-9):.0f}x")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--file", default=str(ROOT / "recordings" / "albacore-water.mcap"))
    ap.add_argument("--runs", type=int, default=2, help="runs per command; the least is shown")
    ap.add_argument("--long", default=None, type=Path, help="the long recording (default: the "
                    "10-minute one, made once under the temp folder)")
    ap.add_argument("--no-long", action="store_true", help="skip the long recording")
    ap.add_argument("--long-only", action="store_true", help="only the long recording")
    args = ap.parse_args()
    path = Path(args.file)
    from ramdaq.daq.recording import read_recording

    rec = read_recording(path)
    dur = rec.duration_s
    ramdaq = [sys.executable, "-m", "ramdaq.daq.commands.cli"]
    print(f"{path.name}: {dur:.1f} s at {rec.fs_hz:g} Hz, {len(rec.impacts)} blow(s); "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (figures are noisy)")
    startup = least([sys.executable, "-c", REPLAY_IMPORTS], args.runs)
    if not args.long_only:
        short(path, dur, ramdaq, startup, args.runs)
    if args.no_long:
        return
    long = long_recording(args.long)
    cpu, wall = least_with_wall([*ramdaq, "replay", str(long)], args.runs)
    replay_parts(long, cpu, startup, wall, args.runs)


def short(path: Path, dur: float, ramdaq: list[str], startup: float, runs: int) -> None:
    """``ramdaq replay`` and ``ramdaq analyze`` of the (short) sample recording."""
    print(speed_line(dur, least([*ramdaq, "replay", str(path)], runs), startup))
    with tempfile.TemporaryDirectory() as out:
        for label, extra in (("default plots (decay)", []), ("--no-plots", ["--no-plots"]),
                             ("--plots all", ["--plots", "all"])):
            cpu = least([*ramdaq, "analyze", str(path), "--out", out, *extra], runs)
            print(f"  ramdaq analyze, {label}: {cpu:.2f} s CPU (target <= 3 with plots)")
    in_process(path)


if __name__ == "__main__":
    main()
