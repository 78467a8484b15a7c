"""Imports from other systems (CSV, UFF 58, TDMS) and the UFF export, on files written from a
simulated trial: lossless counts, gaps, one-line errors, and CSV -> MCAP -> ``ramdaq analyze``."""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
import pyuff
from nptdms import ChannelObject, TdmsWriter
from scipy.signal import lfilter

from ramdaq.daq.commands.cli import main
from ramdaq.drivers.files.export_uff import AXIS_CODES, export_uff
from ramdaq.drivers.files.import_common import (
    G0,
    ImportFormatError,
    detect_step,
    gage_of_name,
    parse_channel_map,
)
from ramdaq.drivers.files.import_csv import CsvImportDevice
from ramdaq.drivers.files.import_tdms import TdmsImportDevice
from ramdaq.drivers.files.import_uff import UffImportDevice
from ramdaq.drivers.registry import open_device
from ramdaq.drivers.sim import SimDevice
from tests.conftest import RIGS

RIG = RIGS / "albacore.toml"
FS = 2048.0


# -- writers: numpy text, pyuff and nptdms, no pandas ------------------------------------------
def write_csv(path: Path, t: np.ndarray, x: np.ndarray, names: list[str], *, units=None,
              units_row: bool = False, fmt: str = "%.17g", delimiter: str = ",") -> Path:
    """A CSV of time (s) and channels (rows of ``x``); ``x`` may hold NaN (written empty)."""
    units = units or ["m/s^2"] * len(names)
    head = ["time", *names] if units_row else \
        ["time [s]"] + [f"{n} [{u}]" for n, u in zip(names, units, strict=True)]
    lines = [delimiter.join(head)] + ([delimiter.join(["s", *units])] if units_row else [])
    buf = io.StringIO()
    np.savetxt(buf, np.column_stack([t, x.T]), fmt=fmt, delimiter=delimiter)
    body = re.sub(rf"(?<=[{delimiter}])nan(?=[{delimiter}\n])", "", buf.getvalue())
    path.write_text("\n".join(lines) + "\n" + body)
    return path


def write_uff58(path: Path, x: np.ndarray, nodes: list[int], *, fs: float = FS, t0: float = 0.0,
                binary: bool = False, unit: str = "m/s^2", func_type: int = 1) -> Path:
    """One type 58 time record (acceleration) per row of ``x``, node = gage."""
    if path.exists():
        path.unlink()
    sets = [dict(type=58, binary=int(binary), func_type=func_type, rsp_node=n, rsp_dir=2,
                 ref_node=0, ref_dir=0, abscissa_spacing=1, x=t0 + np.arange(x.shape[1]) / fs,
                 data=np.ascontiguousarray(row), id1=f"g{n:02d}", ordinate_spec_data_type=12,
                 abscissa_spec_data_type=17, orddenom_spec_data_type=0,
                 ordinate_axis_units_lab=unit, abscissa_axis_units_lab="s")
            for n, row in zip(nodes, x, strict=True)]
    pyuff.UFF(str(path)).write_sets(sets, mode="add")
    return path


def write_tdms(path: Path, x: np.ndarray, names: list[str], *, fs: float = FS,
               units=None, segment: int = 4096, dtype=np.float64) -> Path:
    """Waveform channels (wf_increment, wf_start_offset, unit_string), in several segments."""
    units = units or ["m/s^2"] * len(names)
    with TdmsWriter(str(path)) as w:
        for a in range(0, x.shape[1], segment):
            w.write_segment([ChannelObject("accelerations", n, x[i, a:a + segment].astype(dtype),
                                           properties={"wf_increment": 1 / fs,
                                                       "wf_start_offset": 0.0,
                                                       "unit_string": units[i]})
                             for i, n in enumerate(names)])
    return path


def imported(path: Path, **options) -> tuple[dict, np.ndarray, np.ndarray, list]:
    """Import a file: (extra["import"], counts concatenated, scale, blocks)."""
    with open_device(str(path), rig=RIG, **options) as dev:
        blocks = list(dev)
        extra = dev.info.extra["import"]
    counts = np.concatenate([b.counts for b in blocks], axis=1)
    return extra, counts, blocks[0].scale, blocks


@pytest.fixture(scope="module")
def sim():
    """8 s of the ALBACORE-like rig in air, a ram blow at 3 s: counts (16, n), scale, gages."""
    with SimDevice(RIG, duration_s=8.0, impacts=[3.0], seed=3) as dev:
        blocks = list(dev)
        gages = list(dev.info.gages)
    counts = np.concatenate([b.counts for b in blocks], axis=1)
    return counts, blocks[0].scale, gages


def _names(gages):
    return [f"g{n:02d}" for n in gages]


def _t(n):
    return np.arange(n) / FS


# -- lossless counts ---------------------------------------------------------------------------
def test_csv_of_quantised_values_gives_bit_exact_counts(sim, tmp_path):
    counts, scale, gages = sim
    path = write_csv(tmp_path / "trial.csv", _t(counts.shape[1]), counts * scale[:, None],
                     _names(gages))
    extra, got, got_scale, blocks = imported(path)
    assert np.array_equal(got, counts) and np.array_equal(got_scale, scale)
    assert all(c["method"] == "quantised" and c["exact"] for c in extra["channels"].values())
    assert extra["fs_hz"] == FS and extra["segments"] == 1 and extra["missing_samples"] == 0
    assert [b.first_sample for b in blocks[1:]] == [b.next_sample for b in blocks[:-1]]


@pytest.mark.parametrize("binary", [False, True], ids=["ascii58", "binary58b"])
def test_uff58_of_quantised_values_gives_exact_counts(sim, tmp_path, binary):
    counts, scale, gages = sim
    path = write_uff58(tmp_path / "trial.uff", counts * scale[:, None], gages, binary=binary)
    extra, got, got_scale, _ = imported(path)
    assert np.array_equal(got, counts)  # E20.12 keeps 13 digits: still the exact counts
    if binary:
        assert np.array_equal(got_scale, scale)
    else:
        np.testing.assert_allclose(got_scale, scale, rtol=1e-12)
    assert extra["fs_hz"] == FS  # from abscissa_inc printed as 4.88281E-04


def test_tdms_of_quantised_values_gives_bit_exact_counts(sim, tmp_path):
    counts, scale, gages = sim
    path = write_tdms(tmp_path / "trial.tdms", counts * scale[:, None], _names(gages))
    extra, got, got_scale, _ = imported(path)
    assert np.array_equal(got, counts) and np.array_equal(got_scale, scale)
    assert extra["segments"] == 1 and extra["time"] == "wf_increment"


def test_values_in_g_keep_their_counts(sim, tmp_path):
    counts, scale, gages = sim
    x_g = counts[:4] * scale[:4, None] / G0
    path = write_csv(tmp_path / "g.csv", _t(counts.shape[1]), x_g, _names(gages[:4]),
                     units=["g"] * 4, units_row=True)
    extra, got, got_scale, _ = imported(path)
    assert np.array_equal(got, counts[:4])
    np.testing.assert_allclose(got_scale, scale[:4], rtol=1e-12)
    assert extra["channels"]["g01"]["unit"] == "g"


def test_step_detection_is_exact_on_long_records():
    # least squares over a million values lands ulps off the step; the exact float is found
    k = np.rint(np.random.default_rng(5).normal(0, 20_000, 1_000_000))
    k = k[k != 0]
    s = 0.00011690623668802712
    assert detect_step(k * s) == (s, True)
    step, exact = detect_step((k * s).astype(np.float32).astype(np.float64))
    assert not exact and np.array_equal(np.rint(k * s / step), k)  # float32: counts survive
    assert detect_step(np.random.default_rng(6).normal(0, 1, 10_000)) is None


@pytest.mark.parametrize("fmt", ["csv", "uff", "tdms"])
def test_float_data_is_requantised_within_the_bound(sim, tmp_path, fmt):
    counts, scale, gages = sim
    # low-passed: no longer on any step grid
    x = lfilter([0.2, 0.3, 0.2], [1.0, -0.3], counts[:3] * scale[:3, None], axis=1)
    names = _names(gages[:3])
    path = {"csv": lambda p: write_csv(p, _t(x.shape[1]), x, names),
            "uff": lambda p: write_uff58(p, x, gages[:3], binary=True),
            "tdms": lambda p: write_tdms(p, x, names)}[fmt](tmp_path / f"f.{fmt}")
    extra, got, got_scale, _ = imported(path)
    peak = np.max(np.abs(x), axis=1)
    np.testing.assert_allclose(got_scale, peak / (2**23 - 1), rtol=1e-15)
    err = np.abs(got * got_scale[:, None] - x).max(axis=1)
    assert np.all(err <= peak / (2**24 - 2) * (1 + 1e-9))  # the documented bound
    assert np.abs(got).max() == 2**23 - 1
    for i, name in enumerate(names):
        c = extra["channels"][name]
        assert c["method"] == "requantised" and c["max_error_si"] == pytest.approx(err[i])
        assert c["si_unit"] == "m/s^2"


# -- gaps --------------------------------------------------------------------------------------
def test_missing_values_and_rows_are_gaps_not_interpolated(sim, tmp_path):
    counts, scale, gages = sim
    n = 6000
    x = counts[:, :n] * scale[:, None]
    x[2, 1000:1010] = np.nan  # empty cells in one channel drop those rows for all channels
    t = _t(n)
    keep = np.ones(n, bool)
    keep[3000:3005] = False  # rows missing from the file: a jump in the time column
    path = write_csv(tmp_path / "gaps.csv", t[keep], x[:, keep], _names(gages))
    path.write_text(_set_cell(path.read_text(), 2002, 6, "nan"))  # row 2000: a literal nan
    with pytest.raises(ImportFormatError, match=r"gaps\.csv: line 1002, column 'g03': missing "
                       r"value .*--allow-gaps"):
        imported(path)  # never silent: a gap from a missing value is asked for
    extra, got, _, blocks = imported(path, allow_gaps=True)
    present = np.ones(n, bool)
    present[1000:1010] = present[2000] = present[3000:3005] = False
    starts = [b.first_sample for b in blocks]
    assert {1010, 2001, 3005} <= set(starts)
    assert sum(b.n_samples for b in blocks) == present.sum() == got.shape[1]
    assert np.array_equal(got, counts[:, :n][:, present])
    assert extra["segments"] == 4 and extra["missing_samples"] == 16
    assert extra["time_gaps"] == 1
    # 10 rows lose g03 and one g06: every other channel's values on those rows are dropped
    # with them, and counted
    assert extra["dropped_with_gaps"]["missing"] == {"g03": 10, "g06": 1}
    good = {f"g{g:02d}": 11 for g in gages if g not in (3, 6)} | {"g03": 1, "g06": 10}
    assert extra["dropped_with_gaps"]["good"] == good


def test_a_decay_cut_by_a_gap_says_so(sim, tmp_path):
    """One missing value 2 s after the blow (3 s): the hit is analysed on the 2 s before the
    gap, and its notes say the gap, not the ringing, ended the decay (it said nothing)."""
    from ramdaq.daq.api import analyze

    counts, scale, gages = sim
    x = counts * scale[:, None]
    x[2, round(5.0 * FS)] = np.nan
    path = write_csv(tmp_path / "gap.csv", _t(x.shape[1]), x, _names(gages))
    out = tmp_path / "gap.mcap"
    assert main(["import", str(path), "--rig", str(RIG), "--out", str(out), "--allow-gaps"]) == 0
    hit = analyze(out).hits[0]
    assert hit.accepted and hit.event.end_reason == "gap"
    assert "decay cut by a gap in the stream at 5.000 s" in " ".join(hit.analysis.notes)


def test_uff_records_at_different_starts_are_segments(sim, tmp_path):
    counts, scale, gages = sim
    x = counts[:2] * scale[:2, None]
    path = tmp_path / "two.uff"
    write_uff58(path, x[:, :1000], gages[:2], t0=1.0)
    part = tmp_path / "part.uff"
    write_uff58(part, x[:, 3000:4000], gages[:2], t0=3000 / FS + 1.0)
    path.write_bytes(path.read_bytes() + part.read_bytes())
    extra, got, _, blocks = imported(path)
    assert blocks[0].first_sample == 2048 and blocks[-1].next_sample == 2048 + 4000
    assert extra["record_segments"] == 2 and np.array_equal(got[:, 1000:], counts[:2, 3000:4000])


# -- channel names -----------------------------------------------------------------------------
def test_gage_names_and_channel_map(sim, tmp_path):
    assert [gage_of_name(s) for s in ("g01", "G1", "gage 3", "Gauge_04", "5", "ch1", "g 1a")] \
        == [1, 1, 3, 4, 5, None, None]
    assert parse_channel_map("Accel A=g02, Accel B=3") == {"Accel A": 2, "Accel B": 3}
    with pytest.raises(ValueError, match="SOURCE=GAGE"):
        parse_channel_map("Accel A")
    counts, scale, _ = sim
    x = counts[:2, :500] * scale[:2, None]
    path = write_csv(tmp_path / "named.csv", _t(500), x, ["Accel A", "Accel B"])
    with pytest.raises(ImportFormatError, match="'Accel A' is not a gage name"):
        imported(path)
    extra, got, _, _ = imported(path, channels={"Accel B": 4, "Accel A": 2})
    assert np.array_equal(got, counts[:2, :500])  # rows in the rig's channel order: g02, g04
    assert extra["channels"]["g04"]["source"] == "Accel B"
    with pytest.raises(ImportFormatError, match="both gage 2"):
        imported(path, channels={"Accel A": 2, "Accel B": 2})
    with pytest.raises(ImportFormatError, match="gage 17, which rig"):
        imported(path, channels={"Accel A": 17})


# -- wrong or truncated files: one line naming the file and what --------------------------------
def _csv_ok(tmp_path: Path, sim) -> Path:
    counts, scale, gages = sim
    return write_csv(tmp_path / "bad.csv", _t(200), counts[:3, :200] * scale[:3, None],
                     _names(gages[:3]))


def _bad_csv(edit):
    def make(tmp_path, sim):
        p = _csv_ok(tmp_path, sim)
        p.write_text(edit(p.read_text()))
        return p
    return make


def _set_cell(text: str, line: int, column: int, value: str) -> str:
    lines = text.split("\n")
    cells = lines[line - 1].split(",")
    cells[column] = value
    lines[line - 1] = ",".join(cells)
    return "\n".join(lines)


def _truncated_tdms(tmp_path, sim):
    counts, scale, gages = sim
    p = write_tdms(tmp_path / "bad.tdms", counts[:2, :3000] * scale[:2, None], _names(gages[:2]),
                   segment=1000)
    data = p.read_bytes()
    p.write_bytes(data[: len(data) - 777])
    return p


def _uff_of_type_55(tmp_path, sim):
    p = tmp_path / "bad.uff"
    pyuff.UFF(str(p)).write_sets([{"type": 15, "node_nums": [1, 2], "x": [0.0, 1.0],
                                   "y": [0.0, 0.0], "z": [0.0, 0.0]}], mode="add")
    return p


def _uff_frf(tmp_path, sim):
    return write_uff58(tmp_path / "bad.uff", np.ones((1, 64)), [1], func_type=4)


def _uff_truncated(tmp_path, sim):
    counts, scale, gages = sim
    p = write_uff58(tmp_path / "bad.uff", counts[:2, :400] * scale[:2, None], gages[:2])
    text = p.read_text()
    p.write_text(text[: len(text) * 3 // 4])
    return p


BAD = {
    "truncated csv line": (_bad_csv(lambda s: s[: s.rindex(",") - 3]), "fields, expected 4"),
    "non-numeric cell": (_bad_csv(lambda s: _set_cell(s, 3, 2, "oops")),
                         "line 3, column 'g02': 'oops' is not a number"),
    "unknown unit": (_bad_csv(lambda s: s.replace("g02 [m/s^2]", "g02 [mm/s^2]")),
                     "channel 'g02' is in 'mm/s^2'"),
    "non-uniform time": (_bad_csv(lambda s: s.replace("\n0.048828125,", "\n0.0489,")),
                         "line 102: time 0.0489 s is"),
    "empty csv": (_bad_csv(lambda s: ""), "empty file"),
    "tdms truncated": (_truncated_tdms, "truncated"),
    "uff without type 58": (_uff_of_type_55, "no type 58"),
    "uff frf, not time": (_uff_frf, "function type 4"),
    "uff truncated": (_uff_truncated, "truncated"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_file_is_one_line_error(case, tmp_path, sim):
    make, what = BAD[case]
    path = make(tmp_path, sim)
    with pytest.raises(ImportFormatError) as info:
        imported(path)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg and what in msg, msg
    assert isinstance(info.value, ValueError)


def test_cli_import_refuses_in_one_line(tmp_path, sim, capsys):
    # (a column in volts is no longer refused with this rig: its gages state their sensitivity)
    path = _bad_csv(lambda s: s.replace("g02 [m/s^2]", "g02 [psi]"))(tmp_path, sim)
    assert main(["import", str(path), "--rig", str(RIG), "--out", str(tmp_path / "x.mcap")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.csv" in err[0] and "'g02'" in err[0]
    assert not (tmp_path / "x.mcap").exists()


def test_cli_import_format_channels_medium(sim, tmp_path, capsys):
    from ramdaq.drivers.mcap_replay import McapReplayDevice

    counts, scale, _ = sim
    src = write_csv(tmp_path / "logger.txt", _t(300), counts[:1, :300] * scale[:1, None],
                    ["Accel A"], units=["g"])
    out = tmp_path / "logger.mcap"
    args = ["import", str(src), "--rig", str(RIG), "--format", "csv", "--channels",
            "Accel A=g04", "--medium", "water", "--out", str(out)]
    assert main(args) == 0
    assert "1 channel kept its source step" in capsys.readouterr().out
    with McapReplayDevice(out) as dev:
        assert dev.info.gages == (4,) and dev.info.extra["medium"] == "water"
        assert np.array_equal(np.concatenate([b.counts for b in dev], axis=1), counts[:1, :300])
    assert main(args) == 1 and "exists" in capsys.readouterr().err  # no silent overwrite


# -- end to end: CSV -> ramdaq import -> ramdaq analyze, and export-uff ------------------------
@pytest.fixture(scope="module")
def imported_trial(sim, tmp_path_factory):
    counts, scale, gages = sim
    d = tmp_path_factory.mktemp("e2e")
    csv = write_csv(d / "albacore.csv", _t(counts.shape[1]), counts * scale[:, None],
                    _names(gages))
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["import", str(csv), "--rig", str(RIG), "--out", str(d / "albacore.mcap")]) == 0
    return d, d / "albacore.mcap", out.getvalue()


def test_csv_import_then_analyze_finds_the_predominant_mode(imported_trial, capsys):
    d, mcap, out = imported_trial
    assert "16 channels kept their source step" in out
    assert main(["analyze", str(mcap), "--no-plots", "--out", str(d / "an")]) == 0
    rep = json.loads((d / "an" / "report.json").read_text())
    assert [round(i["onset_s"], 2) for i in rep["impacts"]] == [3.0]
    hit = rep["impacts"][0]
    assert hit["accepted"] and abs(hit["analysis"]["f_hz"] / 24.5 - 1) < 0.02


def test_export_uff_round_trip(imported_trial, tmp_path):
    from ramdaq.daq.commands.analyze import run_analysis

    _, mcap, _ = imported_trial
    rig, hits = run_analysis(mcap)
    r = export_uff(tmp_path / "modes.uff", hits, rig, source=str(mcap))
    a, ev = hits[0].analysis, hits[0].event
    assert (r.hits, r.nodes, r.modes, r.records) == (1, 16, len(a.modes), 16)
    sets = pyuff.UFF(str(r.path)).read_sets()
    assert [s["type"] for s in sets] == [164, 15] + [55] * len(a.modes) + [58] * 16
    nodes = sets[1]
    for g in rig.gages:
        i = nodes["node_nums"].index(g.number)
        assert [nodes[k][i] for k in "xyz"] == pytest.approx(g.position_m, abs=1e-5)
    active = a.active_gages
    for k, s in enumerate(sets[2:2 + len(a.modes)]):
        f = s["eig"].imag / (2 * np.pi)
        assert f == pytest.approx(a.modes.frequency_hz[k], rel=1e-5)
        assert -s["eig"].real / f == pytest.approx(a.modes.delta[k], rel=1e-4)
        assert s["mode_n"] == k + 1 and ("predominant" in s["id1"]) == (k == a.predominant)
        for n, shape in zip(active, a.modes.mode_shape[:, k], strict=True):
            axis = AXIS_CODES[rig.gage(n).axis]
            v = s[f"r{abs(axis)}"][list(s["node_nums"]).index(n)]
            assert abs(v - np.sign(axis) * shape) < 2e-5
    rec = ev.record
    first = round(a.decay_start_s * rec.fs_hz)
    decay = rec.values()[:, first - rec.first_sample:]
    for row, s in enumerate(sets[-16:]):
        assert s["rsp_node"] == ev.gages[row] and s["func_type"] == 1
        assert s["abscissa_inc"] == pytest.approx(1 / FS, rel=1e-5)
        np.testing.assert_allclose(s["data"], decay[row], rtol=1e-11, atol=1e-15)
    # ramdaq's own import reads the decay records back, exact counts, at the decay start
    extra, counts, _, blocks = imported(r.path)
    assert blocks[0].first_sample == first
    assert np.array_equal(counts, rec.counts[:, first - rec.first_sample:])


def test_cli_export_uff(imported_trial, tmp_path, capsys):
    _, mcap, _ = imported_trial
    out = tmp_path / "trial.uff"
    assert main(["export-uff", str(mcap), "--out", str(out), "--binary"]) == 0
    assert "16 gage nodes" in capsys.readouterr().out
    types = [int(t) for t in pyuff.UFF(str(out)).get_set_types()]
    assert types[:2] == [164, 15] and types.count(58) == 16 and 55 in types
    # an existing file is refused in one line, before the analysis, as every writer does
    assert main(["export-uff", str(mcap), "--out", str(out)]) == 1
    err = capsys.readouterr()
    assert "trial.uff exists; --overwrite replaces it" in err.err and "wrote" not in err.out
    assert main(["export-uff", str(mcap), "--out", str(out), "--overwrite"]) == 0


def test_import_devices_are_registered(sim, tmp_path):
    counts, scale, _ = sim
    x = counts[:1, :100] * scale[:1, None]
    files = {CsvImportDevice: write_csv(tmp_path / "x.csv", _t(100), x, ["g01"]),
             UffImportDevice: write_uff58(tmp_path / "x.uff", x, [1]),
             TdmsImportDevice: write_tdms(tmp_path / "x.tdms", x, ["g01"])}
    for cls, path in files.items():
        with open_device(str(path), rig=RIG) as dev:
            assert isinstance(dev, cls) and dev.pace == "fast"
            assert dev.info.channels == ("g01",) and dev.info.device.endswith(os.fspath(path))
