"""Rig files: the shipped rigs load, wrong rigs are refused with a line naming the field."""

import math
import re

import pytest

from ramdaq.analysis.model.rig import RigError, load_rig, parse_rig
from tests.conftest import RIGS


def test_shipped_rigs_load():
    for path in sorted(RIGS.glob("*.toml")):
        rig = load_rig(path)
        assert len(rig.gages) == 16
        assert [g.channel for g in rig.gages_by_channel()] == list(range(16))


def _edit(text: str, old: str, new: str) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


def _gage_block(text: str, number: int) -> str:
    pattern = r"\[\[gages\]\]\nnumber = " + str(number) + r"\n.*?(?=\n\[\[gages\]\]|\Z)"
    m = re.search(pattern, text, re.S)
    assert m
    return m.group(0)


def test_a_layout_short_of_16_gages_is_read_and_says_what_it_cannot_compute():
    """A field system of 8 channels (gages 1-8 under their report numbers): the rig is read,
    its geometry has NaN where a left-out gage gives a distance, and the steps of the report's
    chain that need gages 9-16 are named with the gages they lack; two gages are refused."""
    from ramdaq.analysis.impact import CHAIN_STEPS, skipped_steps
    from ramdaq.analysis.model.geometry import gage_geometry

    text = (RIGS / "albacore.toml").read_text()
    for n in range(9, 17):
        text = text.replace(_gage_block(text, n), "")
    rig = parse_rig(text, "eight.toml")
    assert [g.number for g in rig.gages] == list(range(1, 9))
    geom = gage_geometry(rig)
    assert math.isnan(geom.L_H) and math.isnan(geom.x7) and geom.x1 > 0 and geom.z1 > 0
    skipped = {s.step: s.reason for s in skipped_steps(rig, tuple(range(1, 9)))}
    assert set(skipped) == {step for step, need in CHAIN_STEPS.items() if max(need) > 8}
    assert all(r.endswith(f"which rig {rig.name!r} does not have") for r in skipped.values())
    two = text
    for n in range(3, 9):
        two = two.replace(_gage_block(two, n), "")
    with pytest.raises(RigError, match=r"two\.toml: gages: 2 gage\(s\); a structure needs 3 or more"):
        parse_rig(two, "two.toml")


def test_duplicate_gage_refused():
    text = (RIGS / "albacore.toml").read_text()
    bad = _edit(text, "number = 16\n", "number = 15\n")
    with pytest.raises(RigError, match=r"gages\[15\]\.number: duplicate gage 15"):
        parse_rig(bad, "bad.toml")


def test_unknown_axis_refused():
    text = (RIGS / "albacore.toml").read_text()
    block = _gage_block(text, 4)
    bad = text.replace(block, block.replace('axis = "y"', 'axis = "w"'))
    with pytest.raises(RigError, match=r"gages\[3\]\.axis: unknown axis 'w'"):
        parse_rig(bad, "bad.toml")


def test_negative_mass_refused():
    text = (RIGS / "albacore.toml").read_text()
    bad = _edit(text, "mass_kg = 2870.2", "mass_kg = -2870.2")
    with pytest.raises(RigError, match=r"rudder\.mass_kg: must be positive, got -2870\.2"):
        parse_rig(bad, "bad.toml")


def test_gages_2_and_6_off_common_vertical_refused():
    text = (RIGS / "albacore.toml").read_text()
    bad = _edit(text, "[0.0, 0.0, -1.00]", "[0.05, 0.0, -1.00]")
    with pytest.raises(RigError, match=r"gages 2 and 6 are not on a common vertical"):
        parse_rig(bad, "bad.toml")


@pytest.mark.parametrize(("old", "new", "field"), [
    ('medium = "air"', 'medium = "oil"', "medium"),
    ("adc_bits = 24", "adc_bits = 40", "daq.adc_bits"),
    ("anti_alias_hz = 800.0", "anti_alias_hz = 1500.0", "daq.anti_alias_hz"),
    ("Ixz_kg_m2 = -512.3", "Ixz_kg_m2 = -5000.0", "rudder.Ixz_kg_m2"),
    ('units = "SI"', 'units = "report"', "units"),
    ("channel = 15", "channel = 0", r"gages\[15\]\.channel"),
    ("[-0.17, 0.0, 1.85]", "[-0.17, 0.0, 9.85]", r"gages\[6\]\.position_m"),
])
def test_wrong_fields_named(old, new, field):
    bad = _edit((RIGS / "albacore.toml").read_text(), old, new)
    with pytest.raises(RigError, match=rf"^bad\.toml: {field}: "):
        parse_rig(bad, "bad.toml")


def test_error_is_one_line_and_names_file(tmp_path):
    p = tmp_path / "rig.toml"
    p.write_text("name = 'x'\nmedium = 'air'\n")
    with pytest.raises(RigError) as err:
        load_rig(p)
    assert "\n" not in str(err.value) and str(p) in str(err.value)
    with pytest.raises(RigError, match="cannot read rig file"):
        load_rig(tmp_path / "absent.toml")
    p.write_text("name = [")
    with pytest.raises(RigError, match="not valid TOML"):
        load_rig(p)


@pytest.mark.parametrize(("old", "new", "field", "hint"), [
    ("added_mass_factor = 1.0", "added_mass_factr = 1.0", r"rudder\.added_mass_factr",
     "did you mean 'added_mass_factor'"),
    ("[damping.water]", "[damping.watr]", r"damping\.watr", "did you mean 'water'"),
    ('medium = "air"', 'medium = "air"\nmedum = "water"', "medum", "did you mean 'medium'"),
    ("frequency_hz = 8.0", "frequency_hz = 8.0\nfreq = 8.0", r"hull\.modes\.freq",
     "valid keys here: .*frequency_hz"),
    ("axis = \"y\"", "axis = \"y\"\naxsi = \"y\"", r"gages\.axsi", "did you mean 'axis'"),
    ("[impact]", "[impacts]", r"impact\.peak_force_N", "missing \\(the file has .impacts.: misspelt\\?\\)"),
])
def test_unknown_keys_named_with_the_nearest_valid_one(old, new, field, hint):
    """A misspelt key at any level is an error naming the file, the key and the nearest valid
    key, not a silent default (issue 18: added_mass_factr, [damping.watr])."""
    bad = _edit((RIGS / "albacore.toml").read_text(), old, new)
    with pytest.raises(RigError, match=rf"^bad\.toml: {field}: (unknown key )?.*{hint}") as err:
        parse_rig(bad, "bad.toml")
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(("old", "new", "field"), [
    ("mass_kg = 2870.2", "mass_kg = 2.87e30", r"rudder\.mass_kg"),
    ("mass_kg = 2870.2", "mass_kg = 0.0", r"rudder\.mass_kg"),
    ("sample_rate_hz = 2048.0", "sample_rate_hz = 20.0", r"daq\.sample_rate_hz"),
    ("sample_rate_hz = 2048.0", "sample_rate_hz = 102400.0", r"daq\.sample_rate_hz"),
    ("E_Pa = 2.07e11", "E_Pa = 2.07e16", r"stock\.E_Pa"),
    ("I_m4 = 2.235e-3", "I_m4 = 2.235e3", r"stock\.I_m4"),
    ("frequency_hz = 8.0", "frequency_hz = 8.0e6", r"hull\.modes\[0\]\.frequency_hz"),
    ("frequency_hz = 8.0", "frequency_hz = 0.0", r"hull\.modes\[0\]\.frequency_hz"),
    ("density_kg_m3 = 1027.6", "density_kg_m3 = 1.0276", r"water\.density_kg_m3"),
    ("[-0.70, 0.0, 1.55]", "[-700.0, 0.0, 1550.0]", r"gages\[0\]\.position_m"),
])
def test_implausible_values_named(old, new, field):
    """Numbers outside physical ranges (a unit or an exponent gone wrong) are one-line errors
    naming the key; the shipped rigs lie well inside every range."""
    bad = _edit((RIGS / "albacore.toml").read_text(), old, new)
    with pytest.raises(RigError, match=rf"^bad\.toml: {field}: .*(implausible|positive)") as err:
        parse_rig(bad, "bad.toml")
    assert "\n" not in str(err.value)


def test_ramdaq_rig_warns_of_modes_no_trial_can_record(tmp_path, capsys):
    """A new user pasted the report's rudder mass (0.0878 ton s^2/ft) as mass_kg: ``ramdaq rig``
    listed a 27 864 Hz mode at 2048 Hz samples without a word. A mode above half the sample rate
    is named in a warning; the shipped rig raises none."""
    from ramdaq.daq.commands.cli import main

    text = (RIGS / "albacore.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(re.sub(r"(?m)^mass_kg = .*$", "mass_kg = 0.0878", text, count=1))
    assert main(["rig", str(bad)]) == 0
    out = capsys.readouterr().out
    assert "warning: mode(s) at 27864 Hz lie above half the sample rate (1024 Hz)" in out
    assert main(["rig", str(RIGS / "albacore.toml")]) == 0
    assert "warning" not in capsys.readouterr().out


def test_ramdaq_rig_prints_zeta_in_percent_as_analyze_does(capsys):
    """``rig`` printed the damping ratio as a fraction where ``analyze`` prints a percentage (a
    new user read 0.0163 as 0.0163 %). Each row's zeta (%) is 100 x delta / 2 pi: for light
    damping delta = 2 pi zeta / sqrt(1 - zeta^2), 1.3e-4 off at zeta 1.6 %; the printed digits
    (delta to 1e-4, zeta to 1e-3 %) bound the rows with delta >= 0.05 to 0.2 % relative."""
    from ramdaq.daq.commands.cli import main

    assert main(["rig", str(RIGS / "albacore.toml")]) == 0
    out = capsys.readouterr().out
    assert out.count("   f (Hz)    delta   zeta (%)") == 2
    rows = [r.lstrip("* ").split() for r in out.splitlines() if re.match(r"^[* ] +\d+\.\d{3} ", r)]
    strong = [(float(d), float(z)) for _, d, z in rows if float(d) >= 0.05]
    assert len(strong) >= 4  # two modes in air, two in water
    for d, z in strong:
        assert z == pytest.approx(100 * d / (2 * 3.141592653589793), rel=2e-3)


def test_ramdaq_rig_units_report_gives_eq18_in_ton_s2_per_ft(capsys):
    """``rig --units report`` states Eq 18's masses in the report's ton s^2/ft (SI inside, the
    report's units at the edge on request); each is the SI line's kg over 1 ton s^2/ft =
    9964.016 N / 0.3048 m = 32 690.3 kg, to the printed digits (kg to 1, ton s^2/ft to 1e-4).
    The rudder's mass in air is Report 1836 Table 2's 0.0878 ton s^2/ft."""
    from ramdaq.daq.commands.cli import main

    unit = r"(kg|ton s\^2/ft)"
    pattern = (rf"Eq 18: m_vir = m_a\[\(f_air/f_water\)\^2 - 1\] = ([\d.]+) {unit} x "
               rf"\[\([\d.]+/[\d.]+\)\^2 - 1\] = ([\d.]+) {unit}")
    assert main(["rig", str(RIGS / "albacore.toml")]) == 0
    si = re.search(pattern, capsys.readouterr().out).groups()
    assert main(["rig", str(RIGS / "albacore.toml"), "--units", "report"]) == 0
    rep = re.search(pattern, capsys.readouterr().out).groups()
    assert (si[1], si[3], rep[1], rep[3]) == ("kg", "kg", "ton s^2/ft", "ton s^2/ft")
    per_unit = 2240 * 4.4482216152605 / 0.3048
    for kg, ton in ((si[0], rep[0]), (si[2], rep[2])):
        assert float(ton) == pytest.approx(float(kg) / per_unit, abs=0.5 / per_unit + 0.5e-4)
    assert float(rep[0]) == pytest.approx(0.0878, abs=0.5e-4)


def test_a_rig_without_gage_5_is_analysed_and_says_why_the_torsion_length_is_not(tmp_path):
    """A new user's 12-gage rig had no gage 5 (the hull gage forward of the stock): ``analyze``
    rejected every hit with ``KeyError: 5`` (the stock lengths read gage 5's position before
    asking whether it was recorded). Every hit is now accepted, the bending length is read off
    Figure 8 as before, and the torsion length (Figure 9, which needs the hull's yaw from gages 5
    and 13) is said to be not computed, with the reason."""
    import json

    from ramdaq.daq.commands.cli import main
    from ramdaq.daq.record import record
    from ramdaq.drivers.sim import SimDevice

    text = (RIGS / "albacore.toml").read_text()
    text = text.replace(_gage_block(text, 5), "")
    # its channel (4) left out: the channels after it move down one, as a 15-channel system has them
    text = re.sub(r"(?m)^channel = (\d+)$",
                  lambda m: f"channel = {int(m[1]) - (int(m[1]) > 4)}", text)
    rig = parse_rig(text, "no5.toml")
    assert 5 not in {g.number for g in rig.gages}
    trial = tmp_path / "no5.mcap"
    record(SimDevice(rig, duration_s=9.0, impacts=[2.0, 5.5], seed=3), trial, readout=False)
    assert main(["analyze", str(trial), "--out", str(tmp_path / "out"), "--no-plots"]) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert [h["accepted"] for h in report["impacts"]] == [True, True]
    assert report["summary"]["rejected"] == {}
    notes = json.dumps([h["analysis"] for h in report["impacts"]])
    assert "stock torsion length: needs gamma_b from level hull gages 5 and 13" in notes
    assert "bending_m" in notes
