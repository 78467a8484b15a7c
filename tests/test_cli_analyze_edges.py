"""``ramdaq analyze`` at a new user's edges (tester8's list): a motion averaged over fewer hits
than were accepted says which hits and why, and ``--mode-hz`` picks the mode the report's chain
runs on. On the shipped ALBACORE-in-water recording (3 blows)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ramdaq.daq.commands.analyze import motions_not_used
from ramdaq.daq.commands.cli import main

WATER = Path(__file__).resolve().parents[1] / "recordings" / "albacore-water.mcap"


@pytest.fixture(scope="module")
def water_run(tmp_path_factory):
    """`ramdaq analyze` of the 3 blows as a user runs it (no plots): its output and report."""
    out = tmp_path_factory.mktemp("an")
    import contextlib
    import io
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["analyze", str(WATER), "--no-plots", "--out", str(out)]) == 0
    return buf.getvalue(), json.loads((out / "report.json").read_text())


def test_a_motion_not_taken_from_every_hit_says_which_and_why(water_run):
    """tester8: delta_alpha_b came with n = 1 of 5 and no word why. In water the hull's roll
    at the stock does not stand out of the noise at the predominant mode in any hit: the
    summary says so, for which hits, with the verdicts of gages 13 and 14 it rests on."""
    text, rep = water_run
    assert rep["summary"]["delta_hull_motion"]["alpha_b"]["n"] == 0
    line = next(ln for ln in text.splitlines() if ln.startswith("  delta_alpha_b: n = "))
    assert line.startswith("  delta_alpha_b: n = 0 of 3 accepted hits; not from hits 0, 1, 2: ")
    assert "no decrement of the 13 Hz mode" in line and "(its gages' own decays: g13 ok, g14 ok)" in line
    # every motion the table averages over all 3 hits gets no such line
    full = [m for m, d in rep["summary"]["delta_motion"].items() if d["n"] == 3]
    assert full and not any(ln.startswith(f"  delta_{m}: n = ") for m in full for ln in text.splitlines())


def test_a_hit_without_a_note_is_said_to_have_none():
    """A motion missing from a hit that records no reason for it is not passed over: the line
    says the hit gives none (and a gage's verdict where the motion rests on it)."""
    imp = [{"index": 0, "accepted": True,
            "analysis": {"motions": {"gamma": {"delta": 0.1}}, "hull_motions": {}, "notes": [],
                         "verdicts": {"g04": {"verdict": "ok"}, "g08": {"verdict": "ok"}}}},
           {"index": 1, "accepted": True,
            "analysis": {"motions": {}, "hull_motions": {},
                         "notes": ["gamma: not computed, gage(s) [8] unusable"],
                         "verdicts": {"g04": {"verdict": "ok"}, "g08": {"verdict": "no_decay"}}}},
           {"index": 2, "accepted": True,
            "analysis": {"motions": {"gamma": {"delta": None}}, "hull_motions": {}, "notes": [],
                         "verdicts": {"g04": {"verdict": "ok"}, "g08": {"verdict": "ok"}}}}]
    s = {"delta_motion": {"gamma": {"n": 1}}, "delta_hull_motion": {}}
    (line,) = motions_not_used(imp, s)
    assert line.startswith("  delta_gamma: n = 1 of 3 accepted hits; not from ")
    assert "hit 1: not computed, gage(s) [8] unusable (its gages' own decays: g04 ok, g08 no_decay)" in line
    assert "hit 2: computed, but no decrement recorded and no note why" in line


def test_mode_hz_runs_the_chain_on_the_chosen_mode(tmp_path, capsys):
    """No option chose the predominant mode. --mode-hz 59.8 runs the chain on the 59.83 Hz mode
    (the most energetic on the rudder is 13.0 Hz), and each hit's note says so."""
    out = tmp_path / "an"
    assert main(["analyze", str(WATER), "--impact", "0", "--no-plots", "--out", str(out),
                 "--mode-hz", "59.8"]) == 0
    rep = json.loads((out / "report.json").read_text())
    a = rep["impacts"][0]["analysis"]
    assert abs(a["f_hz"] - 59.83) < 0.05           # the identified mode, not the number asked
    assert any("chosen by mode_hz 59.8" in n and "13.003 Hz" in n for n in a["notes"])
    text = capsys.readouterr().out
    assert "f = 59.834 Hz (asked: mode_hz 59.8)" in text
    # tester10: the chosen mode was labelled "(predominant)" and was report.json's
    # predominant_mode; the predominant one stays the 13 Hz mode, the chosen one is named so
    modes = [m["f_hz"] for m in a["modes"]]
    assert abs(modes[a["predominant_mode"]] - 13.003) < 0.01
    assert a["chosen_mode"] != a["predominant_mode"] and modes[a["chosen_mode"]] == a["f_hz"]
    assert a["mode_hz_asked"] == 59.8
    lines = [ln for ln in text.splitlines() if ln.startswith("    mode ")]
    assert sum(ln.startswith(f"    mode {a['predominant_mode']} (predominant), ") for ln in lines) == 1
    assert sum(ln.startswith(f"    mode {a['chosen_mode']} (asked: mode_hz 59.8), ") for ln in lines) == 1
    assert sum("(predominant" in ln for ln in lines) == 1


def test_mode_hz_near_no_mode_is_one_line(tmp_path, capsys):
    """30 Hz is no mode of this rudder: one line naming the resolution and the modes there are."""
    assert main(["analyze", str(WATER), "--impact", "0", "--no-plots", "--out", str(tmp_path / "a"),
                 "--mode-hz", "30"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("ramdaq analyze: --mode-hz 30: in no hit of ")
    assert "no identified mode within" in err and "13.003" in err


def test_mode_hz_a_few_percent_off_takes_the_mode_on_every_hit(tmp_path, capsys):
    """tester10: --mode-hz 13.15 (1.1 % above the 13.003 Hz mode) rejected the 8 s decays as
    "no usable decay" (0.15 Hz beyond their 0.125 Hz resolution) and took the 5 s one: a mode
    within 5 % of the frequency asked for is the one meant, on every hit alike."""
    out = tmp_path / "a"
    assert main(["analyze", str(WATER), "--no-plots", "--out", str(out), "--mode-hz", "13.15"]) == 0
    a = json.loads((out / "report.json").read_text())
    hits = a["impacts"]
    assert hits and all(h["accepted"] for h in hits), [h.get("reason") for h in hits]
    assert all(abs(h["analysis"]["f_hz"] - 13.003) < 0.01 for h in hits)


def test_a_record_with_no_blow_says_so(tmp_path, capsys):
    """A record from another system in which the trigger never fires (3 channels of noise
    alone, imported from CSV) says "no blow found" and why, not only "0 of 0 hits"."""
    import numpy as np

    t = np.arange(4096) / 2048
    x = 1e-3 * np.random.default_rng(0).standard_normal((3, t.size))
    csv = tmp_path / "quiet.csv"
    np.savetxt(csv, np.column_stack([t, *x]), delimiter=",", comments="",
               header="time_s,a [m/s^2],b [m/s^2],c [m/s^2]")
    assert main(["import", str(csv), "--out", str(tmp_path / "quiet.mcap")]) == 0
    capsys.readouterr()
    assert main(["analyze", str(tmp_path / "quiet.mcap"), "--no-plots"]) == 0
    out = capsys.readouterr().out
    assert "no blow found: the trigger never fired" in out
    assert "0 of 0 hits accepted" in out


def test_a_rig_that_does_not_describe_the_record_is_said_so(albacore, sampson):
    """ALBACORE's 13.0 Hz in water against SAMPSON's water modes (nearest 7.6 Hz: 1.71x, past
    the 1.29x that +-25 % in masses and stiffnesses allow) warns; against ALBACORE's own rig,
    or one 20 % stiffer (sqrt(1.2) = 1.10x), it does not."""
    from ramdaq.analysis.model.rig_modes import RIG_SPREAD_RATIO, rig_agreement

    assert RIG_SPREAD_RATIO == pytest.approx((1.25 / 0.75) ** 0.5, abs=0.02)
    wrong = rig_agreement(sampson.with_medium("water"), 13.0)
    assert not wrong.agrees and wrong.ratio == pytest.approx(13.0 / 7.598, rel=0.01)
    assert wrong.warning().startswith("the rig does not describe this record: its predominant "
                                      "mode, 13 Hz, is 1.71x")
    own = rig_agreement(albacore.with_medium("water"), 13.0)
    assert own.agrees and own.warning() is None
    assert rig_agreement(albacore.with_medium("water"), 13.0 * 1.2 ** 0.5).agrees


def test_the_report_carries_the_rigs_agreement(water_run):
    """The shipped ALBACORE-in-water recording against its own rig: agrees, no warning line."""
    text, rep = water_run
    a = rep["rig_agreement"]
    assert a["agrees"] and a["ratio"] < 1.001 and a["warning"] is None
    assert "WARNING the rig does not describe" not in text
