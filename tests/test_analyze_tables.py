"""What a new user misread in the analysis' tables: the per-mode rows of ``ramdaq batch
analyze``'s table (each row's ``reason`` says which mode the gage's verdict was judged on; an
11 Hz reason on a 37 Hz row was read as the 37 Hz mode's), and a summary that averaged a hit
cut short by the stream's end with no mark."""

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


def test_a_hit_cut_by_the_streams_end_is_marked_in_the_summary(tmp_path):
    """A trial ended by a vanished port 0.9 s after a blow: the hit was accepted and averaged
    into the summary with nothing in its table marking it short. The summary says which hit
    rests on a short decay and what cut it; a hit cut by the next blow is the trial's design and
    is not marked."""
    from ramdaq.daq.analyzer import trial_summary
    from ramdaq.daq.commands.analyze import summary_table
    from ramdaq.daq.record import record
    from ramdaq.drivers.sim import SimDevice

    path = tmp_path / "cut.mcap"
    rig = SAMPLE.parent / "rigs" / "albacore.toml"
    with SimDevice(rig, duration_s=5.0, impacts=[2.5, 3.6], seed=3, pace="fast") as dev:
        record(dev, path, readout=False)
    _, hits = run_analysis(path)
    assert [h.accepted for h in hits] == [True, True], [h.reason for h in hits]
    s = trial_summary(hits)
    # hit 0 is cut by hit 1 (not marked); hit 1 by the end of the 5 s record, 1.4 s after it
    assert list(s["cut_short"]) == [1] and s["cut_short"][1].endswith("cut by the stream's end")
    assert s["cut_short"][1].startswith("1.4 s after the blow")
    lines = summary_table(s)
    assert f"  hit 1 is in these means on a short decay: its record ended {s['cut_short'][1]}" \
        in lines


def test_a_summary_row_whose_hits_sit_at_the_noise_is_marked_unsure(tmp_path):
    """ALBACORE in air: the hull's own rotation at the rudder (alpha_b, gages 5, 13, 14) barely
    moves, so each hit's decrement of it has an error of a third of itself, while the rudder's
    motions have errors of ~0.01 %. The summary's mean over hits of such a row is marked, with
    the hits' own errors, exactly where the median of those errors is above the live readout's
    "unsure" limit; the rudder's rows are not."""
    from ramdaq.daq.analyzer import UNSURE_REL_SE, trial_summary
    from ramdaq.daq.commands.analyze import summary_table
    from ramdaq.daq.record import record
    from ramdaq.drivers.sim import SimDevice

    path = tmp_path / "air.mcap"
    rig = SAMPLE.parent / "rigs" / "albacore.toml"
    with SimDevice(rig, duration_s=30.0, impacts=[5.0, 15.0, 25.0], seed=0, pace="fast") as dev:
        record(dev, path, readout=False)
    _, hits = run_analysis(path)
    ok = [h.analysis for h in hits if h.accepted]
    assert len(ok) == 3
    lines = summary_table(trial_summary(hits))
    for name in ok[0].hull_motions:  # the hits' own errors, straight from each hit
        rel = [a.hull_motions[name].delta_se / abs(a.hull_motions[name].delta) for a in ok]
        at = next(i for i, ln in enumerate(lines) if ln.startswith(f"  delta_{name} "))
        marked = lines[at + 1].lstrip().startswith("^ unsure:")
        assert marked == (float(np.median(rel)) > UNSURE_REL_SE), (name, rel, lines[at:at + 2])
    assert any(ln.lstrip().startswith("^ unsure:") for ln in lines)  # alpha_b, in this trial
    at = next(i for i, ln in enumerate(lines) if ln.startswith("  delta_alpha "))
    assert "unsure" not in lines[at + 1]
