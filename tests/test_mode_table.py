"""The per-mode rows of ``ramdaq batch analyze``'s table: each row's ``reason`` says which mode
the gage's verdict was judged on (a new user read an 11 Hz reason on a 37 Hz row as the 37 Hz
mode's)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ramdaq.daq.commands.analyze import run_analysis
from ramdaq.daq.mode_table import mode_rows

SAMPLE = Path(__file__).resolve().parents[1] / "recordings" / "albacore-water.mcap"


def test_each_mode_row_says_which_mode_the_gage_verdict_judged():
    _, hits = run_analysis(SAMPLE)
    rows = [r for r in mode_rows(hits[0]) if r.fitted]
    assert len({r.mode for r in rows}) >= 2  # the sample's hit fits several modes
    for gage in {r.gage for r in rows}:
        mine = [r for r in rows if r.gage == gage]
        v = hits[0].analysis.verdicts[gage]
        judged = min(mine, key=lambda r: abs(r.mode_f_hz - v.f_hz))
        assert judged.reason == v.reason  # the judged mode's row: the verdict's own words
        others = [r for r in mine if r is not judged]
        assert others and all(r.reason == f"the gage's verdict, judged at {v.f_hz:.4g} Hz: "
                                           f"{v.reason}" for r in others)
        assert np.isfinite(v.f_hz)
