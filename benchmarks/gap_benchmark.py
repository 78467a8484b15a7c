"""Gap diagnosis benchmark: ``ramdaq gap benchmark`` itself, with its own options (see
daq/commands/gap_bench.py).

    python benchmarks/gap_benchmark.py --seeds dev --per-class 20   # tune: writes the thresholds
    python benchmarks/gap_benchmark.py                              # the benchmark's own seeds
    python benchmarks/gap_benchmark.py --seeds holdout              # once, after the work is final
    python benchmarks/gap_benchmark.py --family modal --per-class 1 # smoke: the independent family

Defaults: both generator families (--family all), rigs perturbed by up to 25 % (--perturb 0.25),
every layer of ramdaq gap run, 6 trials per class of 4 blows (--per-class, --blows: the whole run
within 20 min with --jobs 2 on two cores); figures per family and per layer with their 95 %
intervals, and the run's wall and CPU time. Where one scenario's CPU goes:
benchmarks/gap_scenario_cost.py.

Prints the confusion matrix, top-1/top-3 identification, false alarms, localisation, the gap
closed on held-out impacts and the cost per diagnosis.
"""

from __future__ import annotations

import sys

from ramdaq.daq.commands.cli import main  # sets one BLAS thread per process before numpy loads

if __name__ == "__main__":
    sys.exit(main(["gap", "benchmark", *sys.argv[1:]]))
