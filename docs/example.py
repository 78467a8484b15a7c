"""ramdaq from Python, end to end on the shipped sample recordings: read a trial, analyse it, hold
it against its rig's model, and draw the figures -- what a notebook does, as a script.

    python docs/example.py [OUT]          # figures and tables into OUT (default example_out/)

``tests/test_example.py`` runs it. Every step is one call of the API (``ramdaq.read_recording``,
``ramdaq.analyze``, ``ramdaq.diagnose``); the figures are matplotlib ``Figure`` objects, shown
inline by a notebook, saved here. It needs only ``pip install -e .`` (the README's first set-up):
the tables are the API's typed rows written with :mod:`csv`; with pandas (``pip install
'ramdaq[notebook]'``) ``rec.to_dataframe()``, ``res.to_dataframe()`` and ``gap.to_dataframe()``
give the same as DataFrames.
"""

from __future__ import annotations

import csv
import sys
from dataclasses import asdict
from pathlib import Path

import ramdaq  # before numpy: one BLAS thread, the command line's digits

# isort: split
import numpy as np

HERE = Path(__file__).resolve().parent
RECORDINGS = HERE.parent / "recordings"


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)

    # 1. the samples, in SI: channels x samples, with time, rate, gages, units and the blows found
    rec = ramdaq.read_recording(RECORDINGS / "albacore-water.mcap")
    print(f"{rec.path}: {rec.values.shape[0]} channels x {rec.n_samples} samples at {rec.fs_hz:g} Hz "
          f"({rec.duration_s:.1f} s), rig {rec.rig.name} in {rec.rig.medium}, "
          f"{len(rec.impacts)} blows at " + ", ".join(f"{ev.onset_s:.3f}" for ev in rec.impacts) + " s")
    g04 = rec.channels.index("g04")  # rec.values: channels x samples, NaN where missing
    print(f"gage 4 peak {np.nanmax(np.abs(rec.values[g04])):.3f} {rec.units[g04]}")

    # 2. the trial report's numbers: one row per hit x gage x mode (hits and modes from 0)
    res = ramdaq.analyze(rec)
    rows = res.rows()
    write_csv(out / "modes.csv", [asdict(r) for r in rows])
    pred = np.array([(r.f_hz, r.delta) for r in rows if r.predominant])
    modal = res.summary()["delta_modal"]  # the joint fit's, as ramdaq analyze prints it
    print(f"predominant mode over {len(res.analyses)} accepted hits: "
          f"f = {pred[:, 0].mean():.3f} Hz, delta_modal = {modal['mean']:.4f} (all gages "
          f"jointly); per-gage delta {pred[:, 1].mean():.4f} +- {pred[:, 1].std(ddof=1):.4f} "
          f"(plain mean and scatter over gages and hits)")
    for kind, fig in res.figures(0).items():
        fig.savefig(out / f"impact0_{kind}.png", dpi=150)

    # 3. the gap between the rig's model and a trial, and what explains it
    gap = ramdaq.diagnose(RECORDINGS / "sampson-water.mcap")
    write_csv(out / "gap_candidates.csv", [asdict(c) for c in gap.candidates()])
    print(f"gap diagnosis of sampson-water: {gap.verdict}"
          + (f", named effect: {gap.effect}" if gap.effect else ""))
    for kind, fig in gap.figures().items():
        fig.savefig(out / f"gap_{kind}.png", dpi=150)
    print(f"figures and tables in {out}/")


def write_csv(path: Path, rows: list[dict]) -> None:
    """``rows`` (dicts with the same keys) as a CSV file with a header."""
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("example_out"))
