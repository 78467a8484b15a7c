"""Nothing silent on import (issue 18): a CSV's rate against the rig's, the time column's unit
from its header, a missing value named by line and column; then force channels and the
channels-only rig that ``ramdaq import --fs --units`` makes for a record without a rig."""

from __future__ import annotations

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
    """2 s of the ALBACORE-like rig in air, a blow at 0.5 s: values (16, n) m/s^2, gages."""
    with SimDevice(RIG, duration_s=2.0, impacts=[0.5], seed=1) as dev:
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
    info, _ = _read(p, fs_hz=1000.0)
    assert info.fs_hz == 1000.0
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
    assert main([*base, "--time-unit", "s", "--fs", "1000"]) == 0
    assert "2 ch at 1000 Hz" in capsys.readouterr().out
