"""Gap diagnosis benchmark: the same run as ``ramdaq gap benchmark`` (see daq/gap_bench.py).

    python benchmarks/gap_benchmark.py --dev --per-class 6     # tune on the development seeds
    python benchmarks/gap_benchmark.py --per-class 20          # the benchmark's own seeds

Prints the confusion matrix, top-1/top-3 identification, false alarms, localisation, the gap
closed on held-out impacts and the cost per diagnosis.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from daq.gap_bench import run_benchmark  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dev", action="store_true", help="development seeds (writes the thresholds)")
    ap.add_argument("--per-class", type=int, default=20, help="scenarios per effect class")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--out", default="gap_benchmark", help="folder for the results")
    a = ap.parse_args()
    return run_benchmark(Path(a.out), per_class=a.per_class, dev=a.dev, jobs=a.jobs,
                         progress=lambda m: print(m, flush=True))


if __name__ == "__main__":
    sys.exit(main())
