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
    assert "warning: channel 'AI0 acc' is in" in err and f"--units {flag}" in err
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
    rc, out, err = _run(["import", src, "--fs", "1000", "--out", tmp_path / "c.mcap"], capsys)
    assert rc == 1 and "1000 Hz" in err  # a stated rate is still checked against the file's
