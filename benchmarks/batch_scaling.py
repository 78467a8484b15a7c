"""``ramdaq batch analyze`` scaling: wall time and speed-up on 1 and 2 local dask workers, and a
simulated scale-out to N workers from the measured per-task times.

The recordings are short simulated trials written by the project's own simulator and recorder
(``ramdaq record --device sim --fast``): ``--recordings`` of them (default 24), in turn an
ALBACORE-like rudder in air (6 s), the same in water (6 s) and a SAMPSON-like one in water (8 s),
one ram blow each at 2 s, seeds 1, 2, ... -- 16 channels at 2048 Hz, 0.2-0.3 MB each. Each is
analysed as ``ramdaq batch analyze --no-plots --force`` would (plots are matplotlib, not the
analysis).

Measured, per worker count: the wall time from the first submission to the last result
(``tasks``; the local cluster's start is printed apart), the sum of the task times measured
inside the tasks, and the speed-up over one worker. Then, on the running 2-worker cluster, the
scheduling overhead per task (empty tasks, submitted and gathered the same way), and the data
moved per task (the task's arguments and result as pickled, and the recording the worker reads
from storage).

Simulated: a fleet of ``--fleet`` recordings (default 500) whose task times are drawn from the
measured ones, list-scheduled longest first (as ``ramdaq batch`` submits them) on N workers,
each dispatch holding the one scheduler for the measured overhead and each task also reading its
recording over a ``--link-MBps`` link per worker (default 125 MB/s, 1 Gbit/s Ethernet). The
same model run on the measured tasks is printed beside the measured 1- and 2-worker walls.

The machine this runs on may be shared: the load average is printed before and after each
measurement; on a busy machine the measured times and speed-up are not an idle machine's.

    python benchmarks/batch_scaling.py [--recordings 24] [--fleet 500] [--keep DIR]
"""

from __future__ import annotations

import os

# one BLAS thread, set before numpy loads, as the ramdaq command does (the workers' nanny sets it
# for them)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import heapq  # noqa: E402
import pickle  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from ramdaq.daq.commands.batch import finish, open_client, plan_batch, run_tasks  # noqa: E402
from ramdaq.daq.commands.batch_tasks import TaskResult, TaskSpec  # noqa: E402

RIGS = Path(__file__).resolve().parent.parent / "recordings" / "rigs"
KINDS = (("albacore", "air", 6.0), ("albacore", "water", 6.0), ("sampson", "water", 8.0))


def make_recordings(folder: Path, n: int) -> list[Path]:
    """``n`` short simulated trials (see the module docstring) in ``folder``."""
    from ramdaq.daq.record import record
    from ramdaq.drivers.sim import SimDevice

    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for i in range(n):
        rig, medium, seconds = KINDS[i % len(KINDS)]
        path = folder / f"{rig}-{medium}-{i + 1:03d}.mcap"
        if not path.exists():
            dev = SimDevice(RIGS / f"{rig}.toml", medium=medium, seed=i + 1, duration_s=seconds,
                            impacts=[2.0], pace="fast")
            dev.open()
            record(dev, path, readout=False, overwrite=True)
        out.append(path)
    return out


def load() -> str:
    a, b, c = os.getloadavg()
    return f"load average {a:.1f}, {b:.1f}, {c:.1f} on {os.cpu_count()} cores"


def measure(folder: Path, out: Path, workers: int) -> tuple[float, float, list[TaskResult], float]:
    """One batch on a fresh local cluster of ``workers``: (the cluster's start, s; the tasks'
    wall, s; the results; the cluster's scheduling overhead per task, s)."""
    t0 = time.perf_counter()
    plan = plan_batch("analyze", [str(folder)], out, plots=False, force=True)
    with open_client(workers) as client:
        t_start = time.perf_counter() - t0
        outcome = run_tasks(client, plan)
        finish(outcome)
        overhead = dispatch_overhead(client)
    bad = [r for r in outcome.results.values() if r.status != "ok"]
    assert not bad, [(r.recording, r.status_reason) for r in bad]
    return t_start, outcome.seconds, list(outcome.results.values()), overhead


def _empty(spec: TaskSpec) -> TaskResult:
    return TaskResult(spec.path, spec.sha256, "ok")


def dispatch_overhead(client, n: int = 200) -> float:
    """Wall time per task of ``n`` empty tasks (the same spec in, a result out) submitted and
    gathered as ``ramdaq batch`` does, s: the scheduler's, the network's and the client's share
    of a task."""
    from distributed import as_completed

    spec = TaskSpec("/nothing.mcap", "0" * 64, "/nothing", False)
    t0 = time.perf_counter()
    futs = [client.submit(_empty, spec, pure=False) for _ in range(n)]
    for f in as_completed(futs):
        f.result()
        f.release()
    return (time.perf_counter() - t0) / n


def simulate(task_s: np.ndarray, read_bytes: np.ndarray, workers: int, overhead_s: float,
             link_Bps: float) -> float:
    """Makespan (s) of list scheduling the tasks, longest first, on ``workers``: the scheduler
    dispatches one task per ``overhead_s``; a task holds its worker for its time plus reading
    its recording at ``link_Bps``."""
    order = np.argsort(-task_s, kind="stable")
    free = [0.0] * workers
    heapq.heapify(free)
    end = 0.0
    for k, i in enumerate(order):
        start = max(heapq.heappop(free), (k + 1) * overhead_s)
        done = start + task_s[i] + read_bytes[i] / link_Bps
        heapq.heappush(free, done)
        end = max(end, done)
    return end


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--recordings", type=int, default=24, help="simulated recordings (>= 20)")
    p.add_argument("--fleet", type=int, default=500, help="recordings in the simulated scale-out")
    p.add_argument("--link-MBps", type=float, default=125.0, help="each worker's link to storage, MB/s")
    p.add_argument("--keep", type=Path, help="make (or reuse) the recordings here")
    a = p.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="batch_scaling_"))
    folder = a.keep or tmp / "recordings"
    paths = make_recordings(folder, a.recordings)
    sizes = np.array([q.stat().st_size for q in paths], float)
    print(f"{len(paths)} simulated recordings in {folder}: {sizes.min() / 1e6:.2f}-"
          f"{sizes.max() / 1e6:.2f} MB, 16 channels at 2048 Hz, one blow each")
    walls, task_lists, overhead = {}, {}, 0.0
    busy = os.getloadavg()[0] > 0.5 * (os.cpu_count() or 1)   # other jobs, before ours start
    for w in (1, 2):
        print(f"\n{w} worker{'s' * (w > 1)}: {load()}", flush=True)
        t_start, wall, results, over = measure(folder, tmp / f"out{w}", w)
        walls[w], task_lists[w] = wall, results
        overhead = over if w == 2 else overhead
        ts = np.array([r.seconds for r in results])
        print(f"  cluster start {t_start:.1f} s; tasks {wall:.1f} s wall, {ts.sum():.1f} s summed in the "
              f"tasks (median {np.median(ts):.2f} s, max {ts.max():.2f} s); after it: {load()}")
    print(f"\nspeed-up on 2 workers: {walls[1] / walls[2]:.2f}x"
          + (", measured on a busy machine (the load averages above, against its cores): how the CPU "
             "is split between these workers and the other jobs changes with the number of worker "
             "processes, so this is not an idle machine's figure" if busy else
             ", on a machine otherwise idle (the load averages above)"))

    res = task_lists[1]
    task_s = np.array([r.seconds for r in res])
    spec_b = np.mean([len(pickle.dumps(TaskSpec(r.recording, r.sha256, r.folder, r.plots))) for r in res])
    result_b = np.array([len(pickle.dumps(r)) for r in res])
    print(f"\nper task: {np.mean(task_s):.2f} s mean analysis (1 worker); scheduling overhead "
          f"{1e3 * overhead:.2f} ms (empty tasks, 2 workers); data moved: {spec_b:.0f} B of arguments "
          f"to the worker, {result_b.mean() / 1e3:.1f} kB of result back (mean, {result_b.max() / 1e3:.1f} "
          f"max), {sizes.mean() / 1e6:.2f} MB of recording read from storage")
    read = np.array([os.path.getsize(r.recording) for r in res], float)
    link = a.link_MBps * 1e6
    for w in (1, 2):
        model = simulate(task_s, read, w, overhead, link)
        print(f"  model on the measured tasks, {w} worker(s): {model:.1f} s (measured {walls[w]:.1f} s wall)")
    rng = np.random.default_rng(0)
    pick = rng.integers(0, len(res), a.fleet)
    ft, fr = task_s[pick], read[pick]
    t1 = simulate(ft, fr, 1, overhead, link)
    print(f"\nsimulated scale-out: {a.fleet} recordings drawn from the measured task times, "
          f"{1e3 * overhead:.2f} ms dispatch each, {a.link_MBps:g} MB/s per worker to storage")
    print("  workers    wall (s)   speed-up   efficiency   storage read (MB/s, all workers)")
    for n in (1, 2, 4, 8, 16, 32, 64, 128, 256):
        t = simulate(ft, fr, n, overhead, link)
        print(f"  {n:7d}  {t:10.1f}  {t1 / t:9.1f}x  {100 * t1 / t / n:10.0f} %  {fr.sum() / t / 1e6:10.2f}")
    print(f"  (a central scheduler dispatching a task every {1e3 * overhead:.2f} ms saturates near "
          f"{np.mean(task_s) / overhead:.0f} busy workers at these task times)")


if __name__ == "__main__":
    main()
