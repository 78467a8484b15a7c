"""Nothing silent on import (issue 18): a CSV's rate against the rig's, the time column's unit
from its header, a missing value named by line and column; then force channels and the
channels-only rig that ``ramdaq import --fs --units`` makes for a record without a rig."""

from __future__ import annotations

import re

import numpy as np
import pytest

from ramdaq.daq.commands.cli import main
from ramdaq.drivers.files.import_common import ImportFormatError
from ramdaq.drivers.registry import open_device
from ramdaq.drivers.sim import SimDevice
from tests.conftest import RIGS
from tests.test_imports import write_csv

RIG = RIGS / "albacore.toml"
FS = 2048.0


@pytest.fixture(scope="module")
def decay():
    """5 s of the ALBACORE-like rig in air, a blow at 2.5 s: values (16, n) m/s^2, gages."""
    with SimDevice(RIG, duration_s=5.0, impacts=[2.5], seed=1) as dev:
        blocks = list(dev)
        gages = list(dev.info.gages)
    counts = np.concatenate([b.counts for b in blocks], axis=1)
    return counts * blocks[0].scale[:, None], gages


def _csv(path, t, x, header_time: str, names=("g01", "g02")):
    """A CSV whose time column is headed ``header_time`` (with its unit, or none)."""
    p = write_csv(path, t, x, list(names))
    lines = p.read_text().split("\n")
    lines[0] = ",".join([header_time, *(f"{n} [m/s^2]" for n in names)])
    p.write_text("\n".join(lines))
    return p


def _read(path, **options):
    with open_device(str(path), rig=RIG, **options) as dev:
        return dev.info, list(dev)


def test_rate_that_disagrees_with_the_rig_is_refused_unless_stated(decay, tmp_path):
    """A 2048 Hz record whose time column says 1000 Hz used to import silently (and report
    11.97 Hz for the 24.5 Hz mode); now the rates are named, and --fs states the file's."""
    x, _ = decay
    p = _csv(tmp_path / "slow.csv", np.arange(x.shape[1]) / 1000.0, x[:2], "time_s")
    with pytest.raises(ImportFormatError, match=r"slow\.csv: the file's sample rate 1000 Hz "
                       r"disagrees with rig 'albacore-like' \(daq\.sample_rate_hz = 2048 Hz\).*"
                       r"--fs 1000"):
        _read(p)
    with pytest.raises(ImportFormatError, match=r"at 1000 Hz the anti-alias corner of rig "
                       r"'albacore-like' \(800 Hz, daq\.anti_alias_hz, a rig for .* Hz\) lies above Nyquist"):
        _read(p, fs_hz=1000.0)  # its analysis would refuse the rig's filter; said at import
    rig = tmp_path / "slow.toml"
    rig.write_text(RIG.read_text().replace("anti_alias_hz = 800.0", "anti_alias_hz = 400.0"))
    with open_device(str(p), rig=rig, fs_hz=1000.0) as dev:
        assert dev.info.fs_hz == 1000.0
    with pytest.raises(ImportFormatError, match=r"sample rate is 1000 Hz, not the 2048 Hz stated"):
        _read(p, fs_hz=2048.0)


@pytest.mark.parametrize(("header", "scale"), [
    ("time_s", 1.0), ("t [ms]", 1e3), ("time (us)", 1e6), ("t_ms", 1e3), ("Time/s", 1.0),
    ("time [sec]", 1.0),
])
def test_time_unit_read_from_the_header(decay, tmp_path, header, scale):
    x, _ = decay
    p = _csv(tmp_path / "t.csv", np.arange(400) / FS * scale, x[:2, :400], header)
    info, blocks = _read(p)
    assert info.fs_hz == FS and sum(b.n_samples for b in blocks) == 400


def test_time_without_a_unit_asks_for_it(decay, tmp_path):
    """A time column in ms that says no unit used to import as 2.048 Hz."""
    x, _ = decay
    p = _csv(tmp_path / "t.csv", np.arange(400) / FS * 1e3, x[:2, :400], "time")
    with pytest.raises(ImportFormatError, match=r"t\.csv: time column 'time' does not say its "
                       r"unit.*--time-unit"):
        _read(p)
    assert _read(p, time_unit="ms")[0].fs_hz == FS
    p2 = _csv(tmp_path / "t2.csv", np.arange(400) / FS * 1e3, x[:2, :400], "t [ms]")
    with pytest.raises(ImportFormatError, match=r"says 'ms', but the time unit given is 's'"):
        _read(p2, time_unit="s")


def test_a_file_without_a_time_column_is_told_so(tmp_path):
    """Gage columns only, each with its unit (the new user's notime.csv): the error says there
    is no time column and to give the rate, not that the "time column 'Accel 1' is in 'g'"."""
    p = tmp_path / "notime.csv"
    x = 1e-3 * np.random.default_rng(1).standard_normal((400, 2))
    np.savetxt(p, x, delimiter=",", comments="", header="Accel 1 [g],Accel 2 [g]")
    with pytest.raises(ImportFormatError, match=r"notime\.csv: no time column \(the first column, "
                       r"'Accel 1', is in 'g', not s, ms or us\): give the rate"):
        _read(p)


def test_cli_names_the_rate_and_takes_fs(decay, tmp_path, capsys):
    x, _ = decay
    p = _csv(tmp_path / "slow.csv", np.arange(x.shape[1]) / 1000.0, x[:2], "time")
    out = tmp_path / "slow.mcap"
    base = ["import", str(p), "--rig", str(RIG), "--out", str(out)]
    assert main(base) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "does not say its unit" in err[0]
    assert main([*base, "--time-unit", "s"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "disagrees with rig" in err[0] and not out.exists()
    rig = tmp_path / "slow.toml"
    rig.write_text(RIG.read_text().replace("anti_alias_hz = 800.0", "anti_alias_hz = 400.0"))
    base[3] = str(rig)
    assert main([*base, "--time-unit", "s", "--fs", "1000"]) == 0
    assert "2 ch at 1000 Hz" in capsys.readouterr().out


# -- force channels ------------------------------------------------------------------------------
FORCE_RIG = (RIGS / "albacore.toml").read_text() + '\n[[forces]]\nname = "ram"\nchannel = 16\n'


def _force_rig(text: str = FORCE_RIG):
    from ramdaq.analysis.model.rig import parse_rig

    return parse_rig(text, "force.toml")


@pytest.mark.parametrize(("old", "new", "msg"), [
    ("channel = 16\n", "channel = 17\n", r"forces\[0\]\.channel: 17: force channels follow"),
    ('name = "ram"', 'name = "ram"\nunit = "kgf"', r"forces\[0\]\.unit: 'kgf' is not a force"),
    ('name = "ram"', 'name = "ram"\nuint = "N"', r"forces\.uint: unknown key.*'unit'"),
])
def test_rig_force_channel_checked(old, new, msg):
    from ramdaq.analysis.model.rig import RigError

    rig = _force_rig()
    assert [f.name for f in rig.forces] == ["ram"] and rig.n_channels == 17
    with pytest.raises(RigError, match=rf"^force\.toml: {msg}"):
        _force_rig(FORCE_RIG.replace(old, new))


@pytest.fixture(scope="module")
def forced():
    """5 s with a ram load cell, a 20 ms blow at 2.5 s (the rig's ram lasts 5 ms): info, blocks."""
    from ramdaq.drivers.sim import Impact

    rig = _force_rig()
    blow = Impact(2.5, rig.impact.peak_force_N, 0.020, rig.impact.location_m, "y")
    with SimDevice(rig, duration_s=5.0, impacts=[blow], seed=2) as dev:
        blocks = list(dev)
        return dev.info, blocks, rig


def test_sim_force_channel_drives_the_trigger_and_the_decay_start(forced):
    """The simulator streams the ram's force in N; the trigger takes its onset from it and the
    analysis starts the free decay after the contact the force shows (20 ms + 10 ms settling),
    not after the rig's nominal 2 x 5 ms + 10 ms."""
    from ramdaq.daq.analyzer import judge_event
    from ramdaq.daq.trigger import Trigger

    info, blocks, rig = forced
    assert info.channels[-1] == "ram" and info.units[-1] == "N" and info.gages[-1] == 0
    trig = Trigger(info)
    events = [e for b in blocks for e in trig.process(b)] + trig.flush()
    assert trig.mode == "force" and len(events) == 1
    # onset: the blow's start less the anti-alias delay the trigger removes (the sim's force is
    # unfiltered), within 2 samples
    assert abs(events[0].onset_s - 2.5) < 2 / info.fs_hz + trig.delay_s
    hit = judge_event(0, events[0], info, rig)
    assert hit.accepted, hit.reason
    skip = hit.analysis.decay_start_s - events[0].onset_s
    # the half-sine's 5 % points lie 1 % of its length from its ends; 1 sample of rounding
    assert abs(skip - 0.030) < 0.02 * 0.020 + 2 / info.fs_hz, skip
    assert abs(hit.analysis.f_hz / 24.5 - 1) < 0.02


@pytest.mark.parametrize(("unit", "per_unit"), [("N", 1.0), ("kN", 1000.0), ("lbf", 4.4482216152605)])
def test_csv_force_column_in_any_force_unit(forced, tmp_path, unit, per_unit):
    info, blocks, rig = forced
    x = np.concatenate([b.counts * b.scale[:, None] for b in blocks], axis=1)[:, :3000]
    names = [*info.channels[:16], "Load"]
    x = np.vstack([x[:16], x[16] / per_unit])
    p = write_csv(tmp_path / "f.csv", np.arange(x.shape[1]) / FS, x, names,
                  units=["m/s^2"] * 16 + [unit])
    with pytest.raises(ImportFormatError, match=r"channel 'Load' is not a gage name"):
        with open_device(str(p), rig=rig):
            pass
    with open_device(str(p), rig=rig, force_channel="Load") as dev:
        got = np.concatenate([b.counts * b.scale[:, None] for b in dev], axis=1)
        assert dev.info.channels[-1] == "ram" and dev.info.units[-1] == "N"
        assert dev.info.extra["import"]["channels"]["ram"]["source"] == "Load"
    # requantised to 24 bits: within 1/2^23 of the peak (plus the printed digits, %.17g)
    assert np.max(np.abs(got[16] - x[16] * per_unit)) <= 1.2e-7 * np.max(np.abs(x[16] * per_unit))


def test_uff_and_tdms_force_records(forced, tmp_path):
    """UFF: a type 58 record of an excitation force (spec data type 13) is 'force NODE:DIR';
    TDMS: a channel named like the rig's force channel, unit_string N."""
    import pyuff

    from tests.test_imports import write_tdms, write_uff58

    info, blocks, rig = forced
    x = np.concatenate([b.counts * b.scale[:, None] for b in blocks], axis=1)[:, :2048]
    p = write_uff58(tmp_path / "f.uff", x[:16], list(info.gages[:16]))
    pyuff.UFF(str(p)).write_sets([dict(
        type=58, binary=0, func_type=1, rsp_node=4, rsp_dir=2, ref_node=0, ref_dir=0,
        abscissa_spacing=1, x=np.arange(x.shape[1]) / FS, data=x[16], id1="ram",
        ordinate_spec_data_type=13, abscissa_spec_data_type=17, orddenom_spec_data_type=0,
        ordinate_axis_units_lab="N", abscissa_axis_units_lab="s")], mode="add")
    with open_device(str(p), rig=rig, force_channel="force 4:+2") as dev:
        assert dev.info.units[-1] == "N"
        got = np.concatenate([b.counts * b.scale[:, None] for b in dev], axis=1)
    assert np.max(np.abs(got[16] - x[16])) <= 1e-11 * np.max(np.abs(x[16]))  # E20.12: 13 digits
    t = write_tdms(tmp_path / "f.tdms", x, list(info.channels), units=["m/s^2"] * 16 + ["N"])
    with open_device(str(t), rig=rig) as dev:  # named like the rig's force: no option needed
        assert dev.info.channels[-1] == "ram" and dev.info.units[-1] == "N"


# -- a record without a rig, and a record of part of the layout ----------------------------------
def _run(argv, capsys):
    rc = main(argv)
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_import_without_a_rig_makes_one_and_analyze_reports_each_gage(forced, tmp_path, capsys):
    """One response and the force, no rig: ``import --fs --units --force-channel`` writes a
    channels-only rig beside the recording, and ``analyze`` gives the gage's f, delta, zeta with
    standard errors and names every step of the chain it skipped (issue 18: two commands)."""
    import json

    info, blocks, _ = forced
    x = np.concatenate([b.counts * b.scale[:, None] for b in blocks], axis=1)
    p = write_csv(tmp_path / "hammer.csv", np.arange(x.shape[1]) / FS, np.vstack([x[3], x[16]]),
                  ["acc", "Load"], units=["", "N"])
    rc, out, err = _run(["import", str(p), "--fs", "2048"], capsys)
    assert rc == 1 and "hammer.csv: channel 'acc' states no unit; give --units" in err
    rc, out, err = _run(["import", str(p), "--fs", "2048", "--units", "m/s^2", "--force-channel",
                         "Load"], capsys)
    assert rc == 0, err
    # each kind's requantisation error in its own unit (a force's is in N, not m/s^2)
    assert re.search(r"largest error \S+ m/s\^2, \S+ N$", out.splitlines()[1]), out
    rig_file = tmp_path / "hammer.rig.toml"
    assert f"to {rig_file}" in out
    from ramdaq.analysis.model.rig import load_rig

    rig = load_rig(rig_file)
    assert not rig.structural and [g.number for g in rig.gages] == [1]
    assert [f.name for f in rig.forces] == ["Load"] and rig.daq.sample_rate_hz == 2048.0
    rc, out, err = _run(["import", str(p), "--fs", "2048", "--units", "m/s^2"], capsys)
    assert rc == 1 and "exists" in err  # the recording and its rig are not overwritten silently
    rc, out, err = _run(["analyze", str(tmp_path / "hammer.mcap"), "--out",
                         str(tmp_path / "an")], capsys)
    assert rc == 0, err
    rep = json.loads((tmp_path / "an" / "report.json").read_text())
    hit = rep["impacts"][0]
    assert hit["accepted"], hit["reason"]
    g = hit["analysis"]["gages"]["g01"]
    assert abs(g["f_hz"] / 24.5 - 1) < 0.02  # the rig's predominant mode in air (Table 2a)
    for k in ("f_se_hz", "delta", "delta_se", "zeta", "zeta_se"):
        assert g[k] is not None and g[k] > 0, k
    assert g["zeta"] == pytest.approx(g["delta"] / np.hypot(2 * np.pi, g["delta"]))
    steps = {s["step"] for s in rep["skipped"]}
    assert len(steps) == 6 and "virtual inertias (Eq 18-21)" in steps
    assert rep["virtual_inertias"] is None and rep["geometry_m"] is None
    assert "g01: f = 24." in out and "skipped: rudder motions (Eq 1-6b)" in out
    assert (tmp_path / "an" / "impact0_decay.png").exists()  # the default plot kind
    assert (tmp_path / "an" / "frf.png").exists()  # a force channel: its driving-point FRF


def test_part_of_the_layout_runs_the_steps_its_gages_allow(decay, tmp_path, capsys):
    """Gages 2, 4, 6, 8 of the full rig: the rudder motions and Eq 16/17 run; the steps that need
    hull or stock gages are skipped with the gages they lack (was: ``ramdaq analyze: 4``)."""
    import json

    x, gages = decay
    rows = [gages.index(n) for n in (2, 4, 6, 8)]
    p = write_csv(tmp_path / "four.csv", np.arange(x.shape[1]) / FS, x[rows],
                  ["g02", "g04", "g06", "g08"])
    assert _run(["import", str(p), "--rig", str(RIG)], capsys)[0] == 0
    rc, out, err = _run(["analyze", str(tmp_path / "four.mcap"), "--no-plots", "--out",
                         str(tmp_path / "an")], capsys)
    assert rc == 0, err
    a = json.loads((tmp_path / "an" / "report.json").read_text())["impacts"][0]["analysis"]
    assert set(a["motions"]) == {"gamma", "alpha", "v_2_6", "v_4_8"}
    assert a["damping"]["C_N_s_per_m"] is not None and a["relative_to_hull"] == {}
    skipped = {s["step"]: s["reason"] for s in a["skipped"]}
    assert skipped == {
        "decrements relative to the hull (Eq 8-13)":
            "needs gage(s) 5, 13, 14, which the record does not have",
        "effective stock lengths (Figures 8, 9)":
            "needs gage(s) 1, 3, 7, 10, 11, 12, 13, 14, which the record does not have",
        "damping constants with hull motion (Eq 14, 15)":
            "needs gage(s) 5, 13, 14, which the record does not have"}


@pytest.mark.parametrize(("n_gages", "k"), [(1, 1), (2, 1), (3, 2), (4, 3), (16, 3)])
def test_trigger_votes_k_of_at_most_the_gages_it_has(n_gages, k):
    """k of n follows the channel count (was: ``k_of_n k (3) must lie in 1..2``): 3 of four or
    more, all but one of two or three (one dead gage must not hide the blows); a k given is
    kept, and refused when the stream cannot meet it."""
    from ramdaq.daq.trigger import Trigger, TriggerSettings
    from ramdaq.drivers.block import StreamInfo

    info = StreamInfo("test", 2048.0, tuple(f"g{n:02d}" for n in range(1, n_gages + 1)),
                      ("m/s^2",) * n_gages, tuple(range(1, n_gages + 1)))
    assert Trigger(info).settings.k_of_n == (k, None)
    if n_gages < 3:
        with pytest.raises(ValueError, match=r"k_of_n k \(3\) must lie in 1\.\."):
            Trigger(info, TriggerSettings(k_of_n=(3, None)))


def test_channels_only_rig_refused_where_a_structure_is_needed(tmp_path):
    """The simulator, export-uff and the gap diagnosis need the structure: a channels-only rig
    is refused in one line naming what needs it, never an AttributeError on None."""
    from ramdaq.analysis.model.rig import RigError, parse_rig
    from ramdaq.drivers.files.minimal_rig import minimal_rig

    rig = parse_rig(minimal_rig(["a", "b"], name="two", fs_hz=100.0, units="g").text, "two.toml")
    assert [g.unit for g in rig.gages] == ["g", "g"] and rig.daq.sample_rate_hz == 100.0
    with pytest.raises(RigError, match=r"^two\.toml: rig 'two' describes only its channels .*"
                       r"the simulator needs the structure"):
        SimDevice(rig)
    from ramdaq.drivers.files.export_uff import export_uff

    r = export_uff(tmp_path / "x.uff", [], rig)  # the decay records need no structure
    assert r.nodes == 0 and "UFF 15 (gage nodes) and 55 (0 mode shapes) left out" in r.left_out
    from ramdaq.daq.gap_trial import _gages_present  # noqa: PLC2701 - the gap's own check, not its loading

    with pytest.raises(RigError, match=r"comparing a trial with the rig's model \(ramdaq gap, ramdaq "
                       r"rig fit\) needs the structure; pass --rig with a rig that describes it$"):
        _gages_present("t.mcap", None, rig)


def test_a_file_cut_off_mid_line_leaves_its_last_row_out_and_says_so(decay, tmp_path, capsys):
    """The new user's cut.csv (`head -c` of a good file): its last value a cut number
    (-0.152 of -0.1520...) went in as data without a word. The last row, without a line end,
    is left out and the import warns naming its line; the rows before are imported as read."""
    x, _ = decay
    p = _csv(tmp_path / "whole.csv", np.arange(400) / FS, x[:2, :400], "time_s")
    text = p.read_text()
    cut = tmp_path / "cut.csv"
    cut.write_text(text[:-4])   # the line end and the last 3 characters of row 400's last value
    info, blocks = _read(cut)
    assert sum(b.n_samples for b in blocks) == 399
    rc, out, err = _run(["import", str(cut), "--rig", str(RIG), "--out", str(tmp_path / "c.mcap")],
                        capsys)
    assert rc == 0
    assert "warning: line 401, the last, has no line end (the file cut off mid-line?)" in out + err
