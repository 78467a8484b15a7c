"""``ramdaq analyze`` on a shipped sample recording, as a user runs it."""

import json

import pytest

from ramdaq.daq.commands.analyze import format_summary
from ramdaq.daq.commands.cli import main
from tests.conftest import RIGS

SAMPLES = RIGS.parent


@pytest.fixture(scope="module")
def air_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("an")
    assert main(["analyze", str(SAMPLES / "albacore-air.mcap"), "--impact", "1", "--out",
                 str(out), "--units", "report", "--plots", "all"]) == 0
    return out, json.loads((out / "report.json").read_text())


def test_report_json_and_plots(air_report):
    out, rep = air_report
    assert [i["index"] for i in rep["impacts"]] == [0, 1, 2]  # the trigger found the 3 blows
    # the simulator hit at 2, 8, 14 s; the trigger places onsets to within one sample
    assert [round(i["onset_s"], 2) for i in rep["impacts"]] == [2.0, 8.0, 14.0]
    hit = rep["impacts"][1]
    assert hit["accepted"] and rep["impacts"][0]["reason"] == "not requested"
    a = hit["analysis"]
    # the ALBACORE-like rig's predominant mode in air: 24.5 Hz (Table 2a) within the rig's 2 %
    assert abs(a["f_hz"] / 24.5 - 1) < 0.02
    assert set(a["motions"]) == {"gamma", "alpha", "v_2_6", "v_4_8"}
    assert a["gages"]["g04"]["delta_se"] > 0
    for name in ("decay", "spectrum", "modeshape", "stock"):
        assert (out / f"impact1_{name}.png").stat().st_size > 10_000


def test_units_report_in_terminal(air_report, capsys, tmp_path):
    assert main(["analyze", str(SAMPLES / "albacore-air.mcap"), "--impact", "0", "--out",
                 str(tmp_path), "--units", "report", "--no-plots"]) == 0
    text = capsys.readouterr().out
    assert "ton s/ft" in text and "ft ton s^2" in text
    assert not list(tmp_path.glob("*.png"))


def test_not_a_recording_is_one_line(tmp_path, capsys):
    bad = tmp_path / "x.mcap"
    bad.write_bytes(b"not an mcap file at all")
    assert main(["analyze", str(bad)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "x.mcap" in err[0]


def test_plot_kinds_default_all_named_and_unknown():
    """``ramdaq analyze`` draws the decay panels unless asked (``--plots``); every kind stays
    available, and a misspelt kind is refused before any analysis, naming the known ones."""
    from ramdaq.daq.commands.analyze import DEFAULT_PLOTS, plot_kinds
    from ramdaq.daq.reports.impact_plots import PLOT_KINDS

    assert plot_kinds(None) is True and DEFAULT_PLOTS == ("decay",)
    assert plot_kinds("all") == PLOT_KINDS
    assert plot_kinds("spectrum, stock") == ("spectrum", "stock")
    assert plot_kinds("all", off=True) is False
    with pytest.raises(ValueError, match="known: decay, spectrum, modeshape, stock"):
        plot_kinds("decay,spectra")


def test_a_second_run_leaves_no_plots_of_the_first(air_report, tmp_path, capsys):
    """The report folder holds one run: ``--no-plots`` into a folder of an earlier run with
    plots removes them (they would sit beside a report.json they do not belong to)."""
    out, _ = air_report
    again = tmp_path / "again"
    again.mkdir()
    for p in out.glob("*.png"):
        (again / p.name).write_bytes(p.read_bytes())
    (again / "notes.png").write_bytes(b"the user's own")  # not a name analyze writes: kept
    assert main(["analyze", str(SAMPLES / "albacore-air.mcap"), "--impact", "0", "--out",
                 str(again), "--no-plots"]) == 0
    assert sorted(p.name for p in again.glob("*.png")) == ["notes.png"]


def test_air_twin_must_be_the_same_rig_in_air(tmp_path, capsys):
    """Eq 18 compares one surface in air and in water: another rig's trial, or a water trial
    given as --air, is a one-line refusal (it printed a virtual mass of -2790 kg, rc 0)."""
    from ramdaq.analysis.model.rig import load_rig
    from ramdaq.daq.commands.analyze import check_air_twin

    water = load_rig(RIGS / "albacore.toml").with_medium("water")
    check_air_twin(water, water.with_medium("air"), "a.mcap")  # the twin: no complaint
    with pytest.raises(ValueError, match="its rig is 'sampson-like', not the water trial's 'albacore-like'"):
        check_air_twin(water, load_rig(RIGS / "sampson.toml").with_medium("air"), "s.mcap")
    with pytest.raises(ValueError, match="that trial is in water, not air"):
        check_air_twin(water, water, "w.mcap")
    assert main(["analyze", str(SAMPLES / "albacore-water.mcap"), "--impact", "0", "--air",
                 str(SAMPLES / "sampson-water.mcap"), "--out", str(tmp_path), "--no-plots"]) == 1
    out, err = capsys.readouterr()
    err = err.strip().splitlines()
    assert len(err) == 1 and "sampson-water.mcap" in err[0] and "not air" in err[0]
    assert "impact 0" not in out  # refused from the files' rigs, before either is analysed


def test_a_damping_constant_of_no_sign_is_said_and_the_table_says_what_c_is(air_report, capsys):
    """Eq 14/15 can come out negative (on the simulator's air trial too): each such hit's notes
    say it is not a damping constant, a positive one draws no note; the table labels c per
    radian and says what Eq 16/17 read (the whole decay on one dashpot)."""
    out, rep = air_report
    text = format_summary(rep)
    assert "c (N m s/rad)" in text and "each putting the predominant mode's whole decay" in text
    a = rep["impacts"][1]["analysis"]
    for key, eq in (("C_eq14_N_s_per_m", "Eq 14"), ("c_eq15_N_m_s_per_rad", "Eq 15")):
        value = a["damping"][key]
        said = any(n.startswith(f"{eq}:") and "not a damping constant" in n for n in a["notes"])
        assert said == (value <= 0), (key, value, a["notes"])


def test_a_gage_no_hit_took_is_said_with_its_reason(air_report):
    """The summary listed g01..g14 and dropped the vertical hull gages 15 and 16 without a word
    (a new user asked where they went). A horizontal blow gives them no free decay: the summary
    names each with the analysis's verdict on it; every other gage has its decrement row."""
    out, rep = air_report
    s = rep["summary"]
    assert sorted(s["gages_not_used"]) == ["g15", "g16"]
    assert all(why.startswith("no_decay: ") for why in s["gages_not_used"].values())
    assert set(s["delta_gage"]) | set(s["gages_not_used"]) == {f"g{g:02d}" for g in range(1, 17)}
    text = format_summary(rep)
    assert "  g15 not used in any accepted hit: no_decay: " in text


def test_hits_not_requested_are_not_analysed_nor_counted(air_report):
    """tester9: ``--impact 1`` printed the other hits as "REJECTED not requested" and "1 of 3
    hits accepted": they were never judged. They read "not analysed (not requested)" and the
    count is of the requested hits."""
    from ramdaq.daq.commands.analyze import format_summary

    _, rep = air_report
    text = format_summary(rep)
    assert "REJECTED" not in text
    assert text.count("not analysed (not requested)") == 2
    assert "1 of 1 requested hits accepted (2 more not analysed)" in text


def test_an_unknown_plot_kind_is_a_usage_error(capsys):
    """`--plots bogus` exited 1 after reading the recording; the README's usage errors exit 2,
    before any work, naming the known kinds."""
    from pathlib import Path

    rec = Path(__file__).resolve().parents[1] / "recordings" / "albacore-air.mcap"
    with pytest.raises(SystemExit) as ex:
        main(["analyze", str(rec), "--plots", "decay,bogus"])
    assert ex.value.code == 2
    err = capsys.readouterr().err
    assert "argument --plots: unknown kind(s) ['bogus']; known: decay, spectrum" in err
