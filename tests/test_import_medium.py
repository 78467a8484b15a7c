"""The medium a UFF or TDMS file states is imported (tester9/10: only CSV carried it, through
its header): a UFF 151 header's ``medium: water``, ramdaq's own UFF export's ID line 2, a TDMS
``medium`` property. Where the file states none, ``--medium`` or the rig decides and the import
says which in one line. On 1 s of four gages of the shipped ALBACORE-in-water recording."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import pyuff
from nptdms import ChannelObject, RootObject, TdmsWriter

from ramdaq.daq.commands.cli import main
from ramdaq.drivers.files.import_common import ImportFormatError
from ramdaq.drivers.files.import_tdms import read_tdms_table
from ramdaq.drivers.mcap_replay import McapReplayDevice
from ramdaq.drivers.registry import open_device

ROOT = Path(__file__).resolve().parents[1]
WATER = ROOT / "recordings" / "albacore-water.mcap"
RIG = ROOT / "recordings" / "rigs" / "albacore.toml"   # medium = "air"
GAGES = (1, 2, 3, 4)


@pytest.fixture(scope="module")
def water():
    """The first second of gages 1-4 (m/s^2, (4, n)) and the rate."""
    with open_device(str(WATER)) as dev:
        fs, rows = dev.info.fs_hz, [dev.info.gages.index(g) for g in GAGES]
        parts, n = [], 0
        for b in dev:
            parts.append(b.counts[rows] * b.scale[rows, None])
            n += b.n_samples
            if n >= fs:
                break
    return np.concatenate(parts, axis=1)[:, :int(fs)], fs


def _uff(path: Path, x: np.ndarray, fs: float, *, header: str | None = None, id2: str = "") -> Path:
    sets = [] if header is None else [dict(
        type=151, model_name="rudder trial", description=header, db_app="logger",
        date_db_created="27-Nov-26", time_db_created="12:00:00", version_db1=1, version_db2=0,
        file_type=0, date_db_saved="27-Nov-26", time_db_saved="12:00:00", program="logger",
        date_db_written="27-Nov-26", time_db_written="12:00:00")]
    sets += [dict(type=58, binary=0, func_type=1, rsp_node=g, rsp_dir=2, ref_node=0, ref_dir=0,
                  abscissa_spacing=1, x=np.arange(x.shape[1]) / fs, data=np.ascontiguousarray(row),
                  id1=f"g{g:02d}", id2=id2 or "NONE", ordinate_spec_data_type=12,
                  abscissa_spec_data_type=17, orddenom_spec_data_type=0,
                  ordinate_axis_units_lab="m/s^2", abscissa_axis_units_lab="s")
             for g, row in zip(GAGES, x, strict=True)]
    pyuff.UFF(str(path)).write_sets(sets, mode="add")
    return path


def _tdms(path: Path, x: np.ndarray, fs: float, *, medium: str | None = None) -> Path:
    with TdmsWriter(str(path)) as w:
        root = [RootObject(properties={"Medium": medium})] if medium else []
        w.write_segment(root + [ChannelObject("accelerations", f"g{g:02d}", row,
                                              properties={"wf_increment": 1 / fs, "wf_start_offset": 0.0,
                                                          "unit_string": "m/s^2"})
                                for g, row in zip(GAGES, x, strict=True)])
    return path


def _import(src: Path, capsys, *extra: str) -> tuple[str, str]:
    """``ramdaq import SRC --rig albacore.toml``: its standard output and the recording's medium."""
    out = src.with_suffix(".mcap")
    assert main(["import", str(src), "--rig", str(RIG), "--out", str(out), *extra]) == 0
    with McapReplayDevice(out) as dev:
        medium = dev.info.extra["medium"]
    return capsys.readouterr().out, medium


def test_a_uff_header_stating_water_is_applied_and_said(water, tmp_path, capsys):
    x, fs = water
    src = _uff(tmp_path / "a.uff", x, fs, header="ALBACORE rudder impacts, medium: water")
    text, medium = _import(src, capsys)
    assert medium == "water"      # the rig file says air: the file's statement wins
    assert "medium water, as UFF record 1 (type 151) description states (the rig says air; " \
           "--medium overrides)" in text


def test_ramdaqs_own_uff_export_states_its_medium(water, tmp_path, capsys):
    """export_uff writes 'ramdaq rig NAME in water' on each record's ID line 2: read back."""
    x, fs = water
    src = _uff(tmp_path / "own.uff", x, fs, id2="ramdaq rig albacore-like in water")
    text, medium = _import(src, capsys)
    assert medium == "water" and "as UFF record 1 (type 58) ID line 2 states" in text


def test_a_tdms_medium_property_is_applied_and_said(water, tmp_path, capsys):
    x, fs = water
    src = _tdms(tmp_path / "c.tdms", x, fs, medium="Water")
    text, medium = _import(src, capsys)
    assert medium == "water"
    assert "medium water, as the file's property 'Medium' states (the rig says air" in text


def test_a_file_stating_none_says_who_decided(water, tmp_path, capsys):
    """No medium in the file: the rig's, or --medium's, named in one line (it was silent)."""
    x, fs = water
    src = _tdms(tmp_path / "none.tdms", x, fs)
    text, medium = _import(src, capsys)
    assert medium == "air"
    lines = [ln for ln in text.splitlines() if ln.startswith("medium ")]
    assert lines == ["medium air, the rig's: the file states none (--medium overrides)"]
    text, medium = _import(_uff(tmp_path / "none_uff.uff", x, fs), capsys, "--medium", "water")
    assert medium == "water"
    assert [ln for ln in text.splitlines() if ln.startswith("medium ")] == \
        ["medium water as --medium gives (the file states none)"]


def test_a_medium_that_is_neither_or_two_that_disagree_is_one_line(water, tmp_path):
    x, fs = water
    with pytest.raises(ImportFormatError, match=r"property 'Medium' states medium 'brine': "
                                                r"expected air or water"):
        read_tdms_table(_tdms(tmp_path / "brine.tdms", x, fs, medium="brine"))
    src = _uff(tmp_path / "two.uff", x, fs, header="medium: air",
               id2="ramdaq rig albacore-like in water")
    with pytest.raises(ImportFormatError, match=r"type 151\) description states medium air but "
                                                r"UFF record \d \(type 58\) ID line 2 states water"):
        with open_device(str(src), rig=RIG) as dev:
            dev.info  # noqa: B018 - reading the file
