"""Where one gap-benchmark scenario's CPU goes: generation, recording, loading, and each of
``ramdaq gap``'s layers (model level, data-only checks, effect search), for trials of a given
number of blows -- the figures the benchmark's trial design and default size are chosen from.

    python benchmarks/gap_scenario_cost.py --blows 6 4 --effects none double_hit
    python benchmarks/gap_scenario_cost.py --family modal --rigs 0 1 2

Each scenario runs in this process, one at a time, exactly as ``ramdaq gap-benchmark`` runs it
(:func:`ramdaq.daq.commands.gap_bench.run_one`); its stages are timed with
``time.process_time`` (CPU of this process: steadier than wall time on a shared machine, which
is printed too). Prints one line per scenario and a median per blow count, and the whole
benchmark's CPU at the default size it implies. ``double_hit`` is the part of ``data_only`` spent
in the early double-hit check (:func:`ramdaq.analysis.gap.signal_checks.double_hits`, as
:mod:`ramdaq.analysis.gap.sensors` calls it), printed beside the stages, not added to them.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections import defaultdict

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

STAGES = ("generate", "record", "load", "model_level", "data_only", "effect_search")
INSIDE = ("double_hit",)
"""Parts of a stage timed on their own (within ``data_only``), not added to the stages."""


def _timed(module, name: str, stage: str, cpu: dict[str, float]) -> None:
    """Wrap ``module.name`` so its CPU time adds to ``cpu[stage]``."""
    f = getattr(module, name)

    def wrapper(*a, **k):
        t = time.process_time()
        try:
            return f(*a, **k)
        finally:
            cpu[stage] += time.process_time() - t

    setattr(module, name, wrapper)


def main(argv: list[str]) -> int:
    from ramdaq.analysis.gap import sensors
    from ramdaq.daq import gap_layers, record
    from ramdaq.daq.commands import gap, gap_bench

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--blows", type=int, nargs="+", default=[6, 4])
    p.add_argument("--family", choices=("truth", "modal"), default="truth")
    p.add_argument("--effects", nargs="+", default=["none"])
    p.add_argument("--rigs", type=int, nargs="+", default=[0, 1, 2],
                   help="scenario index within each class (the rigs are taken in turn)")
    p.add_argument("--seeds", default="check")
    p.add_argument("--perturb", type=float, default=0.25)
    a = p.parse_args(argv)
    cpu: dict[str, float] = defaultdict(float)
    for module, name, stage in ((gap_bench, "_generate_truth", "generate"),
                                (gap_bench, "_generate_modal", "generate"),
                                (record, "record", "record"), (gap, "load_trial", "load"),
                                (gap_layers, "rig_to_modes", "model_level"),
                                (gap_layers, "data_only", "data_only"),
                                (gap_layers, "diagnose", "effect_search"),
                                (sensors, "double_hits", "double_hit")):
        _timed(module, name, stage, cpu)
    per_blows: dict[int, list[float]] = defaultdict(list)
    print(f"{'blows':>5s} {'effect':14s} {'rig':16s} " + " ".join(f"{s:>13s}" for s in STAGES + INSIDE)
          + f" {'other':>6s} {'total CPU':>9s} {'wall':>6s}  named")
    for blows in a.blows:
        scs = gap_bench.scenarios(max(a.rigs) + 1, a.seeds, tuple(a.effects), a.perturb, a.family, blows)
        for sc in scs:
            if sc["seed"] % 1000 not in a.rigs:
                continue
            cpu.clear()
            t0, w0 = time.process_time(), time.perf_counter()
            with tempfile.TemporaryDirectory() as tmp:
                r = gap_bench.run_one(sc, tmp)
            total, wall = time.process_time() - t0, time.perf_counter() - w0
            per_blows[blows].append(total)
            print(f"{blows:5d} {sc['effect']:14s} {sc['rig'] + '/' + sc['medium']:16s} "
                  + " ".join(f"{cpu[s]:13.2f}" for s in STAGES + INSIDE)
                  + f" {total - sum(cpu[s] for s in STAGES):6.2f} {total:9.2f} {wall:6.1f}  "
                  f"{r.get('named') or r.get('error')}", flush=True)
    load = os.getloadavg()[0]
    print(f"load average at the end: {load:.1f} on {os.cpu_count()} cores (CPU times are this process's)")
    for blows, v in per_blows.items():
        print(f"{blows} blows: median {np.median(v):.1f} s CPU a scenario over {len(v)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
