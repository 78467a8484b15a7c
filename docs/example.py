"""ramdaq from Python, end to end on the shipped sample recordings: read a trial, analyse it, hold
it against its rig's model, and draw the figures -- what a notebook does, as a script.

    python docs/example.py [OUT]          # figures and tables into OUT (default example_out/)

``tests/test_example.py`` runs it. Every step is one call of the API (``ramdaq.read_recording``,
``ramdaq.analyze``, ``ramdaq.diagnose``); the figures are matplotlib ``Figure`` objects, shown
inline by a notebook, saved here.
"""

from __future__ import annotations

import sys
from pathlib import Path

import ramdaq  # before numpy: one BLAS thread, the command line's digits

HERE = Path(__file__).resolve().parent
RECORDINGS = HERE.parent / "recordings"


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)

    # 1. the samples, in SI: channels x samples, with time, rate, gages, units and the blows found
    rec = ramdaq.read_recording(RECORDINGS / "albacore-water.mcap")
    print(f"{rec.path}: {rec.values.shape[0]} channels x {rec.n_samples} samples at {rec.fs_hz:g} Hz "
          f"({rec.duration_s:.1f} s), rig {rec.rig.name} in {rec.rig.medium}, "
          f"{len(rec.impacts)} blows at " + ", ".join(f"{ev.onset_s:.3f}" for ev in rec.impacts) + " s")
    df = rec.to_dataframe()  # pandas: index time_s, a column per channel
    print(f"gage 4 peak {df['g04'].abs().max():.3f} {df.attrs['units']['g04']}")

    # 2. the trial report's numbers: one row per hit x gage x mode
    res = ramdaq.analyze(rec)
    table = res.to_dataframe()
    table.to_csv(out / "modes.csv", index=False)
    pred = table[table.predominant]
    print(f"predominant mode over {len(res.analyses)} accepted hits: "
          f"f = {pred.f_hz.mean():.3f} Hz, delta = {pred.delta.mean():.4f} "
          f"(+- {pred.delta.std():.4f} over gages and hits)")
    for kind, fig in res.figures(0).items():
        fig.savefig(out / f"impact0_{kind}.png", dpi=150)

    # 3. the gap between the rig's model and a trial, and what explains it
    gap = ramdaq.diagnose(RECORDINGS / "sampson-water.mcap")
    gap.to_dataframe().to_csv(out / "gap_candidates.csv", index=False)
    print(f"gap diagnosis of sampson-water: {gap.verdict}"
          + (f", named effect: {gap.effect}" if gap.effect else ""))
    for kind, fig in gap.figures().items():
        fig.savefig(out / f"gap_{kind}.png", dpi=150)
    print(f"figures and tables in {out}/")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("example_out"))
