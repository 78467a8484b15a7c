"""``ramdaq gap`` cost against the number of impacts: CPU s, wall s and max RSS of the whole
diagnosis and of its layers, the slope per impact, and the targets (issues 17 and 19).

The recordings are simulated trials of ALBACORE in water written by ``ramdaq record --fast``
(``--impact-every`` s between blows): 4 blows in 40 s, 6 in 60 s, 10 in 100 s and 20 in 600 s (the
10-minute recording of the memory target). They are made once in ``--dir`` (default a temporary
folder) and reused when present.

Each measurement runs in a fresh subprocess (this script with ``--child``) so its max RSS is its
own (``resource.getrusage(RUSAGE_CHILDREN).ru_maxrss`` of that child alone) and no cache of one
run helps another:

- ``gap``: :func:`ramdaq.daq.commands.gap.run_gap` as ``ramdaq gap --no-plots`` runs it (reading,
  model level, data-only layer, effect search) and the report's JSON;
- ``read``: reading the recording and cutting the trial (:func:`load_trial`, :func:`trial_data`);
- ``model``: the model level (:func:`ramdaq.analysis.gap.rigfit.model_level`);
- ``data``: the data-only layer (:func:`ramdaq.daq.gap_layers.data_only`);
- ``search``: the effect search (:func:`ramdaq.analysis.gap.diagnose.diagnose`) on the rig the
  model level calibrated.

A layer's CPU is measured around that layer alone (``time.process_time``); its max RSS is the
child's peak, which includes reading the trial and the layers run before it (``model`` before
``search``). CPU time is reported rather than wall time because the machine is shared: the load
average is printed before and after, and wall times under load are not an idle machine's. One
BLAS thread (``OPENBLAS_NUM_THREADS=1``): the targets are for one core.

    python benchmarks/gap_cost.py [--dir DIR] [--blows 4,10,20] [--layers] [--repeat 1]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RIG = Path(__file__).resolve().parent.parent / "recordings" / "rigs" / "albacore.toml"
TRIALS = {4: (40.0, 10.0), 6: (60.0, 10.0), 10: (100.0, 10.0), 20: (600.0, 30.0)}
"""Blows -> (duration s, s between blows)."""
TARGET_MB = 500.0
"""Max RSS of ``ramdaq gap`` on the 10-minute, 20-blow recording (issue 17/19)."""
TARGET_6_S = 10.0
"""Median CPU s of a 6-blow diagnosis, all layers, one core (issue 17)."""


def recording(folder: Path, blows: int) -> Path:
    """The simulated trial with ``blows`` impacts in ``folder`` (made if missing)."""
    dur, every = TRIALS[blows]
    out = folder / f"albacore-water-{blows}blows.mcap"
    if not out.exists():
        subprocess.run([sys.executable, "-m", "ramdaq", "record", "--rig", str(RIG), "--medium",
                        "water", "--duration", str(dur), "--impact-every", str(every), "--fast",
                        "--quiet", "--seed", "1", "--out", str(out)], check=True,
                       stdout=subprocess.DEVNULL)
    return out


def child(path: str, layer: str) -> dict:
    """Run one measurement in this process; CPU and wall of ``layer`` alone."""
    from dataclasses import replace

    from ramdaq.analysis.gap.diagnose import diagnose
    from ramdaq.analysis.gap.rigfit import model_level
    from ramdaq.daq.commands.gap import run_gap
    from ramdaq.daq.gap_layers import data_only
    from ramdaq.daq.gap_trial import load_trial, trial_data

    def timed(fn):
        c0, w0 = time.process_time(), time.perf_counter()
        out = fn()
        return out, time.process_time() - c0, time.perf_counter() - w0

    if layer == "gap":
        (_, _, d), cpu, wall = timed(lambda: run_gap(path))
        json.dumps(d.to_json())      # the report reads the features too
        return {"cpu": cpu, "wall": wall}
    (lt, td), cpu, wall = timed(lambda: (lambda lt: (lt, trial_data(lt)))(load_trial(path)))
    if layer == "read":
        return {"cpu": cpu, "wall": wall}
    if layer == "data":
        _, cpu, wall = timed(lambda: data_only(lt, td))
        return {"cpu": cpu, "wall": wall}
    level, cpu, wall = timed(lambda: model_level(td))
    if layer == "model":
        return {"cpu": cpu, "wall": wall}
    if level.fit is not None:
        lt = replace(lt, rig=level.fit.rig)
        td = trial_data(lt)
    _, cpu, wall = timed(lambda: diagnose(td))
    return {"cpu": cpu, "wall": wall}


def measure(path: Path, layer: str) -> dict:
    """One child run: its CPU and wall (of the layer) and max RSS (of the child), MB."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    p = subprocess.run([sys.executable, __file__, "--child", str(path), layer], env=env,
                       capture_output=True, text=True)
    if p.returncode:
        raise RuntimeError(f"{layer} on {path} failed:\n{p.stderr[-2000:]}")
    rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    out = json.loads(p.stdout.strip().splitlines()[-1])
    # ru_maxrss of all children is the largest of them: a child smaller than an earlier one
    # does not show; each child also reports its own
    out["rss_mb"] = max(out.pop("own_rss_kb"), rss if rss > before else 0) / 1024
    return out


def slope(xs: list[float], ys: list[float]) -> float:
    """Least-squares slope of ys on xs."""
    n = len(xs)
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys, strict=True)) / sxx if sxx else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dir", type=Path, default=None, help="where the recordings are (made)")
    ap.add_argument("--blows", default="4,10,20", help="comma-separated: of 4, 6, 10, 20")
    ap.add_argument("--layers", action="store_true", help="also each layer on its own")
    ap.add_argument("--repeat", type=int, default=1, help="runs of the whole gap per trial (median)")
    ap.add_argument("--child", nargs=2, metavar=("PATH", "LAYER"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        out = child(*a.child)
        out["own_rss_kb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        print(json.dumps(out))
        return
    folder = a.dir or Path(tempfile.mkdtemp(prefix="gap_cost_"))
    folder.mkdir(parents=True, exist_ok=True)
    blows = [int(b) for b in a.blows.split(",")]
    print(f"load average before: {os.getloadavg()[0]:.2f} (2 cores shared; wall times are noisy)")
    layers = ["gap"] + (["read", "model", "data", "search"] if a.layers else [])
    rows: dict[str, list[tuple[int, dict]]] = {k: [] for k in layers}
    print(f"{'blows':>5} {'dur s':>6} {'layer':>7} {'CPU s':>7} {'wall s':>7} {'max RSS MB':>10}")
    for b in blows:
        path = recording(folder, b)
        for layer in layers:
            runs = [measure(path, layer) for _ in range(a.repeat if layer == "gap" else 1)]
            runs.sort(key=lambda r: r["cpu"])
            m = runs[len(runs) // 2]
            rows[layer].append((b, m))
            print(f"{b:5d} {TRIALS[b][0]:6.0f} {layer:>7} {m['cpu']:7.2f} {m['wall']:7.2f} "
                  f"{m['rss_mb']:10.0f}" + (f"  (median of {len(runs)}: CPU "
                                             + ", ".join(f"{r['cpu']:.1f}" for r in runs) + ")"
                                             if len(runs) > 1 else ""), flush=True)
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    if len(blows) > 1:
        for layer, rs in rows.items():
            xs = [float(b) for b, _ in rs]
            print(f"slope {layer:>7}: {slope(xs, [m['cpu'] for _, m in rs]):.2f} CPU s/impact, "
                  f"{slope(xs, [m['rss_mb'] for _, m in rs]):.1f} MB/impact")
    got = {b: m for b, m in rows["gap"]}
    mb = f"{got[20]['rss_mb']:.0f} MB" if 20 in got else "not measured (--blows 20)"
    print(f"target: max RSS <= {TARGET_MB:.0f} MB on 10 minutes / 20 blows: {mb}")
    s6 = f"{got[6]['cpu']:.1f} s" if 6 in got else "not measured (--blows 6)"
    print(f"target: a 6-blow diagnosis <= {TARGET_6_S:.0f} s median CPU on one core: {s6}")


if __name__ == "__main__":
    main()
