"""Rig files: the shipped rigs load, wrong rigs are refused with a line naming the field."""

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


def test_missing_gage_refused():
    text = (RIGS / "albacore.toml").read_text()
    bad = text.replace(_gage_block(text, 16), "")
    with pytest.raises(RigError, match=r"bad\.toml: gages: missing gage\(s\) 16"):
        parse_rig(bad, "bad.toml")


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
