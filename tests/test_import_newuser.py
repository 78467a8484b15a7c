"""What a new user met importing their own records (CSV, UFF; 5000 and 1651 Hz; g and m/s^2;
a load cell): the channels-only rig records the unit applied, the file's own rate is taken,
the written rig re-imports its source, CSV dialects, and the CLI names its options only."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ramdaq.analysis.model.rig import load_rig
from ramdaq.daq.commands.cli import main
from ramdaq.drivers.registry import open_device

G = 9.80665
FS_B = 1651.0  # archive B's rate: no rig ships it


def _run(argv, capsys):
    rc = main([str(a) for a in argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


def _decay(fs: float, n_ch: int, dur: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """``t`` (s) and ``n_ch`` decaying 8.3 Hz sines (m/s^2), peak 0.5 / (k+1)."""
    t = np.arange(round(dur * fs)) / fs
    x = np.array([0.5 / (k + 1) * np.exp(-1.5 * t) * np.sin(2 * np.pi * 8.3 * t + 0.3)
                  for k in range(n_ch)])
    return t, x


def _archive_b(path: Path, header_unit: str | None, scale: float = 1.0,
               names=("AI0 acc", "AI1 acc")) -> Path:
    """Archive B's shape: time in ms, channels ``"AI0 acc (m/s^2)"``; values divided by
    ``scale`` (G for a file in g); ``header_unit=None`` writes no units."""
    t, x = _decay(FS_B, len(names))
    head = ["t [ms]"] + [f"{n} ({header_unit})" if header_unit else n for n in names]
    rows = [",".join(head)] + [",".join([f"{t[i] * 1e3:.4f}"] + [f"{v:.9e}" for v in x[:, i] / scale])
                               for i in range(t.size)]
    path.write_text("\n".join(rows) + "\n")
    return path


def _values(mcap: Path) -> np.ndarray:
    """The recording's samples, (channels, n), SI."""
    with open_device(str(mcap)) as dev:
        return np.concatenate([b.counts * b.scale[:, None] for b in dev], axis=1)


# -- 1: the rig file records the unit applied ----------------------------------------------------
@pytest.mark.parametrize("header,flag,scale", [("m/s^2", "g", 1.0), ("g", "m/s^2", G)])
def test_written_rig_records_the_unit_applied_not_the_flag(tmp_path, capsys, header, flag, scale):
    """``import archive_B.csv --units g`` on a file whose header says m/s^2 imported the data
    right but wrote ``unit = "g"`` to the rig: a sibling file without unit headers imported with
    that rig came out 9.81 times too large. Now the header's unit is applied, recorded, and the
    difference from --units warned of naming the channel."""
    src = _archive_b(tmp_path / "archive_B.csv", header, scale)
    rc, out, err = _run(["import", src, "--units", flag], capsys)
    assert rc == 0, err
    assert "warning: channels 'AI0 acc', 'AI1 acc' are in" in err and f"--units {flag}" in err
    rig = load_rig(tmp_path / "archive_B.rig.toml")
    assert {g.unit for g in rig.gages} == {header}
    first = _values(tmp_path / "archive_B.mcap")
    _, x = _decay(FS_B, 2)
    # 10-digit text, requantised to 24 bits: 6e-8 of the peak (import_common's bound)
    assert np.max(np.abs(first - x)) <= 1e-7 * np.max(np.abs(x))
    sib = _archive_b(tmp_path / "sibling.csv", None, scale)
    rc, out, err = _run(["import", sib, "--rig", tmp_path / "archive_B.rig.toml", "--channels",
                         "AI0 acc=1,AI1 acc=2"], capsys)
    assert rc == 0, err
    assert np.max(np.abs(_values(tmp_path / "sibling.mcap") - first)) <= 2e-7 * np.max(np.abs(x))


def test_no_unit_anywhere_asks_for_units(tmp_path, capsys):
    """A channel stating no unit and no --units: one line naming the channel and the option."""
    src = _archive_b(tmp_path / "b.csv", None)
    rc, out, err = _run(["import", src], capsys)
    assert rc == 1 and "'AI0 acc' states no unit; give --units" in err


# -- 2: the file's own rate ----------------------------------------------------------------------
def test_file_rate_is_taken_without_fs(tmp_path, capsys):
    """--fs was demanded without --rig although the time column states 1651 Hz."""
    src = _archive_b(tmp_path / "b.csv", "m/s^2")
    rc, out, err = _run(["import", src], capsys)
    assert rc == 0, err
    assert load_rig(tmp_path / "b.rig.toml").daq.sample_rate_hz == FS_B
    assert "at 1651 Hz" in out
    # the medium a channels-only rig takes is said, and how to change it (it was silent)
    assert "(no --rig given; medium air, --medium water for a flooded trial)" in out
    rc, out, err = _run(["import", src, "--fs", "1000", "--out", tmp_path / "c.mcap"], capsys)
    assert rc == 1 and "1000 Hz" in err  # a stated rate is still checked against the file's


# -- 3: channel names ----------------------------------------------------------------------------
def test_written_rig_reimports_its_own_source(tmp_path, capsys):
    """The rig ``import`` wrote refused its own source: ``'AI0 acc' is not a gage name``. It
    records each gage's source channel, and a file with those channels maps through it; a file
    with other names is told to use --channels (the option, not the Python argument)."""
    src = _archive_b(tmp_path / "b.csv", "m/s^2")
    assert _run(["import", src], capsys)[0] == 0
    first = _values(tmp_path / "b.mcap")
    rc, out, err = _run(["import", src, "--rig", tmp_path / "b.rig.toml", "--out",
                         tmp_path / "again.mcap"], capsys)
    assert rc == 0, err
    assert np.array_equal(_values(tmp_path / "again.mcap"), first)  # same file, same counts
    other = _archive_b(tmp_path / "o.csv", "m/s^2", names=("AI0", "AI1"))
    rc, out, err = _run(["import", other, "--rig", tmp_path / "b.rig.toml"], capsys)
    assert rc == 1 and "'AI0' is not a source channel of rig 'b'" in err
    assert "--channels" in err and "channels=" not in err


def test_force_channel_named_with_its_unit(tmp_path, capsys):
    """``--force-channel 'Load cell [N]'`` (the header's text) was refused; the name without
    the unit was needed. Both are taken, with and without a rig."""
    t, x = _decay(5000.0, 2, dur=0.5)
    f = 100.0 * np.exp(-((t - 0.1) / 1e-3) ** 2)
    src = tmp_path / "a.csv"
    src.write_text("Time [s],Accel 1 [g],Load cell [N]\n" + "".join(
        f"{t[i]:.6f},{x[0, i] / G:.9e},{f[i]:.6f}\n" for i in range(t.size)))
    rc, out, err = _run(["import", src, "--force-channel", "Load cell [N]"], capsys)
    assert rc == 0, err
    rig = load_rig(tmp_path / "a.rig.toml")
    assert [fc.name for fc in rig.forces] == ["Load cell"] and rig.gages[0].unit == "g"
    rc, out, err = _run(["import", src, "--rig", tmp_path / "a.rig.toml", "--force-channel",
                         "Load cell [N]", "--out", tmp_path / "b.mcap"], capsys)
    assert rc == 0, err
    assert np.array_equal(_values(tmp_path / "b.mcap"), _values(tmp_path / "a.mcap"))


def test_cli_messages_name_options_not_python_arguments(tmp_path, capsys):
    """``(fs_hz=, --fs)``, ``allow_gaps= (--allow-gaps)`` on the command line: options only;
    from Python both are named."""
    src = _archive_b(tmp_path / "b.csv", "m/s^2")
    assert _run(["import", src], capsys)[0] == 0
    lines = src.read_text().split("\n")
    lines[5] = lines[5].rsplit(",", 1)[0] + ","  # a missing value on line 6
    gap = tmp_path / "gap.csv"
    gap.write_text("\n".join(lines))
    rc, out, err = _run(["import", gap, "--rig", tmp_path / "b.rig.toml"], capsys)
    assert rc == 1 and "line 6" in err and "--allow-gaps" in err and "allow_gaps=" not in err
    rc, out, err = _run(["import", src, "--rig", tmp_path / "b.rig.toml", "--fs", "1000",
                         "--out", tmp_path / "x.mcap"], capsys)
    assert rc == 1 and "--fs" in err and "fs_hz=" not in err
    from ramdaq.drivers.files.import_common import ImportFormatError

    with pytest.raises(ImportFormatError, match=r"allow_gaps= \(--allow-gaps\)"):
        with open_device(str(gap), rig=tmp_path / "b.rig.toml") as dev:
            list(dev)


# -- 4: CSV dialects -----------------------------------------------------------------------------
def _dryd_a(path: Path, fs: float = 5000.0) -> tuple[Path, np.ndarray]:
    """Drydock A's shape: a ``key;value`` header block, a blank line, ``;`` delimiters, decimal
    commas, accelerations in g and a load cell in N."""
    t, x = _decay(fs, 2, dur=0.4)
    f = 1000.0 * np.exp(-((t - 0.1) / 1e-3) ** 2)
    rows = ["Measurement system;HBM-like QuantumX export", "Date;2026-11-20",
            "Sample rate;5000 Hz", "", "Time [s];Accel 1 [g];Accel 2 [g];Load cell [N]"]
    rows += [";".join([f"{t[i]:.6f}", f"{x[0, i] / G:.8e}", f"{x[1, i] / G:.8e}",
                       f"{f[i]:.3f}"]).replace(".", ",") for i in range(t.size)]
    path.write_text("\n".join(rows) + "\n")
    return path, x


def test_header_block_and_decimal_commas_are_read_and_said(tmp_path, capsys):
    """A ``key;value`` header block above the column names and ``0,000200`` decimals were
    refused ('Operator' is not a number); now the block is skipped and both are said."""
    src, x = _dryd_a(tmp_path / "dryd_A.csv")
    rc, out, err = _run(["import", src, "--force-channel", "Load cell"], capsys)
    assert rc == 0, err
    assert "skipped 3 lines above the column names (lines 1-3" in out
    assert "read decimal commas as decimal points (the delimiter is ';')" in out
    got = _values(tmp_path / "dryd_A.mcap")
    # 9 significant digits in g, requantised to 24 bits: well within 1e-7 of the peak
    assert np.max(np.abs(got[:2] - x)) <= 1e-7 * np.max(np.abs(x))
    assert load_rig(tmp_path / "dryd_A.rig.toml").daq.sample_rate_hz == 5000.0


def test_bad_value_named_on_its_own_line(tmp_path, capsys):
    """``0,000;abc`` on line 2 was reported on line 3 (the row was taken for a units row)."""
    p = tmp_path / "c.csv"
    p.write_text("time_s;g1\n0,000;abc\n0,001;2,5\n")
    rc, out, err = _run(["import", p, "--units", "g"], capsys)
    assert rc == 1 and "line 2, column 'g1': 'abc' is not a number" in err


def test_quoted_decimal_comma_in_a_comma_file_says_what(tmp_path, capsys):
    """A quoted ``"1,5"`` in a comma-separated file was '3 fields, expected 2'."""
    p = tmp_path / "c.csv"
    p.write_text('time_s,g1\n0.000,"1,5"\n0.001,2.5\n')
    rc, out, err = _run(["import", p, "--units", "g"], capsys)
    assert rc == 1 and "line 2, column 'g1': '1,5' is not a number (a decimal comma?" in err


# -- 6: export-uff of a channels-only import -----------------------------------------------------
def test_export_uff_of_a_channels_only_import_writes_the_decays(tmp_path, capsys):
    """``export-uff`` refused a channels-only import ('needs the structure') after analysing
    it; now it writes the 58 decay records with direction 0 and says what was left out."""
    import pyuff

    fs = FS_B
    t = np.arange(round(4.0 * fs)) / fs
    tb = np.clip(t - 1.0, 0.0, None)
    x = np.array([a * (t >= 1.0) * np.exp(-1.5 * tb) * np.sin(2 * np.pi * 8.3 * tb)
                  for a in (0.5, 0.3)]) + 1e-5 * np.random.default_rng(0).standard_normal((2, t.size))
    src = tmp_path / "b.csv"
    src.write_text("t [ms],AI0 acc (m/s^2),AI1 acc (m/s^2)\n" + "".join(
        f"{t[i] * 1e3:.4f},{x[0, i]:.9e},{x[1, i]:.9e}\n" for i in range(t.size)))
    assert _run(["import", src], capsys)[0] == 0
    rc, out, err = _run(["export-uff", tmp_path / "b.mcap"], capsys)
    assert rc == 0, err
    assert "UFF 15 (gage nodes) and 55 (" in out and "left out: rig 'b' describes only its " \
           "channels" in out
    sets = pyuff.UFF(str(tmp_path / "b.uff")).read_sets()
    sets = sets if isinstance(sets, list) else [sets]
    assert [d["type"] for d in sets] == [164, 58, 58]  # one accepted hit, two gages
    assert [d["rsp_dir"] for d in sets[1:]] == [0, 0] and [d["rsp_node"] for d in sets[1:]] == [1, 2]
    rec = _values(tmp_path / "b.mcap")
    first = round(sets[1]["x"][0] * fs)
    # E20.12 ordinates: 13 significant digits
    assert np.allclose(sets[1]["data"], rec[0, first:first + sets[1]["data"].size], rtol=1e-11,
                       atol=1e-12 * np.max(np.abs(rec[0])))


def test_uff_channels_by_their_id1_text(tmp_path, capsys):
    """UFF channels were named only by node number ('1', 'force 100:+3'); a record's ID line 1
    ('Accel 1', 'Hammer') names it too, for --force-channel and --channels."""
    import pyuff

    t, x = _decay(FS_B, 2, dur=0.5)
    f = 100.0 * np.exp(-((t - 0.1) / 2e-3) ** 2)
    sets = [pyuff.prepare_58(binary=0, id1=name, func_type=1, rsp_node=node, rsp_dir=3,
                             ref_node=0, ref_dir=0, abscissa_spacing=1, abscissa_inc=1 / FS_B,
                             abscissa_min=0.0, x=t, abscissa_spec_data_type=17,
                             ordinate_spec_data_type=spec, orddenom_spec_data_type=0, data=y,
                             ordinate_axis_units_lab=unit, abscissa_axis_units_lab="s",
                             num_pts=t.size)
            for name, node, spec, y, unit in [("Accel 1", 1, 12, x[0] / G, "g"),
                                              ("Accel 2", 2, 12, x[1] / G, "g"),
                                              ("Hammer", 100, 13, f, "N")]]
    src = tmp_path / "c.uff"
    pyuff.UFF(str(src)).write_sets(sets, mode="add")
    rc, out, err = _run(["import", src, "--force-channel", "Hammer"], capsys)
    assert rc == 0, err
    rig = load_rig(tmp_path / "c.rig.toml")
    assert [g.unit for g in rig.gages] == ["g", "g"] and rig.forces[0].name == "force 100:+3"
    rc, out, err = _run(["import", src, "--rig", tmp_path / "c.rig.toml", "--channels",
                         "Accel 2=g02", "--force-channel", "Hammer", "--out", tmp_path / "d.mcap"],
                        capsys)
    assert rc == 0, err
    got = _values(tmp_path / "d.mcap")
    # E20.12 in g: 13 digits, requantised to 24 bits: 6e-8 of the peak
    assert got.shape[0] == 2 and np.max(np.abs(got[0] - x[1])) <= 1e-7 * np.max(np.abs(x[1]))


def test_a_rig_unit_the_header_contradicts_is_warned_of(tmp_path, capsys):
    """With --rig, a header unit that differs from the rig's gage unit is applied (the file's
    word for its own samples) and said, naming the channel, not silently."""
    src = _archive_b(tmp_path / "b.csv", "g", G)
    assert _run(["import", src], capsys)[0] == 0
    other = _archive_b(tmp_path / "o.csv", "m/s^2")
    rc, out, err = _run(["import", other, "--rig", tmp_path / "b.rig.toml"], capsys)
    assert rc == 0, err
    assert ("warning: channels 'AI0 acc', 'AI1 acc' are in m/s^2 by the file's header, but rig "
            "'b' says g" in err) and err.count("warning") == 1  # one line for all such channels
    _, x = _decay(FS_B, 2)
    assert np.max(np.abs(_values(tmp_path / "o.mcap") - x)) <= 1e-7 * np.max(np.abs(x))


def test_a_rig_that_states_no_unit_is_not_contradicted(tmp_path, capsys):
    """``export-csv --units g`` then ``import --rig`` with a rig whose gages state no unit
    warned "in g by the file's header, but rig says m/s^2" on an exact round trip: the rig's
    m/s^2 was only the default for unlabelled columns. A header's unit against a rig that says
    nothing is no disagreement; an unlabelled column is still read in m/s^2."""
    src = _archive_b(tmp_path / "b.csv", "g", G)
    assert _run(["import", src], capsys)[0] == 0
    rig = tmp_path / "b.rig.toml"
    rig.write_text(rig.read_text().replace('unit = "g"\n', ""))
    assert load_rig(rig).gages[0].unit is None and load_rig(rig).gages[0].assumed_unit == "m/s^2"
    _, x = _decay(FS_B, 2)
    for header, scale in (("g", G), (None, 1.0)):
        f = _archive_b(tmp_path / f"in_{header}.csv".replace("/", ""), header, scale)
        rc, _, err = _run(["import", f, "--rig", rig], capsys)
        assert rc == 0 and "warning" not in err, err
        # E16.9 in g, requantised to 24 bits: 6e-8 of the peak
        got = _values(tmp_path / f"in_{header}.mcap".replace("/", ""))
        assert np.max(np.abs(got - x)) <= 1e-7 * np.max(np.abs(x))


def test_a_tsv_file_is_read_as_csv(tmp_path, capsys):
    """``dryd_A_tab.tsv`` without --format: 'format 'tsv' is not csv, uff or tdms'."""
    src = tmp_path / "b.tsv"
    src.write_text(_archive_b(tmp_path / "b.csv", "m/s^2").read_text().replace(",", "\t"))
    rc, out, err = _run(["import", src], capsys)
    assert rc == 0, err
    assert _run(["import", tmp_path / "b.csv", "--out", tmp_path / "c.mcap"], capsys)[0] == 0
    assert np.array_equal(_values(tmp_path / "b.mcap"), _values(tmp_path / "c.mcap"))


def test_allow_gaps_says_which_good_values_went_with_the_gap(tmp_path, capsys):
    """tester9: 60 NaNs on one channel of three dropped those rows on every channel without a
    word (120 good values lost). A recording's gap is stream-wide (a block has no per-channel
    hole), so the rows still go, but one line says how many good values on which channels."""
    src = _archive_b(tmp_path / "nan.csv", "m/s^2", names=("A1", "A2", "A3"))
    lines = src.read_text().splitlines()
    for i in range(101, 161):  # data rows 100..159 (line 0 is the header): A2 empty
        cells = lines[i].split(",")
        cells[2] = "nan"
        lines[i] = ",".join(cells)
    src.write_text("\n".join(lines) + "\n")
    rc, out, err = _run(["import", src, "--allow-gaps"], capsys)
    assert rc == 0, err
    assert ("warning: --allow-gaps: 120 good values on 'A1' (60), 'A3' (60) were dropped with "
            "the gaps, the rows where 'A2' (60) had no value") in err
    assert "1 gaps (60 samples missing)" in out


def _accel_rows(n: int, fs: float) -> np.ndarray:
    """(3, n) decaying sines, m/s^2 (the shape of tester9's 'Accel 1..3' files)."""
    _, x = _decay(fs, 3, dur=n / fs)
    return x


def test_no_time_column_with_fs_reads_every_column_as_a_channel(tmp_path, capsys):
    """tester9: headers 'Accel 1..3' and --fs 2048: 'Accel 1' was taken as time (and refused
    for saying no unit). With --fs and no column named like a time, the rows are samples at
    --fs and every column a channel, said in one line; without --fs the refusal names --fs."""
    x = _accel_rows(4096, 2048.0)
    src = tmp_path / "notime.csv"
    src.write_text("Accel 1,Accel 2,Accel 3\n" + "\n".join(
        ",".join(f"{v:.9e}" for v in x[:, i]) for i in range(x.shape[1])) + "\n")
    rc, out, err = _run(["import", src, "--units", "m/s^2"], capsys)
    assert rc == 1 and "a file without a time column: give its rate, --fs HZ" in err
    rc, out, err = _run(["import", src, "--units", "m/s^2", "--fs", "2048"], capsys)
    assert rc == 0, err
    assert "no time column" in out and "samples at 2048 Hz as --fs states" in out
    got = _values(tmp_path / "notime.mcap")
    assert got.shape == x.shape  # three channels, every row a sample
    # 10-digit text requantised to 24 bits: 6e-8 of the peak (import_common's bound)
    assert np.max(np.abs(got - x)) <= 1e-7 * np.max(np.abs(x))


@pytest.mark.parametrize("fs_flag", [None, "2048"])
def test_times_rounded_to_their_printed_resolution_are_one_grid(tmp_path, capsys, fs_flag):
    """tester9: 2048 Hz printed to 0.1 ms (steps 0.0005 / 0.0004 s) was refused as
    non-uniform, and --fs 2048 refused too (median step 0.0005 s = 2000 Hz). A time rounded to
    0.1 ms lies up to 0.05 ms = 0.10 sample off its sample, so each row is placed within that
    more; the rate comes from the whole span; a 10-row gap stays a gap."""
    fs, n = 2048.0, 16384
    x = _accel_rows(n, fs)
    keep = np.ones(n, bool)
    keep[9000:9010] = False
    t = np.arange(n) / fs
    src = tmp_path / "round4.csv"
    src.write_text("time_s,A1,A2,A3\n" + "\n".join(
        f"{t[i]:.4f}," + ",".join(f"{v:.9e}" for v in x[:, i]) for i in np.flatnonzero(keep))
        + "\n")
    argv = ["import", src, "--units", "m/s^2"] + (["--fs", fs_flag] if fs_flag else [])
    rc, out, err = _run(argv, capsys)
    assert rc == 0, err
    assert "3 ch at 2048 Hz" in out and "1 gaps (10 samples missing)" in out
    assert "printed to 0.0001 s (0.20 sample at 2048 Hz)" in out
    got = _values(tmp_path / "round4.mcap")
    assert np.max(np.abs(got - x[:, keep])) <= 1e-7 * np.max(np.abs(x))


@pytest.mark.parametrize("fs_flag", [None, "2048"])
def test_times_printed_to_significant_digits_are_one_grid(tmp_path, capsys, fs_flag):
    """A new user's CSV had its times written with ``%g`` (numpy's and many exports' default):
    six significant digits, so 0.000488281 s early and 10.0229 s after 10 s -- 0.1 ms there,
    0.20 sample at 2048 Hz. One resolution for the column (its first rows': 1e-9 s) refused
    line 20529 as "-0.10 samples off the grid (a non-uniform time column)". Each row is now
    placed within its own printed rounding, and the import says how the column was printed."""
    fs, n = 2048.0, 20 * 2048 + 600              # past 10 s, where %g drops to 4 decimals
    x = _accel_rows(n, fs)
    t = np.arange(n) / fs
    src = tmp_path / "g.csv"
    src.write_text("time_s,A1,A2,A3\n" + "\n".join(
        f"{t[i]:g}," + ",".join(f"{v:.9e}" for v in x[:, i]) for i in range(n)) + "\n")
    argv = ["import", src, "--units", "m/s^2"] + (["--fs", fs_flag] if fs_flag else [])
    rc, out, err = _run(argv, capsys)
    assert rc == 0, err
    assert "3 ch at 2048 Hz" in out and "0 gaps (0 samples missing)" in out
    assert ("the time column is printed to 6 significant digits, down to 0.0001 s at its latest "
            "rows (0.20 sample at 2048 Hz)") in out
    got = _values(tmp_path / "g.mcap")
    assert got.shape == x.shape
    assert np.max(np.abs(got - x)) <= 1e-7 * np.max(np.abs(x))   # 24-bit requantisation, as above
    # a row without its time is the one-line refusal naming it (the digits' reading skips it;
    # it once broke on it, a numpy broadcast error instead of the line)
    lines = src.read_text().splitlines()
    lines[101] = "," + lines[101].split(",", 1)[1]
    src.write_text("\n".join(lines) + "\n")
    rc, out, err = _run(argv + ["--overwrite"], capsys)
    assert rc == 1 and "g.csv: line 102: the time is missing or not finite" in err, err


def test_seconds_under_a_ms_header_ask_for_the_unit_not_a_rate_nothing_can_analyse(tmp_path, capsys):
    """A new user's seconds under a 't [ms]' header read as 2.048 MHz: the refusal told them to
    give --fs 2.048e+06, which imports a 0.01 s recording no trigger can read (the trigger takes
    50 Hz to 51.2 kHz). A rate 1000 times the rig's, or one outside that span, now asks about
    the time column's unit instead; a plain disagreement still offers --fs."""
    t, x = _decay(2048.0, 2, dur=0.5)
    rig = Path(__file__).resolve().parents[1] / "recordings" / "rigs" / "albacore.toml"
    rows = "\n".join(f"{t[i]:.6f},{x[0, i]:.9e},{x[1, i]:.9e}" for i in range(t.size)) + "\n"
    src = tmp_path / "ms.csv"
    src.write_text("t [ms],g01,g02\n" + rows)
    rc, out, err = _run(["import", src, "--rig", rig], capsys)
    assert rc == 1
    assert "2.048e+06 Hz disagrees with rig 'albacore-like'" in err
    assert "1000 times it: are the times in s, read as ms? -- check the time column's unit" in err
    assert "--fs 2.048e+06" not in err
    src = tmp_path / "s.csv"                     # seconds said as such, at 1/2 the rig's rate
    src.write_text("time_s,g01,g02\n" + "\n".join(
        f"{2 * t[i]:.6f},{x[0, i]:.9e},{x[1, i]:.9e}" for i in range(t.size)) + "\n")
    rc, out, err = _run(["import", src, "--rig", rig], capsys)
    assert rc == 1 and "state it with --fs 1024" in err and "read as" not in err


def test_the_anti_alias_line_names_the_rig_once_quoted(tmp_path, capsys):
    """tester9: "rig 'albacore-like''s anti-alias corner" (a doubled quote)."""
    t, x = _decay(1000.0, 2, dur=0.5)  # 1000 Hz: Nyquist 500 Hz, below the rig's 800 Hz corner
    src = tmp_path / "slow.csv"
    src.write_text("time_s,g01,g02\n" + "\n".join(f"{t[i]:.6f},{x[0, i]:.9e},{x[1, i]:.9e}"
                                                  for i in range(t.size)) + "\n")
    rig = Path(__file__).resolve().parents[1] / "recordings" / "rigs" / "albacore.toml"
    rc, out, err = _run(["import", src, "--rig", rig, "--fs", "1000"], capsys)
    assert rc == 1 and "the anti-alias corner of rig 'albacore-like' (" in err and "''" not in err


def test_a_tdms_file_with_decimated_groups_names_their_rates_and_imports_one(tmp_path, capsys):
    """LabVIEW writes decimated copies of a recording as groups of their own (new user, npTDMS's
    ``Digital_Input.tdms``): the import said 'a truncated or partial file?' of a whole one. It
    names each group's rate and asks for one group; ``--group`` imports it."""
    from nptdms import ChannelObject, TdmsWriter

    fs = 2000.0
    t, x = _decay(fs, 2)
    src = tmp_path / "decimated.tdms"
    with TdmsWriter(str(src)) as w:
        w.write_segment(
            [ChannelObject("All Data", f"g{k + 1:02d}", x[k], properties={
                "wf_increment": 1 / fs, "wf_start_offset": 0.0, "unit_string": "m/s^2"})
             for k in range(2)]
            + [ChannelObject("Decimated Data_Level1", f"g{k + 1:02d}", x[k, ::50], properties={
                "wf_increment": 50 / fs, "wf_start_offset": 0.0, "unit_string": "m/s^2"})
               for k in range(2)])
    rc, out, err = _run(["import", src], capsys)
    assert rc == 1 and "truncated" not in err
    assert "group 'All Data' at 2000 Hz; group 'Decimated Data_Level1' at 40 Hz" in err
    assert "--group NAME" in err
    rc, out, err = _run(["import", src, "--group", "All Data"], capsys)
    assert rc == 0, err
    rig = load_rig(tmp_path / "decimated.rig.toml")
    assert rig.daq.sample_rate_hz == fs and len(rig.gages) == 2
    np.testing.assert_allclose(_values(tmp_path / "decimated.mcap")[:, : t.size], x, rtol=0,
                               atol=1e-6 * np.abs(x).max())  # 24-bit requantisation of 0.5 m/s^2
    rc, out, err = _run(["import", _archive_b(tmp_path / "b.csv", "m/s^2"), "--group", "All Data"],
                        capsys)
    assert rc == 1 and "--group is for a TDMS file" in err


def test_accelerometers_recorded_in_volts_import_with_their_sensitivity(tmp_path, capsys):
    """A field system that stores volts (new user: npTDMS's ``raw1.tdms``, 'Volts'): refused with
    the option to give, then imported with ``--sensitivity`` per channel (100 mV/g and 10.2
    mV/(m/s^2)), said channel by channel; the m/s^2 come back within the 24-bit requantisation
    (the file's volts are not quantised: 1e-6 of full scale)."""
    sens = {"AI0 acc": 0.1 / G, "AI1 acc": 10.2e-3}          # V per m/s^2
    t, x = _decay(FS_B, 2)
    volts = tmp_path / "v.csv"
    rows = ["t [ms],AI0 acc (V),AI1 acc (mV)"] + [
        f"{t[i] * 1e3:.4f},{x[0, i] * sens['AI0 acc']:.9e},{x[1, i] * sens['AI1 acc'] * 1e3:.9e}"
        for i in range(t.size)]
    volts.write_text("\n".join(rows) + "\n")
    rc, out, err = _run(["import", volts], capsys)
    assert rc == 1 and "'AI0 acc' is in 'V'" in err and "--sensitivity" in err
    rc, out, err = _run(["import", volts, "--sensitivity", "AI0 acc=100mV/g,AI1 acc=10.2mV/(m/s^2)"],
                        capsys)
    assert rc == 0, err
    assert "channel 'AI0 acc' is in volts: converted at 10.2 mV/(m/s^2) = 100 mV/g" in out
    assert "channel 'AI1 acc' is in volts: converted at 10.2 mV/(m/s^2) = 100 mV/g" in out  # 100.03
    got = _values(tmp_path / "v.mcap")[:, : t.size]
    np.testing.assert_allclose(got, x, rtol=0, atol=2e-6 * np.abs(x).max())
    # the rig that import wrote keeps each sensitivity: it re-imports its source without the
    # option, saying whose sensitivity converted the volts, to the same counts
    rig = load_rig(tmp_path / "v.rig.toml")
    np.testing.assert_allclose([g.sensitivity_V_per_m_s2 for g in rig.gages_by_channel()],
                               [sens["AI0 acc"], sens["AI1 acc"]], rtol=1e-15)  # as parsed
    rc, out, err = _run(["import", volts, "--rig", tmp_path / "v.rig.toml",
                         "--out", tmp_path / "again.mcap"], capsys)
    assert rc == 0, err
    assert "channel 'AI0 acc' is in volts: converted at 10.2 mV/(m/s^2) = 100 mV/g (gage 1's " \
           "sensitivity in rig 'v')" in out
    np.testing.assert_array_equal(_values(tmp_path / "again.mcap"), _values(tmp_path / "v.mcap"))
    # a sensitivity nothing uses is an error, not a silent no-op
    ms2 = _archive_b(tmp_path / "b.csv", "m/s^2")
    rc, out, err = _run(["import", ms2, "--sensitivity", "100mV/g", "--out", tmp_path / "b.mcap"],
                        capsys)
    assert rc == 1 and "no channel imported is in volts" in err
    rc, out, err = _run(["import", volts, "--sensitivity", "AI0 acc=100mV/g,AI1 acc=10mV/g,AI2=1V/g",
                         "--out", tmp_path / "c.mcap"], capsys)
    assert rc == 1 and "'AI2'" in err
    rc, out, err = _run(["import", volts, "--sensitivity", "100 mV per g", "--out", tmp_path / "d.mcap"],
                        capsys)
    assert rc == 1 and "expected e.g. 100mV/g" in err
