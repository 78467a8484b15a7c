"""Whether a change moved any number of a hit's final analysis: dump and compare.

Run:  python benchmarks/hit_results.py dump FILE [--hits 5] [--seconds 6 14]
      python benchmarks/hit_results.py compare A B

``dump`` runs :func:`ramdaq.analysis.impact.analyze_decay` on the ragged records of
``benchmarks/hit_cost.py --ragged`` (the same seeds, so two trees dump the same hits) and pickles
the analyses; ``compare`` walks two dumps field by field (dataclasses, dicts, sequences, arrays,
numbers) and prints every leaf that differs with its largest relative difference, then how many
leaves were compared and how many differ (exit status 1 where any does). A speed change that
claims "the same numbers" shows 0 differing leaves here; one that moves a filter's rounding shows
its largest relative difference. Figures for CPU cost: ``hit_cost.py``; instruction counts of a
dump run (which does not drift with the machine's load): run ``dump`` under
``valgrind --tool=callgrind``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import pickle
import sys

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import hit_cost  # noqa: E402

from ramdaq.analysis.impact import analyze_decay  # noqa: E402


def dump(path: str, hits: int, seconds: list[float]) -> None:
    """Pickle ``analyze_decay`` of ``hits`` ragged records of each length in ``seconds`` (s)."""
    out = []
    for decay_s in seconds:
        rig, xs, fs, gages = hit_cost.records("water", hits, decay_s, ragged=True)
        out += [analyze_decay(x, fs, rig, gages, onset_s=hit_cost.ONSET_S,
                              decay_start_s=hit_cost.ONSET_S + hit_cost.SKIP_S) for x in xs]
    with open(path, "wb") as fh:
        pickle.dump(out, fh)
    print(f"{len(out)} analyses written to {path}")


def differences(a: object, b: object, path: str = "") -> tuple[int, list[str]]:
    """(leaves compared, one line per differing leaf) between two analysis trees ``a``, ``b``."""
    if dataclasses.is_dataclass(a):
        pairs = [(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
                 for f in dataclasses.fields(a)]
    elif isinstance(a, dict):
        if a.keys() != b.keys():
            return 1, [f"{path}: keys {sorted(map(str, a))} != {sorted(map(str, b))}"]
        pairs = [(a[k], b[k], f"{path}[{k!r}]") for k in a]
    elif isinstance(a, list | tuple):
        if len(a) != len(b):
            return 1, [f"{path}: length {len(a)} != {len(b)}"]
        pairs = [(u, v, f"{path}[{i}]") for i, (u, v) in enumerate(zip(a, b, strict=True))]
    else:
        return 1, _leaf(a, b, path)
    n, lines = 0, []
    for u, v, p in pairs:
        m, got = differences(u, v, p)
        n, lines = n + m, lines + got
    return n, lines


def _leaf(a: object, b: object, path: str) -> list[str]:
    """One line if the leaves ``a`` and ``b`` differ (NaN equals NaN), else none."""
    if isinstance(a, np.ndarray | float | complex | np.floating | np.complexfloating):
        x, y = np.asarray(a), np.asarray(b)
        if x.shape != y.shape:
            return [f"{path}: shape {x.shape} != {y.shape}"]
        if np.array_equal(x, y, equal_nan=x.dtype.kind in "fc"):
            return []
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = np.nanmax(np.abs(x - y) / np.maximum(np.abs(x), 1e-300))
        return [f"{path}: largest relative difference {rel:.3g}"]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump", help="pickle analyze_decay of hit_cost's ragged records")
    d.add_argument("file")
    d.add_argument("--hits", type=int, default=5, help="records a length (default 5)")
    d.add_argument("--seconds", type=float, nargs="+", default=[6.0, 14.0],
                   help="decay lengths, s (default 6 14)")
    c = sub.add_parser("compare", help="every differing number of two dumps")
    c.add_argument("a")
    c.add_argument("b")
    args = ap.parse_args()
    if args.cmd == "dump":
        dump(args.file, args.hits, args.seconds)
        return
    with open(args.a, "rb") as fa, open(args.b, "rb") as fb:
        n, lines = differences(pickle.load(fa), pickle.load(fb))
    print("\n".join(lines[:50]) + ("\n" if lines else "")
          + f"{n} leaves compared, {len(lines)} differ")
    sys.exit(1 if lines else 0)


if __name__ == "__main__":
    main()
